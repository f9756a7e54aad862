"""The served controller's time: a step of the wall clock (NTP, an operator) moves neither the service's time
nor its estimator; after a gap of samples the controller's previous plan is moved on by the samples missed."""

import asyncio
import logging
import math

import pytest

from .conftest import LockStep


def test_a_wall_clock_step_moves_neither_the_service_time_nor_the_estimator(small_scene, small_tags, small_parts,
                                                                            url, tmp_path, caplog):
    """Stepped back 1 h, every cycle was skipped for an hour (nothing written, no heartbeat: the plant's watchdog
    shed the service), said as 'the trigger fires faster than the samples'; stepped on 0.5 h, the estimator
    predicted 10 samples blind in one cycle of one sample."""
    dt = small_scene.scene.sample_period_h
    ls = LockStep(small_scene, small_tags, small_parts, url, tmp_path / "audit")

    async def run():
        await ls.start()
        await ls.step(12)
        rows = []
        for step_h in (-1.0, 0.5):
            ls.clock.step_wall(step_h)
            model_h = ls.service.t_model_h
            rows += [await ls.step() for _ in range(3)]
            assert ls.service.t_model_h == pytest.approx(model_h + 3 * dt)
        await ls.stop()
        return rows

    rows = asyncio.run(run())
    assert not any(r.get("skipped") for r in rows)
    assert all(r["mode"] == "auto" and r["written"] for r in rows)
    assert [r["service_time_h"] for r in rows] == pytest.approx([(13 + k) * dt for k in range(6)])
    steps = [m for m in caplog.messages if "the wall clock stepped" in m]
    assert len(steps) == 2 and "-1 plant h" in steps[0] and "+0.5 plant h" in steps[1]


def test_after_an_outage_longer_than_the_horizon_a_failed_step_holds_the_input(small_scene, small_tags, small_parts,
                                                                                url, tmp_path):
    """The controller plans nothing while the service is disconnected: told of one sample since its last step, its
    failed steps after an outage of 6 samples (horizon 5) applied the expired plan (audited shifted_plan; its moves
    here those of holding, a plan that moves on is in tests/mpc/test_nmpc.py)."""
    ls = LockStep(small_scene, small_tags, small_parts, url, tmp_path / "audit")
    ls.plant.watchdog_h = float("inf")  # a DCS without a watchdog: the plant stays in auto through the outage
    ctrl = small_parts.controller
    solver = ctrl._solver

    def broken(**kwargs):
        raise RuntimeError("forced failure")

    async def run():
        await ls.start()
        await ls.step(12)
        await ls.plant.drop()
        outage = [await ls.step() for _ in range(ctrl.settings.horizon_steps + 1)]
        await ls.plant.restore()
        for _ in range(100):  # the reconnection's back-off runs on wall time
            await asyncio.sleep(0.05)
            if ls.service.conn is not None:
                break
        ctrl._solver = broken
        try:
            rows = [await ls.step() for _ in range(2)]
        finally:
            ctrl._solver = solver
        await ls.stop()
        return outage, rows

    outage, rows = asyncio.run(run())
    assert all(r["mode"] == "disconnected" for r in outage)
    for row in rows:
        moved = {k: (row[f"{k}_proposed{u}"], row[f"{k}_actual{u}"]) for k, u in (("feed", "_tph"),
                                                                                   ("speed", "_frac_critical"))}
        assert row["mode"] == "auto" and row["fallback"] == "hold_input", (row["fallback"], moved)
        assert all(proposed == actual for proposed, actual in moved.values()), moved


def test_a_move_whose_solve_overran_its_sample_is_not_written(small_scene, small_tags, small_parts, url, tmp_path,
                                                              caplog):
    """A solve that overran its sample wrote its move late, computed from readings a sample old, into the next
    sample (the run loop logged the overrun, the audit had solve_s, nothing discarded the move). The move is
    discarded, the plant keeps the last written setpoints, and the row, the log and a count say so."""
    dt = small_scene.scene.sample_period_h
    ls = LockStep(small_scene, small_tags, small_parts, url, tmp_path / "audit")
    ctrl = small_parts.controller
    make_step = ctrl.make_step

    def slow(*args, **kwargs):
        ls.clock.advance(1.2 * dt)  # the solve takes longer than a sample
        return make_step(*args, **kwargs)

    async def run():
        await ls.start()
        before = await ls.step(6)
        ctrl.make_step = slow
        try:
            late = await ls.step()
        finally:
            ctrl.make_step = make_step
        after = await ls.step()
        await ls.stop()
        return before, late, after

    with caplog.at_level(logging.INFO, logger="grindtwin.online"):
        before, late, after = asyncio.run(run())
    assert late["mode"] == "auto" and not late["written"], late  # it was written, a sample late
    assert before["mode"] == "auto" and before["written"] and not before["move_late"] and late["move_late"]
    assert not late["feed_tph_written"] and math.isnan(late["feed_sp_tph"])
    assert "after its sample's readings: the next sample had begun, the move is discarded" in late["reason"]
    assert f"setpoints stay at feed {before['feed_sp_tph']:.4g} t/h" in late["reason"]
    assert after["written"] and not after["move_late"] and ls.service.late_moves == 1
    assert ls.service.u_written[0] == after["feed_sp_tph"]
    assert sum("the move is discarded" in m for m in caplog.messages) == 1
    assert any("late moves good again" in m for m in caplog.messages)
    assert any("1 late move(s) discarded" in m for m in caplog.messages)
