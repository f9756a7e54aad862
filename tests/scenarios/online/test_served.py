"""The served controller in real (sped-up) time: SIGTERM leaves the setpoints where they are, and
on the reference transition (shortened) the served NMPC holds P80 with the in-process loop's KPIs."""

import asyncio
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from asyncua import ua

import scenarios.online as online
from scenarios.scene import load_scene

from .conftest import free_port

CLI = [sys.executable, "-c", "import sys; from scenarios.cli import main; sys.exit(main(sys.argv[1:]))"]


async def _wait_for(predicate, timeout_s, what):
    t0 = time.monotonic()
    while not predicate():
        if time.monotonic() - t0 > timeout_s:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.05)


def test_sigterm_stops_the_service_and_leaves_the_setpoints(small_scene, small_tags, small_parts, tmp_path):
    """Both in one process, each on its own timer (x1200: a sample every 0.15 s); the service
    starts before the plant listens (it retries), controls, and gets SIGTERM."""
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    small_parts.reset()
    plant = online.PlantServer(small_scene, small_tags, online.PlantServerSettings(
        url, online.ServerSecurity(insecure=True), speedup=1200.0, hold_h=0.2), models=small_parts.models)
    service = online.Service(small_parts, small_tags, online.ServeSettings(
        url, online.ClientSecurity(insecure=True), tmp_path / "audit", speedup=1200.0, warmup_h=0.1))

    async def main():
        serving = asyncio.create_task(service.run(install_signal_handlers=True))
        await asyncio.sleep(0.3)  # the service is up and retrying before the plant listens
        running = asyncio.create_task(plant.run(install_signal_handlers=False))
        await _wait_for(lambda: service.u_written is not None and service.k > 8, 120, "the service's moves")
        os.kill(os.getpid(), signal.SIGTERM)
        await serving
        await asyncio.sleep(0.5)  # the plant runs on without its controller
        node = plant.server.get_node(ua.NodeId.from_string(small_tags.setpoints.feed_tph.node))
        status = plant.server.get_node(ua.NodeId.from_string(small_tags.status.node))
        left = (await node.read_value(), await status.read_value(), float(plant.u[0]))
        plant.request_stop("test end")
        await running
        return left

    feed_node, status, feed_in_plant = asyncio.run(main())
    assert service.stop_reason == "SIGTERM"
    last = float(service.u_written[0])
    assert feed_node == last == feed_in_plant  # nothing written after the stop
    assert status.startswith("stopped (SIGTERM): setpoints left at feed")
    audit = online.read_audit(tmp_path / "audit")
    assert audit["mode"].iloc[-1] == "stopped" and f"feed {last:.4g} t/h" in audit["reason"].iloc[-1]
    assert (audit["mode"] == "disconnected").iloc[0]  # it started before the plant and retried


# ---------------------------------------------------------------------------------------------
#: The reference transition, shortened: the ramp to 60 % B / 40 % D starts at 0.75 h (0.5 h
#: preview), the run ends at 1.75 h; the estimator warms up for 0.5 h in both loops.
SHORT = {"duration_h = 8.0": "duration_h = 1.75", "at_h = 3.0": "at_h = 0.75"}
WARMUP_H = 0.5
#: The served KPIs against the in-process loop's of the same seed (the same analyser noise): in
#: lock step the same loop, so equal to rounding. In real time a move lands at the plant's first
#: scan mark after the cycle, a share of a sample late (MAX_LATE_FRAC at most, median). In lock-step
#: runs of this case (seeds 1-3, moves 0.1-0.25 of a sample late) the IAE moved by up to 0.34 um h
#: either way (it is about 1.5 um h: noise-driven, any change of timing changes it) and the specific
#: energy rose by 0.04-0.13 %; a move 0.9 of a sample late raised the energy by 0.42-0.46 %
#: (online.run_lock_step(..., late_frac=F) beside online.run_in_process; the 8-hour case over five
#: seeds: benchmarks/results/online_cycle.md). Those runs predate the volume-flow discharge; on it
#: the 0.9-late move of seed 2 raises the energy by 0.27 %.
IAE_TOL_UM_H, SE_REL_TOL, MAX_LATE_FRAC = 0.35, 0.0015, 0.25
#: The real-time run's sample period in wall-clock seconds, as a multiple of the in-process NMPC
#: step's p95 measured just before on this machine (and at least MIN_PERIOD_S): a move follows
#: its sample by the cycle (about 1.5 solves after the plant's step), which must stay a small
#: share of a sample on a loaded machine for the loops to be the same.
PERIOD_PER_SOLVE, MIN_PERIOD_S = 8.0, 0.75


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """The shortened reference scene (file and loaded), the virtual plant's tag map and its parts."""
    text = Path("scenarios/reference_transition.toml").read_text(encoding="utf-8")
    for old, new in SHORT.items():
        assert old in text
        text = text.replace(old, new)
    path = tmp_path_factory.mktemp("short") / "reference_short.toml"
    path.write_text(text)
    scene = load_scene(path)
    return path, scene, online.load_tags(online.VIRTUAL_PLANT_TAGS, scene), online.build_parts(scene)


KEYS = ("p80_iae_um_h", "p80_within_10um_frac", "p80_max_abs_err_um", "specific_energy_kwh_t", "throughput_t")


@pytest.mark.slow
def test_in_lock_step_the_served_loop_is_the_in_process_loop(short, tmp_path):
    """Same scene, seed, warm-up and analyser: over OPC UA the loop is the in-process one, to
    rounding; a move 0.9 of a sample late (the service cycling just before the plant's next
    sample) is far outside that rounding. Its KPIs move less than the real-time test's tolerances
    on this short run, so that test tells a late loop by the lateness it measures (MAX_LATE_FRAC),
    not by its KPIs."""
    _, _, tags, parts = short
    ref = online.run_in_process(parts, 2, WARMUP_H).kpis
    same = asyncio.run(online.run_lock_step(parts, tags, 2, tmp_path / "a0", WARMUP_H)).kpis()
    for k in KEYS:  # specific energy: the in-process frame's last row holds a move never applied
        assert same[k] == pytest.approx(ref[k], rel=5e-4 if k == "specific_energy_kwh_t" else 1e-6, abs=1e-9), k
    late = asyncio.run(online.run_lock_step(parts, tags, 2, tmp_path / "a1", WARMUP_H, late_frac=0.9)).kpis()
    # the lock step tells it apart: 100x the rounding it holds the in-process loop to (on the sized
    # mill the late move costs ~0.1 % of this short run's IAE)
    assert late["p80_iae_um_h"] != pytest.approx(ref["p80_iae_um_h"], rel=1e-4)


async def _listening(url, proc, timeout_s=180):
    """Wait until the plant server accepts TCP connections (the service then connects at once,
    not after its reconnection back-off has grown)."""
    host, port = url.removeprefix("opc.tcp://").rsplit(":", 1)
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < timeout_s:
        try:
            _, writer = await asyncio.open_connection(host, int(port))
            writer.close()
            return
        except OSError:
            await asyncio.sleep(0.1)
    raise AssertionError(f"the plant server did not listen at {url}")


async def _served(parts, tags, url, audit, proc, speedup):
    await _listening(url, proc)
    # the frozen plant's readings are stale by the time the service connects: the estimator
    # starts at the plant's first sample, one into the hold (one update fewer than in process)
    service = online.Service(parts, tags, online.ServeSettings(
        url, online.ClientSecurity(insecure=True), audit, speedup=speedup,
        warmup_h=WARMUP_H - parts.scene.scene.sample_period_h))
    serving = asyncio.create_task(service.run(install_signal_handlers=False))
    await _wait_for(lambda: service.conn is not None, 180, "the plant server")
    sim = online.PlantConnection(url, online.ClientSecurity(insecure=True), {},
                                 {"speedup": "ns=2;s=Simulation.Speedup", "run": "ns=2;s=Simulation.Run"})
    await sim.open()  # the plant was frozen: set its speed-up and let it run
    await sim.write({"speedup": (speedup, ua.StatusCodes.Good), "run": (True, ua.StatusCodes.Good)},
                    online.Clock().now())
    await sim.close()
    # the plant server stops at the end of its run; the service then finds it gone
    await _wait_for(lambda: proc.poll() is not None, 300, "the end of the plant's run")
    service.request_stop("test end")
    await serving
    return service


@pytest.mark.slow
def test_the_served_nmpc_holds_the_reference_transition_like_the_in_process_loop(short, tmp_path):
    """In (sped-up) real time, the plant server in its own process, the same seed: the served
    KPIs are the in-process ones within the tolerances above."""
    path, scene, tags, parts = short
    seed, url = 1, f"opc.tcp://127.0.0.1:{free_port()}"
    log = tmp_path / "plant.log"  # a file, not a pipe: a full pipe would stall the server
    with log.open("w") as err:
        proc = subprocess.Popen([*CLI, "plant-server", str(path), "--opcua", url, "--insecure", "--paused",
                                 "--hold-h", str(WARMUP_H), "--duration-h", "1.75", "--seed", str(seed),
                                 "--record", str(tmp_path / "plant")], stderr=err)
        try:
            ref = online.run_in_process(parts, seed, WARMUP_H).kpis  # while the plant server starts
            period_s = max(MIN_PERIOD_S, PERIOD_PER_SOLVE * ref["solve_time_p95_s"])
            speedup = 3600 * scene.scene.sample_period_h / period_s
            service = asyncio.run(_served(parts, tags, url, tmp_path / "audit", proc, speedup))
        finally:
            if proc.poll() is None:
                proc.terminate()
            proc.wait(timeout=60)
    assert proc.returncode == 0, log.read_text()[-2000:]
    served = json.loads((tmp_path / "plant" / "plant-kpis.json").read_text())
    audit = online.read_audit(tmp_path / "audit")
    auto = audit[audit["mode"] == "auto"]
    print(f"x{speedup:.0f}", "in-process", {k: round(ref[k], 4) for k in KEYS}, "served",
          {k: round(served[k], 4) for k in KEYS}, audit["started_by"].value_counts().to_dict())
    late = pd.read_parquet(tmp_path / "plant" / "plant.parquet")["setpoint_applied_at_frac"].dropna()
    print("moves applied at", late.describe().round(3).to_dict())
    assert late.median() <= MAX_LATE_FRAC
    assert abs(served["p80_iae_um_h"] - ref["p80_iae_um_h"]) <= IAE_TOL_UM_H
    assert served["p80_within_10um_frac"] == ref["p80_within_10um_frac"] == 1.0
    assert served["specific_energy_kwh_t"] == pytest.approx(ref["specific_energy_kwh_t"], rel=SE_REL_TOL)
    assert served["load_outside_band_frac"] == 0.0
    assert len(auto) >= 30 and not auto["feed_sp_tph"].isna().any()
    assert (auto["started_by"] == "new p80_um").mean() >= 0.9  # the analyser's reports start the cycles
    assert service.stop_reason == "test end"
