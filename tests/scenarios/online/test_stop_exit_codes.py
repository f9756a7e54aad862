"""How ``grindtwin serve`` and ``grindtwin plant-server`` end, as a service manager sees them (each
command in a subprocess): a SIGTERM stops them cleanly with the exit code README states, and a
second signal while they stop neither cuts the stop short nor changes the code."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import scenarios.online as online

from .conftest import free_port

ROOT = Path(__file__).resolve().parents[3]
CLI = [sys.executable, "-c", "import sys; from scenarios.cli import main; sys.exit(main(sys.argv[1:]))"]
#: README's statement of the code both commands exit with after a clean stop by a signal.
README_STOP_CODE = re.compile(r"`serve` and `plant-server` exit (\d+) after a clean stop")
#: The commands with each method that runs at their stop replaced by one that first sends the
#: process a SIGTERM (a second signal, as from an impatient operator or a service manager that
#: repeats its stop), then does the stop.
SIGNAL_WHILE_STOPPING = """\
import asyncio, os, signal, sys
from scenarios.online.plant_server import PlantServer
from scenarios.online.service import Service

def signalled(stop):
    async def wrapped(self, *args):
        os.kill(os.getpid(), signal.SIGTERM)
        await asyncio.sleep(0.2)  # the signal is handled (or kills the process) before the stop goes on
        return await stop(self, *args)
    return wrapped

PlantServer.stop_server = signalled(PlantServer.stop_server)
Service.shutdown = signalled(Service.shutdown)
from scenarios.cli import main
sys.exit(main(sys.argv[1:]))
"""


class Command:
    """A grindtwin command in a subprocess, its log in a file (a pipe could fill and stall it)."""

    def __init__(self, argv, log: Path, program=None):
        self.log = log
        self._err = log.open("w")
        cmd = [sys.executable, "-c", program] if program else CLI
        self.proc = subprocess.Popen([*cmd, *map(str, argv)], cwd=ROOT, stderr=self._err)

    def text(self) -> str:
        return self.log.read_text()

    def wait_for(self, needle: str, timeout_s: float = 180.0) -> None:
        t0 = time.monotonic()
        while needle not in self.text():
            assert self.proc.poll() is None, f"ended with {self.proc.returncode} before {needle!r}:\n{self.text()}"
            assert time.monotonic() - t0 < timeout_s, f"no {needle!r} in {timeout_s:g} s:\n{self.text()}"
            time.sleep(0.05)

    def stop(self, sig=signal.SIGTERM, timeout_s: float = 120.0) -> int:
        if sig is not None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout=timeout_s)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
            self._err.close()


def _readme_stop_code() -> int:
    codes = {int(c) for c in README_STOP_CODE.findall((ROOT / "README.md").read_text(encoding="utf-8"))}
    assert len(codes) == 1, f"README states {sorted(codes) or 'no'} exit code(s) for serve and plant-server's stop"
    return codes.pop()


def test_sigterm_stops_both_commands_with_the_exit_code_readme_states(small_files, tmp_path):
    """serve against the plant-server, both in their own process: SIGTERM to each (as systemd's
    stop) ends it after its running cycle or sample, with everything written, and the code
    README states."""
    expected = _readme_stop_code()
    scene, tags = small_files
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    plant = Command(["plant-server", scene, "--tags", tags, "--opcua", url, "--insecure", "--speedup", 300,
                     "--record", tmp_path / "record"], tmp_path / "plant.log")
    serve = None
    try:
        plant.wait_for("serving at")
        serve = Command(["serve", scene, "--tags", tags, "--opcua", url, "--insecure", "--speedup", 300,
                         "--audit", tmp_path / "audit", "--warmup-h", 0.05], tmp_path / "serve.log")
        serve.wait_for("mode warmup -> auto")
        serve_code = serve.stop()
    finally:
        if serve is not None and serve.proc.poll() is None:
            serve.stop(signal.SIGKILL)
        plant_code = plant.stop()
    assert serve_code == expected, serve.text()[-2000:]
    assert plant_code == expected, plant.text()[-2000:]
    assert "Traceback" not in serve.text() + plant.text()
    audit = online.read_audit(tmp_path / "audit")
    assert audit["mode"].iloc[-1] == "stopped" and audit["reason"].iloc[-1].startswith("stopped (SIGTERM)")
    assert "virtual plant stopped (SIGTERM)" in plant.text()
    assert (tmp_path / "record" / "plant.parquet").exists()


@pytest.mark.parametrize("command", ["serve", "plant-server"])
def test_a_second_signal_while_stopping_does_not_cut_the_stop_short(small_files, tmp_path, command):
    """Each command ends on its own (--duration-h) and gets a SIGTERM in the middle of its stop:
    the stop completes (the audit's last row, the plant's record) and the exit code is README's."""
    expected = _readme_stop_code()
    scene, tags = small_files
    url = f"opc.tcp://127.0.0.1:{free_port()}"  # nothing listens there: serve runs disconnected
    out = tmp_path / ("audit" if command == "serve" else "record")
    argv = [command, scene, "--tags", tags, "--opcua", url, "--insecure", "--speedup", 3600, "--duration-h", 0.1,
            "--audit" if command == "serve" else "--record", out]
    run = Command(argv, tmp_path / "log", program=SIGNAL_WHILE_STOPPING)
    code = run.stop(sig=None)
    assert code == expected, run.text()[-2000:]
    assert "stop requested: SIGTERM" not in run.text()  # the duration stopped it; the signal changed nothing
    if command == "serve":
        audit = online.read_audit(out)
        assert audit["mode"].iloc[-1] == "stopped" and "duration 0.1 h reached" in audit["reason"].iloc[-1]
    else:
        assert "virtual plant stopped (duration 0.1 h reached)" in run.text()
        assert (out / "plant.parquet").exists()
