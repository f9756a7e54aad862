"""Real signals in the middle of a run (a subprocess of the grindtwin command): one line, the
exit code of the signal, no traceback, and nothing left that looks like a result."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.scenarios.test_runner import short_pyrite_scene

ROOT = Path(__file__).resolve().parents[2]
COMMAND = [sys.executable, "-c", "import sys; from scenarios.cli import main; sys.exit(main())"]
#: Long enough (an open loop of 200 h at one-minute samples) that the signal lands mid-sweep.
LONG_H = 200.0
#: A single run 10x longer: 200 h ran in about a second on a quiet machine, and the run ended
#: before the signal.
RUN_LONG_H = 2000.0


class Running:
    """The command in a subprocess, its stderr collected as it comes (the progress bar)."""

    def __init__(self, args):
        self.proc = subprocess.Popen([*COMMAND, *map(str, args)], cwd=ROOT, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.err = ""
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in iter(lambda: self.proc.stderr.read(64), ""):
            self.err += line

    def wait_for_progress(self, timeout_s: float = 120.0):
        """Until the progress bar has moved (the run is integrating), then a moment more."""
        deadline = time.monotonic() + timeout_s
        while "sample/s" not in self.err and "case/s" not in self.err and "it/s" not in self.err:
            assert self.proc.poll() is None, self.err
            assert time.monotonic() < deadline, "no progress: " + self.err
            time.sleep(0.05)
        time.sleep(0.5)
        assert self.proc.poll() is None, "the run ended before the signal: make it longer"

    def finish(self, sig) -> tuple[int, str]:
        self.proc.send_signal(sig)
        self.proc.wait(timeout=120)
        self._reader.join(timeout=10)
        self.proc.stdout.close()
        self.proc.stderr.close()
        return self.proc.returncode, self.err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_mid_run_leaves_nothing_that_looks_complete(tmp_path, sig):
    scene = short_pyrite_scene(tmp_path, duration_h=RUN_LONG_H)
    out = tmp_path / "out"
    run = Running(["run", scene, "--out", out])
    run.wait_for_progress()
    code, err = run.finish(sig)
    assert code == 128 + sig, err
    assert "Traceback" not in err
    assert f"interrupted by {sig.name}" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.toml"]  # no out, .partial or .lock


def test_ctrl_c_in_a_sweep_stops_its_workers_without_tracebacks(tmp_path):
    scene = short_pyrite_scene(tmp_path, duration_h=LONG_H)
    out = tmp_path / "sweep"
    run = Running(["sweep", scene, "--vary", "feed.feed_tph=24,30,36", "--workers", "2", "--out", out])
    run.wait_for_progress()  # the sweep's bar shows "0/3 [00:00<?, ?case/s]" when the cases start
    t0 = time.monotonic()
    code, err = run.finish(signal.SIGINT)
    assert code == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert time.monotonic() - t0 < 60  # the workers were stopped, not waited for
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.toml"]
