"""A fault drill of the served controller on the virtual plant, in lock step on loopback: warm-up,
auto, a Bad P80, a frozen analyser, a manual period with an operator's move, a network outage
that sheds the service by the plant's watchdog, and the return. Each is handled, logged and
audited; no exception escapes. The drill runs once; each test reads one phase of it."""

import asyncio
import logging

import numpy as np
import pandas as pd
import pytest
from asyncua import ua

import scenarios.online as online

from .conftest import LockStep


class Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.DEBUG)
        self.records = []

    def emit(self, record):
        self.records.append(record)


async def _operator(url, tags):
    """An operator's client (the DCS console): writes the mode and the feed setpoint."""
    conn = online.PlantConnection(url, online.ClientSecurity(insecure=True), {},
                                  {"mode": tags.mode.node, "feed": tags.setpoints.feed_tph.node})
    await conn.open()
    return conn


async def _drill(ls: LockStep, url, tags):
    phases, inn = {}, []

    async def phase(name, n):
        start = len(ls.rows)
        for _ in range(n):
            await ls.step()
            inn.append(ls.service.parts.estimator.innovation[0])
        phases[name] = (start, len(ls.rows))

    await ls.start()
    await phase("warmup_auto", 10)                     # warm-up 0.2 h, then auto
    ls.plant.set_fault("bad")
    await phase("bad_p80", 6)                          # 0.3 h: on the model, then hold (> 0.15 h)
    ls.plant.set_fault("none")
    await phase("recovered_1", 4)
    ls.plant.set_fault("frozen")
    await phase("frozen", 9)                           # frozen after 0.2 h, then hold
    ls.plant.set_fault("none")
    await phase("recovered_2", 4)
    op = await _operator(url, tags)
    await op.write({"mode": ("manual", ua.StatusCodes.Good), "feed": (12.0, ua.StatusCodes.Good)}, ls.clock.now())
    await phase("manual", 5)
    await op.write({"mode": ("auto", ua.StatusCodes.Good)}, ls.clock.now())
    await phase("back_to_auto", 3)
    await op.close()
    await ls.plant.drop()
    await phase("outage", 5)                           # 0.25 h without heartbeat: the watchdog sheds (0.15 h)
    await ls.plant.restore()
    for _ in range(100):                               # the reconnection task's back-off runs on wall time
        await asyncio.sleep(0.05)
        if ls.service.conn is not None:
            break
    await phase("returned", 3)
    plant_mode_after = ls.plant.mode
    op = await _operator(url, tags)
    await op.write({"mode": ("auto", ua.StatusCodes.Good)}, ls.clock.now())
    await op.close()
    await phase("auto_again", 3)
    soft = await ls.plant.server.get_node(ua.NodeId.from_string(tags.soft_sensor.p80_um)).read_data_value()
    await ls.stop()
    return phases, np.array(inn), plant_mode_after, soft


@pytest.fixture(scope="module")
def drill(small_scene, small_tags, small_parts, tmp_path_factory):
    from .conftest import free_port

    url = f"opc.tcp://127.0.0.1:{free_port()}"
    audit_dir = tmp_path_factory.mktemp("drill") / "audit"
    handler = Records()
    loggers = [logging.getLogger(n) for n in ("grindtwin.online", "asyncio")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.addHandler(handler)
        lg.setLevel(logging.INFO)
    ls = LockStep(small_scene, small_tags, small_parts, url, audit_dir)
    try:
        phases, innovation, plant_mode, soft = asyncio.run(_drill(ls, url, small_tags))
    finally:
        for lg, level in zip(loggers, levels):
            lg.removeHandler(handler)
            lg.setLevel(level)
    audit = online.read_audit(audit_dir)
    return {"phases": phases, "innovation": innovation, "audit": audit, "rows": pd.DataFrame(ls.rows),
            "records": handler.records, "plant": ls.plant, "plant_mode_after_outage": plant_mode, "tags": small_tags,
            "soft_node": soft}


def _rows(d, phase):
    a, b = d["phases"][phase]
    return d["rows"].iloc[a:b]


def _messages(d, level=logging.WARNING):
    return [r.getMessage() for r in d["records"] if r.levelno >= level]


def test_no_exception_escapes_and_every_cycle_is_audited(drill):
    assert len(drill["audit"]) == len(drill["rows"]) + 1  # and the shutdown row
    assert drill["audit"]["mode"].iloc[-1] == "stopped"
    assert not [r for r in drill["records"] if r.name == "asyncio" and r.levelno >= logging.ERROR]


def test_warm_up_then_auto_writes_the_controllers_moves(drill):
    r = _rows(drill, "warmup_auto")
    assert list(r["mode"][:4]) == ["warmup"] * 4 and (r["mode"][5:] == "auto").all()
    assert not r["written"][:4].any() and r["written"][5:].all()


def test_a_bad_p80_runs_on_the_model_then_holds(drill):
    r = _rows(drill, "bad_p80")
    assert (r["p80_um_quality"] == "bad").all()
    assert r["mode"].iloc[0] == "auto" and "on the model: P80 unusable" in r["reason"].iloc[0]
    held = r[r["mode"] == "hold"]
    assert len(held) >= 2 and not held["written"].any()
    assert held["reason"].str.contains(r"P80 unusable for .* h \(> 0.15 h\)").all()
    a, b = drill["phases"]["bad_p80"]
    assert np.isnan(drill["innovation"][a:b]).all()  # the estimator got no P80
    assert any("p80_um unusable: bad (status BadSensorFailure)" in m for m in _messages(drill))
    r2 = _rows(drill, "recovered_1")
    assert r2["mode"].iloc[-1] == "auto" and r2["written"].iloc[-1]


def test_a_frozen_analyser_is_found_and_held(drill):
    r = _rows(drill, "frozen")
    q = list(r["p80_um_quality"])
    assert "frozen" in q and q[0] == "good"  # frozen only after frozen_after_h of the same value
    assert (r["mode"] == "hold").any()
    assert any("p80_um unusable: frozen (value" in m for m in _messages(drill))
    a, b = drill["phases"]["frozen"]
    frozen_rows = np.flatnonzero(r["p80_um_quality"].to_numpy() == "frozen")
    assert np.isnan(drill["innovation"][a + frozen_rows]).all()


def test_manual_writes_nothing_and_the_return_to_auto_is_bumpless(drill):
    r = _rows(drill, "manual")
    assert (r["mode"] == "manual").all() and not r["written"].any()
    assert r["feed_proposed_tph"].notna().all()  # the controller tracks
    assert (r["feed_actual_tph"].iloc[1:] == 12.0).all()  # the operator's move stands
    back = _rows(drill, "back_to_auto")
    first = back[back["written"]].iloc[0]
    rate = drill["tags"].setpoints.feed_tph.rate_max_per_h * drill["plant"].dt_h
    assert abs(first["feed_sp_tph"] - 12.0) <= rate + 1e-9  # starts where the operator left it
    assert any("bumpless" in m for m in _messages(drill, logging.INFO))


def test_an_outage_is_reported_the_plant_sheds_the_service_and_it_comes_back(drill):
    r = _rows(drill, "outage")
    assert (r["mode"] == "disconnected").all() and not r["written"].any()
    assert r["reason"].str.contains("setpoints left at feed").all()
    msgs = _messages(drill)
    assert any("lost" in m and "the plant keeps the last setpoints" in m for m in msgs)
    assert any("watchdog: no heartbeat" in m for m in msgs)
    assert drill["plant_mode_after_outage"] == "manual"
    ret = _rows(drill, "returned")
    assert (ret["mode"] == "manual").all()  # shed by the watchdog: it waits for the operator
    assert any("connection established" in m for m in _messages(drill, logging.INFO))
    again = _rows(drill, "auto_again")
    assert again["mode"].iloc[-1] == "auto" and again["written"].iloc[-1]


def test_setpoints_stay_within_the_writers_limits(drill):
    w = drill["rows"][drill["rows"]["written"]]
    lim = drill["tags"].setpoints.feed_tph
    assert w["feed_sp_tph"].between(lim.min, lim.max).all()
    steps = (w["feed_sp_tph"] - w["feed_actual_tph"]).abs()
    assert (steps <= lim.rate_max_per_h * drill["plant"].dt_h + 1e-9).all()
    # in auto from one cycle to the next the limit holds on the setpoint itself (it was measured from the actual
    # reading: a lagging or mis-scaled actual let a write jump)
    consecutive = w.index.to_series().diff().eq(1) & w["mode"].eq("auto")
    assert consecutive.sum() >= 3
    assert (w["feed_sp_tph"].diff().abs()[consecutive] <= lim.rate_max_per_h * drill["plant"].dt_h + 1e-9).all()


def test_the_soft_sensor_publishes_the_twins_prediction_of_the_ore_on_the_belt(drill, small_parts):
    last = drill["rows"].iloc[-1]
    dv = drill["soft_node"]
    assert dv.StatusCode.is_good() and dv.Value.Value == last["soft_p80_um"]
    belt = [drill["plant"].published[f"blend.{o}"].Value.Value for o in ("B", "D")]
    ss = small_parts.models.control.steady(feed_tph=last["feed_actual_tph"],
                                           speed_frac_critical=last["speed_actual_frac_critical"], blend=belt)
    assert last["soft_p80_um"] == pytest.approx(ss.p80_um, rel=1e-9)


class _SilentPlant:
    """A session whose requests never come back in time (a plant server too busy to answer)."""

    async def read(self):
        raise asyncio.TimeoutError

    async def close(self):
        pass


def test_a_busy_plant_holds_cycles_and_counts_as_lost_after_three_timeouts(small_parts, small_tags, url, tmp_path,
                                                                             caplog):
    from scenarios.online.service import LOST_AFTER_TIMEOUTS

    small_parts.reset()
    service = online.Service(small_parts, small_tags, online.ServeSettings(
        url, online.ClientSecurity(insecure=True), tmp_path / "audit"), clock=online.ManualClock(3600.0))

    async def go():
        service.conn = _SilentPlant()
        rows = []
        for k in range(LOST_AFTER_TIMEOUTS):  # a sample apart: cycles under half a sample apart are skipped
            service.clock.advance(service.dt_h if k else 0.0)
            rows.append(await service.cycle())
        await service.shutdown("test end")
        return rows

    with caplog.at_level(logging.WARNING, logger="grindtwin.online"):
        rows = asyncio.run(go())
    assert [r["mode"] for r in rows] == ["hold"] * (LOST_AFTER_TIMEOUTS - 1) + ["disconnected"]
    assert "did not answer within 1 s (1 of 3" in rows[0]["reason"]
    assert any("lost (TimeoutError" in r.getMessage() for r in caplog.records)


def test_a_refused_setpoint_write_holds_says_why_and_records_each_setpoint(small_scene, small_tags, small_parts,
                                                                          tmp_path):
    """A feed setpoint the server refused (a tag map's node it may not write): the service stayed in auto, the
    plant's status read 'auto', the audit's reason lost the refusal (overwritten), and the speed setpoint,
    written and applied, was recorded as not written ("setpoints left at none written by this service")."""
    from .conftest import LockStep, free_port

    url = f"opc.tcp://127.0.0.1:{free_port()}"
    wrong = small_tags.model_copy(deep=True)
    wrong.setpoints.feed_tph.node = "ns=2;s=Simulation.P80True_um"  # the plant's own, read-only
    ls = LockStep(small_scene, small_tags, small_parts, url, tmp_path / "audit")
    ls.service = online.Service(small_parts, wrong, online.ServeSettings(
        url, online.ClientSecurity(insecure=True), tmp_path / "audit2", warmup_h=0.2), clock=ls.clock)

    async def run():
        await ls.plant.start()
        # as a read-only display of the feed would hold it (its 210 um beside the 10 t/h feed reading is refused
        # on connecting: a node in other units); the plant's next sample writes its P80 there again
        server, node = ls.plant.server, ua.NodeId.from_string
        feed = server.read_attribute_value(node(small_tags.measurements.feed_tph.node)).Value.Value
        await server.write_attribute_value(node(wrong.setpoints.feed_tph.node), ua.DataValue(ua.Variant(feed)))
        await ls.service.connect()
        await ls.step(8)
        await ls.stop()
    asyncio.run(run())
    rows = pd.DataFrame(ls.rows)
    first = rows.index[rows["feed_tph_written"].notna() & rows["speed_frac_critical_written"].eq(True)][0]
    assert rows.loc[first, "mode"] == "auto" and not rows.loc[first, "feed_tph_written"]
    assert "the server refused writes: {'setpoints.feed_tph': 'BadUserAccessDenied'}" in rows.loc[first, "reason"]
    assert not rows.loc[first, "written"]
    later = rows.loc[first + 1:]
    assert len(later) and later["mode"].eq("hold").all() and not later["speed_frac_critical_written"].any()
    assert later["reason"].str.contains("the server refused the setpoint writes").all()
    assert ls.service.u_written[1] == pytest.approx(rows.loc[first, "speed_sp_frac_critical"])


def test_cycles_started_faster_than_the_samples_do_not_advance_the_estimator(small_scene, small_tags, small_parts,
                                                                            tmp_path):
    """A trigger firing every scan (a gateway refreshing source timestamps) ran a cycle each time, and each
    advanced the estimator a whole sample: 316 cycles in 2.06 plant hours, 15.8 h of model time."""
    from .conftest import LockStep, free_port

    ls = LockStep(small_scene, small_tags, small_parts, f"opc.tcp://127.0.0.1:{free_port()}", tmp_path / "audit")

    async def run():
        await ls.start()
        await ls.step(3)
        model_h, x = ls.service.t_model_h, np.array(ls.service.parts.estimator.x_est, copy=True)
        early = [await ls.service.cycle("new p80_um") for _ in range(3)]  # no plant time has passed
        unchanged = ls.service.t_model_h == model_h and np.array_equal(ls.service.parts.estimator.x_est, x)
        after = await ls.step()
        await ls.stop()
        return early, unchanged, after, model_h
    early, unchanged, after, model_h = asyncio.run(run())
    assert all(r["skipped"] for r in early) and unchanged and ls.service.skipped_cycles == 3
    assert "skipped" not in after and ls.service.t_model_h == pytest.approx(model_h + small_scene.scene.sample_period_h)



async def _until(predicate, what, timeout_s=5.0):
    """Wait (wall clock) for something the event loop delivers: a subscription's report, a reconnection."""
    for _ in range(round(timeout_s / 0.01)):
        if predicate():
            return
        await asyncio.sleep(0.01)
    raise AssertionError(f"timed out waiting for {what}")


def test_after_a_reconnection_the_cycles_follow_the_restarted_servers_samples(small_scene, small_tags, small_parts,
                                                                             tmp_path, caplog):
    """The plant's server restarts and samples half a sample off its old phase; the analyser's reports reach the
    service 1 % of a sample late, give or take 2 %. The model clock, in whole samples on the old phase, skipped
    reports a little under half a sample after it, the next ran two samples on; while the plant was away, the
    timer's cycles (half a sample off the model clock after the trigger's 1.5-sample timeout) were skipped every
    other one. The run loop's cycles are started here as it starts them, on a manual clock (times in samples)."""
    from scenarios.online.service import TIMER

    from .conftest import LockStep, free_port

    tags = small_tags.model_copy(deep=True)
    tags.cycle.on_new = "p80_um"
    ls = LockStep(small_scene, tags, small_parts, f"opc.tcp://127.0.0.1:{free_port()}", tmp_path / "audit")
    ls.plant.watchdog_h = 10.0  # the outage must not shed the service: this is about timing
    s, dt = ls.service, small_scene.scene.sample_period_h
    latency, jitter = 0.01, 0.02  # of a sample: the report's way to the service, and its spread
    shift = 0.52  # the restarted server's samples on the old ones': its reports straddle half a sample after them
    now = [0.0]

    def to(t):
        ls.clock.advance((t - now[0]) * dt)
        now[0] = t

    async def tick(t):
        to(t)
        await ls.plant.tick()

    async def cycle(started_by):
        row = await s.cycle(started_by)
        return row | {"t": s.clock.hours_between(s.start, s.clock.now()) / dt, "model_t": s.t_model_h / dt}

    async def sample(t, k):
        """The plant's sample at ``t`` and the cycle its analyser's report starts (as Service.run)."""
        await tick(t)
        await _until(lambda: s.new_data, "the analyser's report")
        to(t + latency + jitter * (-1) ** k)
        s.new_data = False
        return await cycle("new p80_um")

    async def run():
        await ls.plant.start()
        for k in (1, 2, 3):  # past the analyser's dead time: a report every sample from now on
            await tick(k)
        await s.connect()
        await _until(lambda: s.new_data, "the subscription's first report")
        to(3 + latency + jitter)
        s.new_data = False
        before = [await cycle("new p80_um")] + [await sample(k, k) for k in range(4, 9)]  # the last one late
        await ls.plant.drop()
        outage = []
        for k in range(4):  # the timer: 1.5 samples after the last cycle started, then every sample
            await tick(9 + k)
            to(before[-1]["t"] + 1.5 + k + latency + jitter * (-1) ** k)
            outage.append(await cycle(TIMER))
        await ls.plant.restore()
        await _until(lambda: s.conn is not None and s.new_data, "the reconnection and its first report")
        s.new_data = False
        outage.append(await cycle("new p80_um"))  # the value the node held: not a new sample
        after = [await sample(13 + shift + k, k) for k in range(6)]  # the restarted server's phase
        await ls.stop()
        return before, outage, after

    with caplog.at_level(logging.INFO, logger="grindtwin.online"):
        before, outage, after = asyncio.run(run())
    assert not any(r.get("skipped") for r in before[1:])
    assert [r.get("mode") for r in outage[:4]] == ["disconnected"] * 4, [(r["t"], r["model_t"]) for r in outage]
    # the first fresh report may come under half a sample after the model clock (skipped); every later one
    # starts a cycle that runs, in auto, on the model clock's sample (within the reports' spread), not a sample late
    assert [r.get("skipped", False) for r in after[1:]] == [False] * 5, [(r["t"], r["model_t"]) for r in after]
    assert all(r["mode"] == "auto" and r["written"] for r in after[1:])
    assert [r["t"] - r["model_t"] for r in after[1:]] == pytest.approx([0.0] * 5, abs=2 * jitter + 1e-9)
    # said once, with the phase the clock moved by (to the nearest sample: the first fresh report's cycle),
    # and no more "the trigger fires faster than the samples" after the reconnection
    messages = [r.getMessage() for r in caplog.records]
    said = [m for m in messages if "after the reconnection" in m]
    assert len(said) == 1 and f"come {shift - round(shift):+.2f} of a sample off" in said[0], said
    reconnected = max(i for i, m in enumerate(messages) if m.startswith("connected to"))
    assert not [m for m in messages[reconnected:] if "the trigger fires faster" in m]


@pytest.mark.parametrize("fails", ["after", "during"])
def test_a_connection_lost_around_the_setpoint_write_is_audited_as_it_happened(small_scene, small_tags, small_parts,
                                                                                tmp_path, fails):
    """Lost after the setpoint write (at the soft sensor's), the row read written False and disconnected while the
    plant had the move (feed_tph_written True, and the log's 'setpoints left at' named it); lost during it, the row
    did not say which move may have landed."""
    from .conftest import LockStep, free_port

    ls = LockStep(small_scene, small_tags, small_parts, f"opc.tcp://127.0.0.1:{free_port()}", tmp_path / "audit")

    async def run():
        await ls.start()
        await ls.step(10)
        conn, write = ls.service.conn, ls.service.conn.write

        async def cut(items, t):
            if any(k.startswith("soft_sensor." if fails == "after" else "setpoints.") for k in items):
                raise ConnectionError("connection reset by peer")
            return await write(items, t)
        conn.write = cut
        row = await ls.step()
        await ls.stop()
        return row
    row = asyncio.run(run())
    assert row["mode"] == "disconnected"
    if fails == "after":
        assert row["written"] and row["feed_tph_written"] and row["speed_frac_critical_written"]
        assert ls.service.u_written[0] == row["feed_sp_tph"]
        assert row["reason"].startswith("auto: setpoints written (")
        assert f"then no connection: setpoints left at feed {row['feed_sp_tph']:.4g} t/h" in row["reason"]
    else:
        assert not row["written"] and "feed_tph_written" not in row
        assert f"a setpoint write (feed {row['feed_sp_tph']:.4g} t/h" in row["reason"]
        assert "was in flight: the plant may have it" in row["reason"]


def _lockstep_serving(tags, small_scene, small_tags, small_parts, tmp_path):
    """The small scene in lock step, its plant behind the tests' tag map, served with the tag map ``tags``."""
    from .conftest import LockStep, free_port

    url = f"opc.tcp://127.0.0.1:{free_port()}"
    ls = LockStep(small_scene, small_tags, small_parts, url, tmp_path / "audit")
    ls.service = online.Service(small_parts, tags, online.ServeSettings(
        url, online.ClientSecurity(insecure=True), tmp_path / "audit2", warmup_h=0.2), clock=ls.clock)
    return ls


def test_a_refused_soft_sensor_write_is_logged_and_audited(small_scene, small_tags, small_parts, tmp_path, caplog):
    """A soft sensor node the server refuses (read-only) kept an older prediction on the operator's screen: the
    write's result was not read, nothing was logged or audited."""
    wrong = small_tags.model_copy(deep=True)
    wrong.soft_sensor.p80_um = "ns=2;s=Simulation.P80True_um"  # the plant's own, read-only
    ls = _lockstep_serving(wrong, small_scene, small_tags, small_parts, tmp_path)

    async def run():
        await ls.start()
        await ls.step(3)
        await ls.stop()
    with caplog.at_level(logging.WARNING, logger="grindtwin.online"):
        asyncio.run(run())
    published = [r for r in ls.rows if "soft_p80_um" in r]
    assert published and all("the server refused the soft sensor's writes: {'soft_sensor.p80_um': "
                             "'BadUserAccessDenied'}" in r["reason"] for r in published)
    assert sum("refused the soft sensor's writes" in m for m in caplog.messages) == 1


def test_a_refused_heartbeat_write_is_logged_when_it_starts_not_every_cycle(small_scene, small_tags, small_parts,
                                                                           tmp_path, caplog):
    """A heartbeat (or status) node the server refuses was logged as an error every cycle (each cycle writes it);
    now it is logged when the refusal starts, as a soft sensor's, and each row's reason still says it."""
    wrong = small_tags.model_copy(deep=True)
    wrong.heartbeat.node = "ns=2;s=Simulation.P80True_um"  # the plant's own, read-only
    ls = _lockstep_serving(wrong, small_scene, small_tags, small_parts, tmp_path)

    async def run():
        await ls.start()
        await ls.step(4)
        conn = ls.service.conn  # the node put right (as a restart with the tag map mended would)
        conn._write_ids["heartbeat"] = ua.NodeId.from_string(small_tags.heartbeat.node)
        conn._variants["heartbeat"] = ua.VariantType.UInt32
        await ls.step(2)
        await ls.stop()
    with caplog.at_level(logging.INFO, logger="grindtwin.online"):
        asyncio.run(run())
    assert all("the server refused writes: {'heartbeat': 'BadUserAccessDenied'}" in r["reason"] for r in ls.rows[:4])
    assert not any("refused" in r["reason"] for r in ls.rows[4:])
    assert sum("refused" in m for m in caplog.messages) == 1, caplog.messages
    assert sum("heartbeat or status write good again" in m for m in caplog.messages) == 1
