"""The virtual plant without the network: a setpoint takes effect when it is written (the input
piecewise constant), the analyser is mpc.SensorState with the scene's seed, the belt analyser
reports the blend lead_h ahead, and the record's KPIs are mpc.loop_kpis of its frame."""

import asyncio
import math

import numpy as np
import pytest

import scenarios.online as online
from mpc import SensorState, loop_kpis
from scenarios.errors import SceneError
from scenarios.run.closed_loop import scene_sensors


@pytest.fixture
def plant(small_scene, small_tags, small_parts):
    clock = online.ManualClock(speedup=3600.0)
    p = online.PlantServer(small_scene, small_tags, online.PlantServerSettings(
        "opc.tcp://127.0.0.1:1", online.ServerSecurity(insecure=True)), models=small_parts.models, clock=clock)
    return p, clock


def ticks(p, clock, n):
    async def go():
        for _ in range(n):
            clock.advance(p.dt_h)
            await p.tick()
    asyncio.run(go())


def test_a_setpoint_takes_effect_at_the_time_it_was_written(plant):
    p, clock = plant
    dt = p.dt_h
    x0, u0, d = p.x.copy(), p.u.copy(), p.plant.disturbance(0.0, p.schedule(0.0), 1.0)
    clock.advance(dt / 4)  # a quarter into the sample the feed setpoint changes
    p._apply_write("setpoints.feed_tph", 12.0, p.plant_time(), "test")
    clock.advance(3 * dt / 4)
    asyncio.run(p.tick())
    x1, _, _ = p.plant.step(x0, u0, d, dt / 4)
    x2, _, _ = p.plant.step(x1, np.array([12.0, u0[1]]), d, 3 * dt / 4)
    np.testing.assert_allclose(p.x, x2, rtol=1e-9, atol=1e-12)  # a quarter is 5 marks, to the last bit
    held, _, _ = p.plant.step(x0, np.array([12.0, u0[1]]), d, dt)  # the test can fail: the timing matters
    assert np.max(np.abs(p.x - held) / (np.abs(held) + 1e-9)) > 1e-4
    assert p.published["feed_tph"].Value.Value == 12.0


def test_non_physical_setpoints_are_ignored(plant):
    p, _ = plant
    for value in (math.nan, -3.0, "20"):
        p._apply_write("setpoints.feed_tph", value, 0.0, "test")
    p._apply_write("setpoints.speed_frac_critical", 1.2, 0.0, "test")
    assert p.writes == []


def test_a_centrifuging_speed_is_logged_as_the_runs_warn(plant, caplog):
    """A client set 0.99 of critical: the plant ran on, drawing power the model overestimates
    there, and logged nothing. Now a warning when it leaves what its models describe, once."""
    p, clock = plant
    ticks(p, clock, 1)
    p._apply_write("setpoints.speed_frac_critical", 0.99, p.plant_time(), "test")
    with caplog.at_level("INFO", logger="grindtwin.online.plant"):
        ticks(p, clock, 3)
    said = [r for r in caplog.records if "left what its models describe" in r.getMessage()]
    assert len(said) == 1 and said[0].levelname == "WARNING" and "centrifuges" in said[0].getMessage()


def test_the_analyser_is_sensor_state_with_the_scenes_seed(plant, small_scene):
    p, clock = plant
    ticks(p, clock, 12)
    f = p.frame()
    ref = SensorState(scene_sensors(small_scene), np.random.default_rng(small_scene.scene.seed))
    for row in f.itertuples():
        _, held, pw, ld = ref.make_step(row.time_h - p.t_start_h, row.p80_um, row.power_kw, row.load_frac)
        assert (held, pw, ld) == (row.p80_measured_um, row.power_meas_kw, row.load_meas_frac) or (
            math.isnan(held) and math.isnan(row.p80_measured_um))
    reports = f["p80_measured_um"].dropna()
    assert reports.nunique() >= 8  # a live analyser (a report every sample after the dead time)
    assert (reports - f.loc[reports.index, "p80_um"]).abs().max() > 0.5  # with noise


def test_the_belt_analyser_reports_the_blend_lead_h_ahead(plant, small_scene):
    p, clock = plant
    p.t_h = p.t_start_h = 0.5  # near the ramp at 1.0 h
    belt = []
    for _ in range(10):
        ticks(p, clock, 1)
        belt.append(p.published["blend.D"].Value.Value)
    lead = small_scene.controller.preview_lead_h
    t = p.frame()["time_h"].to_numpy()
    np.testing.assert_allclose(belt, [p.schedule(tt + lead)[1] for tt in t])
    assert belt[-1] > 0 and p.frame()["blend_D_frac"].iloc[-1] < belt[-1]  # the belt sees D before the mill


def test_the_record_kpis_are_loop_kpis(plant):
    p, clock = plant
    ticks(p, clock, 10)
    k = p.kpis()
    ref = loop_kpis(p.frame(), tuple(p.scene.controller.load_band_frac))
    assert k["p80_iae_um_h"] == ref["p80_iae_um_h"] > 0 and k["throughput_t"] == ref["throughput_t"]


def test_a_write_storm_costs_at_most_one_integrator_restart_per_5_percent_of_a_sample(plant, monkeypatch):
    from scenarios.online.plant_server import MIN_PIECE_FRAC

    p, clock = plant
    calls = []
    step = p.plant.step
    monkeypatch.setattr(p.plant, "step", lambda *a: calls.append(a[-1]) or step(*a))
    for k in range(200):  # a client writing 200 times a sample
        clock.advance(p.dt_h / 200)
        p._apply_write("setpoints.feed_tph", 16.0 + k / 200, p.plant_time() - p.dt_h / 400, "storm")
    asyncio.run(p.tick())
    assert len(calls) <= 1 / MIN_PIECE_FRAC + 1 and sum(calls) == pytest.approx(p.dt_h)
    assert p.u[0] < 17.0 and len(p.writes) > 0  # the last writes wait for the next sample


def test_a_setpoint_waits_for_the_next_scan_mark_so_piece_lengths_repeat(plant, monkeypatch):
    from scenarios.online.plant_server import MIN_PIECE_FRAC

    p, clock = plant
    lengths = set()
    step = p.plant.step
    monkeypatch.setattr(p.plant, "step", lambda *a: lengths.add(a[-1]) or step(*a))
    rng = np.random.default_rng(0)
    for _ in range(8):  # a write at a random time in each sample, as a served controller's
        x0, u0, d = p.x.copy(), p.u.copy(), p.plant.disturbance(p.t_h, p.schedule(max(p.t_h, 0.0)), 1.0)
        frac = rng.uniform(0.0, 1.0 - MIN_PIECE_FRAC)
        clock.advance(frac * p.dt_h)
        p._apply_write("setpoints.feed_tph", float(u0[0]) + 0.5, p.plant_time(), "test")
        clock.advance((1 - frac) * p.dt_h)
        asyncio.run(p.tick())
    # the last sample: the write took effect at the first 5 % mark after it
    at = math.ceil(frac / MIN_PIECE_FRAC) * MIN_PIECE_FRAC * p.dt_h
    x1, _, _ = p.plant.step(x0, u0, d, at)
    x2, _, _ = p.plant.step(x1, np.array([u0[0] + 0.5, u0[1]]), d, p.dt_h - at)
    np.testing.assert_allclose(p.x, x2, rtol=1e-9, atol=1e-12)
    marks = np.array(sorted(lengths)) / (MIN_PIECE_FRAC * p.dt_h)
    np.testing.assert_allclose(marks, np.round(marks), atol=1e-9)  # whole numbers of marks: cached integrators


def test_frozen_plant_time_stands_still_for_writes(plant):
    p, clock = plant
    p.running = False
    clock.advance(5 * p.dt_h)
    assert p.plant_time() == p.t_h
    p.running = True
    assert p.plant_time() == pytest.approx(p.t_h + 5 * p.dt_h)


def test_a_step_of_the_wall_clock_moves_not_the_plant_time_of_a_write(plant):
    """The plant's time ran on the wall clock: stepped back 1 h (NTP, an operator) half a sample in, a write then
    had the plant time of an hour before and took effect at the sample's start, half a sample early (stepped on, it
    waited for the next sample). It runs on the monotonic clock, as the service's does."""
    p, clock = plant
    ticks(p, clock, 1)
    clock.advance(p.dt_h / 2)
    clock.step_wall(-1.0)
    assert p.plant_time() == pytest.approx(p.t_h + p.dt_h / 2)
    p._apply_write("setpoints.feed_tph", 12.0, p.plant_time(), "test")
    clock.advance(p.dt_h / 2)
    asyncio.run(p.tick())
    assert p.applied_at_frac == pytest.approx(0.5) and p.u[0] == 12.0


def test_a_new_speed_up_counts_from_the_time_it_was_written(plant):
    p, clock = plant  # x3600: a wall-clock second is a plant hour
    clock.advance(p.dt_h / 2)
    p._apply_write("sim.speedup", 7200.0, p.plant_time(), "instructor")
    clock.advance(p.dt_h / 2)  # at x7200: half the wall time of the first half
    # the first half at x3600, the second at x7200 (the new pace applied to all: 1.5 samples)
    assert p.plant_time() == pytest.approx(p.t_h + p.dt_h)
    for bad in (0.0, -2.0, math.inf, "fast"):
        p._apply_write("sim.speedup", bad, 0.0, "instructor")
    assert p.clock.speedup == 7200.0


def test_a_paused_plant_runs_at_the_speed_up_written_with_run(small_scene, small_tags, small_parts, url):
    """Started frozen at real time (a 3-minute sample), the plant must not wait out the sample it
    was paused in once the instructor sets x3600 and runs it: three samples take 0.15 s."""
    p = online.PlantServer(small_scene, small_tags, online.PlantServerSettings(
        url, online.ServerSecurity(insecure=True), paused=True, duration_h=3 * small_scene.scene.sample_period_h),
        models=small_parts.models)

    async def go():
        serving = asyncio.create_task(p.run(install_signal_handlers=False))
        while p.server is None:
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.2)  # a frozen while at x1
        p._apply_write("sim.speedup", 3600.0, p.t_h, "instructor")
        p._apply_write("sim.run", True, p.t_h, "instructor")
        await asyncio.wait_for(serving, 30)  # before the re-timing: the 180 s sample ran out first

    asyncio.run(go())
    assert p.t_h == pytest.approx(3 * small_scene.scene.sample_period_h) and len(p.rows) == 4
    # the record starts at the first sample, t = 0 (it had no row there without --hold-h, and its KPIs
    # left out the first sample: throughput one sample short of what the plant produced)
    assert [r["time_h"] for r in p.rows] == pytest.approx([0.0, *(k * small_scene.scene.sample_period_h
                                                                   for k in (1, 2, 3))])


def test_an_ignored_setpoint_does_not_stay_on_its_node(small_scene, small_tags, small_parts, url):
    """A client writes feed -5 t/h: answered Good (the write is PostWrite) while the plant runs on
    the setpoint in effect, and the node read back -5, so every reader saw a setpoint the plant
    does not run. The node now reads the setpoint in effect again."""
    from asyncua import Client, ua

    p = online.PlantServer(small_scene, small_tags, online.PlantServerSettings(
        url, online.ServerSecurity(insecure=True), speedup=60.0), models=small_parts.models)
    node_id = small_tags.setpoints.feed_tph.node

    async def go():
        serving = asyncio.create_task(p.run(install_signal_handlers=False))
        while p.server is None or not p.published:
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.2)
        async with Client(url) as client:
            node = client.get_node(ua.NodeId.from_string(node_id))
            await node.write_value(ua.DataValue(ua.Variant(-5.0, ua.VariantType.Double)))
            await asyncio.sleep(0.3)
            back = await node.read_value()
        p.request_stop("test end")
        await serving
        return back

    back = asyncio.run(go())
    assert back == pytest.approx(float(p.u[0])) and back > 0 and p.writes == []


def test_a_record_folder_holding_the_users_files_is_refused_and_a_recording_is_replaced_only_as_written(
        small_scene, small_tags, small_parts, tmp_path):
    """--record DIR knew its files by name: a plant-kpis.json of the user's there was replaced, exit 0.
    Now a recording writes a manifest; a file it did not write, or one changed since, is refused
    before the models are built, and kept."""
    def server(record):
        return online.PlantServer(small_scene, small_tags, online.PlantServerSettings(
            "opc.tcp://127.0.0.1:1", online.ServerSecurity(insecure=True), record_dir=record),
            models=small_parts.models, clock=online.ManualClock(speedup=3600.0))

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "plant-kpis.json").write_text("my survey")
    with pytest.raises(SceneError, match=r"--record .*mine: must be a new folder or one this command wrote, as it "
                                         r"wrote it \(it holds plant-kpis.json"):
        server(mine)
    assert (mine / "plant-kpis.json").read_text() == "my survey"
    rec = tmp_path / "rec"
    p = server(rec)
    ticks(p, p.clock, 3)
    p.write_record()
    server(rec)  # its own recording: accepted, to be replaced
    (rec / "plant-kpis.json").write_text((rec / "plant-kpis.json").read_text() + " ")
    with pytest.raises(SceneError, match="which it did not write or which changed since"):
        server(rec)


@pytest.mark.parametrize("stop_at", [0, 1, 2, 3])
def test_a_recording_stopped_while_it_writes_is_taken_by_the_next_record(small_scene, small_tags, small_parts,
                                                                          tmp_path, monkeypatch, stop_at):
    """The record's files were replaced before its manifest: a server stopped between them left files the old
    manifest called edited since, and the next --record of that folder was refused. A stop at each rename
    (the manifest listing both contents, each file, the manifest of the new ones) now leaves a folder it takes."""
    import os
    from pathlib import Path

    from scenarios.online.plant_server import RECORD_FILES
    from scenarios.output import MANIFEST, strangers
    from twin import temporaries_of

    def server():
        return online.PlantServer(small_scene, small_tags, online.PlantServerSettings(
            "opc.tcp://127.0.0.1:1", online.ServerSecurity(insecure=True), record_dir=tmp_path / "rec"),
            models=small_parts.models, clock=online.ManualClock(speedup=3600.0))

    p = server()
    ticks(p, p.clock, 2)
    p.write_record()
    ticks(p, p.clock, 2)
    real_replace, calls = os.replace, []

    def replace_until_killed(src, dst):
        calls.append(dst)
        if len(calls) > stop_at:
            raise SystemExit("killed")
        return real_replace(src, dst)

    with monkeypatch.context() as m:  # a kill runs no clean-up: its temporaries stay
        m.setattr(os, "replace", replace_until_killed)
        m.setattr(Path, "unlink", lambda self, missing_ok=False: None)
        with pytest.raises(SystemExit):
            p.write_record()
    rec = tmp_path / "rec"
    left = tuple(temporaries_of(rec, (*RECORD_FILES, MANIFEST)))
    assert strangers(rec, also=left) == []
    server()  # taken: not "changed since"
    p.write_record()
    assert sorted(n for n in os.listdir(rec) if n not in left) == sorted([MANIFEST, *RECORD_FILES])
    assert strangers(rec, also=left) == []


def test_a_start_that_fails_keeps_the_folders_last_recording(small_scene, small_tags, small_parts, tmp_path):
    """A plant server whose port was in use exited 1, and its clean-up wrote its one-row record over the
    folder's earlier recording (plant-kpis.json became {})."""
    import socket

    from .conftest import free_port

    rec = tmp_path / "rec"

    def server(port):
        return online.PlantServer(small_scene, small_tags, online.PlantServerSettings(
            f"opc.tcp://127.0.0.1:{port}", online.ServerSecurity(insecure=True), record_dir=rec),
            models=small_parts.models, clock=online.ManualClock(speedup=3600.0))

    first = server(free_port())
    ticks(first, first.clock, 3)
    first.write_record()
    before = {p.name: p.read_bytes() for p in rec.iterdir()}
    held = socket.socket()
    held.bind(("127.0.0.1", 0))
    held.listen()
    try:
        with pytest.raises(OSError):
            asyncio.run(server(held.getsockname()[1]).run(install_signal_handlers=False))
    finally:
        held.close()
    assert {p.name: p.read_bytes() for p in rec.iterdir()} == before


def test_a_record_folder_is_made_when_the_record_is_written(small_scene, small_tags, small_parts, tmp_path):
    # made when checked, before the models: a server stopped while it built them left an empty folder
    rec = tmp_path / "runs" / "rec"
    p = online.PlantServer(small_scene, small_tags, online.PlantServerSettings(
        "opc.tcp://127.0.0.1:1", online.ServerSecurity(insecure=True), record_dir=rec),
        models=small_parts.models, clock=online.ManualClock(speedup=3600.0))
    assert not rec.exists() and not rec.parent.exists()
    ticks(p, p.clock, 2)
    p.write_record()
    assert (rec / "plant.parquet").is_file()


def test_an_undefined_kpi_of_a_recording_is_null_not_the_text_nan(small_scene, small_tags, small_parts, tmp_path,
                                                                  monkeypatch):
    """plant-kpis.json wrote an undefined KPI (the specific energy of a run that fed nothing: NaN) as the text NaN,
    which is no JSON (a strict reader refuses the file); it is null now, as in a run's summary.json."""
    import json

    from scenarios.online import plant_server

    def nothing_fed(frame, band):
        return loop_kpis(frame, band) | {"specific_energy_kwh_t": math.nan}

    monkeypatch.setattr(plant_server, "loop_kpis", nothing_fed)
    rec = tmp_path / "rec"
    p = online.PlantServer(small_scene, small_tags, online.PlantServerSettings(
        "opc.tcp://127.0.0.1:1", online.ServerSecurity(insecure=True), record_dir=rec),
        models=small_parts.models, clock=online.ManualClock(speedup=3600.0))
    ticks(p, p.clock, 3)
    p.write_record()

    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    kpis = json.loads((rec / "plant-kpis.json").read_text(encoding="utf-8"), parse_constant=refuse)
    assert kpis["specific_energy_kwh_t"] is None and kpis["throughput_t"] > 0
