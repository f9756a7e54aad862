"""A reading outside its plausible range, served over OPC UA with a Good status code, is Bad: the
estimator does not get it, the actual inputs fall back to the last written setpoints, the audit
marks it bad and the log names the tag, the value and the range."""

import asyncio
import logging
import math

from asyncua import ua

from .conftest import LockStep

#: Every measurement of the small tag map, each far outside its physical range.
OUT_OF_RANGE = {"p80_um": -5.0, "power_kw": -100.0, "load_frac": -0.2, "feed_tph": -3.0,
                "speed_frac_critical": 3.0}


async def _cycle_with(ls: LockStep, tags, values: dict) -> dict:
    """One lock-step sample whose plant nodes are overwritten with ``values`` (Good, timestamped
    now, as a faulty instrument would send them) before the service reads them."""
    ls.clock.advance(ls.dt)
    await ls.plant.tick()
    for role, value in values.items():
        node = getattr(tags.measurements, role).node
        await ls.plant.server.write_attribute_value(ua.NodeId.from_string(node), ua.DataValue(
            ua.Variant(value, ua.VariantType.Double), ua.StatusCode(ua.StatusCodes.Good), ls.clock.now()))
    row = await ls.service.cycle()
    ls.rows.append(row)
    return row


def test_out_of_range_readings_are_bad_and_not_passed_on(small_scene, small_tags, small_parts, url, tmp_path,
                                                         caplog):
    ls = LockStep(small_scene, small_tags, small_parts, url, tmp_path / "audit")
    ekf = small_parts.estimator
    seen = []  # (y, u) of each EKF update

    def spy(y, u, d, _step=ekf.make_step):
        seen.append((list(y), list(u)))
        return _step(y, u, d)

    async def go():
        await ls.start()
        await ls.step(8)  # warm-up (0.2 h), then auto: setpoints written
        written = ls.service.u_written.copy()
        seen.clear()
        bad = await _cycle_with(ls, small_tags, OUT_OF_RANGE)
        bad_seen = list(seen)
        seen.clear()
        good = await _cycle_with(ls, small_tags, {"p80_um": 205.0})
        await ls.stop()
        return written, bad, bad_seen, good

    ekf.make_step = spy
    try:
        with caplog.at_level(logging.WARNING, logger="grindtwin.online"):
            written, bad, bad_seen, good = asyncio.run(go())
    finally:
        del ekf.make_step
    assert all(bad[f"{role}_quality"] == "bad" for role in OUT_OF_RANGE)
    assert math.isnan(bad["p80_um"])
    (y, u), = bad_seen
    assert all(math.isnan(v) for v in y)  # no P80, power or load update from the out-of-range values
    assert u == list(written)  # the inputs the plant keeps stand in for the actual feed and speed
    assert (bad["feed_actual_tph"], bad["speed_actual_frac_critical"]) == tuple(written)
    assert bad["mode"] == "auto" and "on the model: P80 unusable" in bad["reason"]
    messages = [r.getMessage() for r in caplog.records]
    top = small_scene.mill.size_classes.top_um
    assert any(f"p80_um unusable: bad (p80_um = -5 is outside its plausible range [1, {top:g}) um)" in m
               for m in messages)
    assert any("speed_frac_critical = 3 is outside its plausible range (0, 1) of critical" in m for m in messages)
    # the same injection inside the range is used: the check is what kept -5 out
    assert good["p80_um_quality"] == "good" and good["p80_um"] == 205.0
    # the audit row says why, each cycle: the reason beside the quality (empty when good)
    assert bad["p80_um_quality_reason"] == f"p80_um = -5 is outside its plausible range [1, {top:g}) um"
    assert good["p80_um_quality_reason"] == ""
    assert bad["p80_um_raw"] == -5.0 and good["p80_um_raw"] == 205.0  # what the tag read is kept, used or not
    assert seen[-1][0][0] == 205.0


def test_a_takeover_from_an_input_outside_its_bounds_holds_rather_than_jump(small_scene, small_tags, small_parts,
                                                                            url, tmp_path):
    """A feed in kg/s of 18 t/h reads 5, within a feeder's following of the feeds the service writes (8 to 30 t/h),
    and with no Good value in the setpoint node nothing else to compare it with: the first move in auto started from
    5 and was written at the bound, 8 t/h, the plant's feed stepped from 18 to 8 t/h against 0.5 t/h a sample (the
    bounds won over the rate limit). A takeover from an actual input outside its bounds by more than a sample's rate
    holds: nothing written, the reason names the input, its bounds and the rate."""
    import scenarios.online as online

    ls = LockStep(small_scene, small_tags, small_parts, url, tmp_path / "audit")
    publish, node = ls.plant._publish, ua.NodeId.from_string

    def in_kg_s(vals, wall):
        publish(vals, wall)
        dv = ls.plant.published["feed_tph"]
        ls.plant.published["feed_tph"] = ua.DataValue(ua.Variant(dv.Value.Value / 3.6, ua.VariantType.Double),
                                                      dv.StatusCode, dv.SourceTimestamp)

    async def run():
        ls.plant._publish = in_kg_s
        await ls.plant.start()
        op = online.PlantConnection(url, online.ClientSecurity(insecure=True), {},
                                    {"feed": small_tags.setpoints.feed_tph.node})
        await op.open()
        await op.write({"feed": (18.0, ua.StatusCodes.Good)}, ls.clock.now())  # an operator's, then the node is lost
        await op.close()
        await ls.step()
        await ls.plant.server.write_attribute_value(node(small_tags.setpoints.feed_tph.node), ua.DataValue(
            ua.Variant(None, ua.VariantType.Null), ua.StatusCode(ua.StatusCodes.BadWaitingForInitialData)))
        ls.rows.clear()
        await ls.service.connect()
        await ls.step(6)
        await ls.stop()

    asyncio.run(run())
    assert ls.plant.u[0] == 18.0 and not any(r["written"] for r in ls.rows), [r.get("feed_sp_tph") for r in ls.rows]
    taking_over = [r for r in ls.rows if r["mode"] != "warmup"]
    assert taking_over and all(r["mode"] == "hold" for r in taking_over)
    assert all("the actual feed_tph 5 lies 3 below its bounds [8, 30], beyond the rate limit (0.5 a sample)"
               in r["reason"] for r in taking_over), taking_over[0]["reason"]
