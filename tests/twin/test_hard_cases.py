"""Hard cases finish with finite, non-negative results and a closed mass balance."""

import math

import numpy as np
import pytest

from twin.breakage import BreakageParams
from twin.sizes import SizeGrid
from twin.errors import TwinInputError
from twin.twin import DEFAULT_EFFECTS, Twin

EFFECTS = [*DEFAULT_EFFECTS, "slowing_down"]


def _check(run, model):
    masses = run.states[:, : model.n_mass]
    assert np.all(np.isfinite(run.states)) and masses.min() >= 0.0
    assert run.mass_balance_error() < 1e-8
    p80 = run.frame["p80_um"].to_numpy()
    assert np.all(np.isfinite(p80[run.frame["holdup_t"] > 0]))


def test_selection_rates_spanning_six_decades():
    def stiff(ore, coefficients):
        return BreakageParams(se_1mm_t_kwh=5.0, alpha=2.0, mu_um=1e6, Lambda=2.5)

    t = Twin("B", effects=EFFECTS, breakage_map=stiff)
    s = t.spec.breakage[0].selection_per_h[:-1]
    assert s.max() / s.min() > 1e6
    run = t.simulate(3.0, 0.05, rtol=1e-10, atol_rel=1e-12)
    _check(run, t.model)
    ss = t.steady()
    assert ss.x.min() >= 0.0 and np.isfinite(ss.p80_um)


def test_zero_feed_empties_the_mill():
    t = Twin("B", effects=EFFECTS)
    # the balance check (1e-8) is the integrator's default relative tolerance itself: a decade
    # tighter keeps it a check of conservation over the 30 h, not of the tolerance
    run = t.simulate(30.0, 0.5, feed_tph=0.0, rtol=1e-9, atol_rel=1e-11)
    _check(run, t.model)
    assert run.frame["holdup_t"].iloc[-1] < 0.05 * run.frame["holdup_t"].iloc[0]
    assert t.steady(feed_tph=0.0).outputs["holdup_t"] == 0.0
    assert math.isnan(t.steady(feed_tph=0.0).outputs["specific_energy_kwh_t"])  # as the trajectory's
    # energy per tonne fed is undefined without feed: NaN, not the model's division floor (~1e7)
    assert run.frame["specific_energy_kwh_t"].isna().all() and (run.frame["power_kw"] > 0).all()


def test_a_feed_mostly_of_fines_passes_them_straight_through():
    """Three quarters of the feed in the sink (below the finest sieve) leaves as product unchanged,
    mass conserved; a feed whose P80 itself lies in the sink is refused (its P80 is not on the grid,
    and the product's read as an extrapolation inside one class)."""
    grid = SizeGrid()
    feed = np.zeros(grid.count)
    feed[-2:] = (0.25, 0.75)
    t = Twin("B", effects=EFFECTS, feed_psd=feed)
    ss = t.steady()
    assert ss.psd.sum() == pytest.approx(ss.feed_tph, rel=1e-9)
    assert ss.psd[-1] >= 0.75 * ss.feed_tph * (1 - 1e-9)
    run = t.simulate(3.0, 0.1)
    _check(run, t.model)
    with pytest.raises(TwinInputError, match="below the size grid's finest sieve"):
        Twin("B", effects=EFFECTS, feed_p80_um=1.0)


def test_single_class_feed():
    grid = SizeGrid()
    feed = np.zeros(grid.count)
    feed[3] = 1.0
    t = Twin("B", effects=EFFECTS, feed_psd=feed)
    run = t.simulate(3.0, 0.1, x0=np.zeros(t.model.n_x))
    _check(run, t.model)
    ss = t.steady()
    assert ss.psd[:3].sum() == pytest.approx(0.0, abs=1e-12)  # nothing coarser than the feed


@pytest.mark.parametrize("speed", [0.90, 0.99])
def test_speed_near_critical(speed):
    t = Twin("B", effects=EFFECTS)
    run = t.simulate(3.0, 0.1, speed_frac_critical=speed)
    _check(run, t.model)
    assert t.steady(speed_frac_critical=speed).load_status in ("stable", "over")


def test_holdup_near_zero_refills():
    t = Twin("B", effects=EFFECTS)
    x0 = t.model.initial_state(load_frac=1e-6)
    run = t.simulate(5.0, 0.05, x0=x0)
    _check(run, t.model)
    assert run.frame["load_frac"].iloc[-1] > 0.5


def test_overloaded_mill_is_reported_and_recovers():
    t = Twin("B", effects=EFFECTS)
    assert t.steady(feed_tph=0.08).load_status == "over"
    run = t.simulate(10.0, 0.1, x0=t.model.initial_state(load_frac=3.0))
    _check(run, t.model)
    assert run.frame["load_frac"].iloc[-1] == pytest.approx(t.steady().outputs["load_frac"], rel=1e-3)


def test_thousand_hour_run():
    t = Twin(["B", "D"], effects=EFFECTS)
    run = t.simulate(1000.0, 1.0, blend=lambda th: [0.5 + 0.5 * np.sin(th / 50.0) ** 2, 0.5 - 0.5 * np.sin(th / 50.0) ** 2])
    _check(run, t.model)


def test_sixty_size_classes():
    grid = SizeGrid(top_um=6700.0, ratio=2 ** 0.2, count=60)
    t = Twin(["B", "D"], effects=EFFECTS, grid=grid)
    run = t.simulate(2.0, 0.1)
    _check(run, t.model)
    # the discretisation error of the 25-class grid is measured in benchmarks/twin_accuracy.py
    coarse = Twin(["B", "D"], effects=EFFECTS).steady()
    assert t.steady().p80_um == pytest.approx(coarse.p80_um, rel=0.15)


def test_extreme_mineralogy_all_quartz_and_all_clay():
    from twin.ore.mineralogy import Mineralogy, Texture

    quartz = Mineralogy({"quartz": 100.0}, Texture(1000.0, 1.0, 0.0), name="quartzite")
    clay = Mineralogy({"kaolinite": 100.0}, Texture(2.0, 0.2, 1.0), name="kaolin")
    for ore in (quartz, clay):
        t = Twin(ore, effects=EFFECTS)
        ss = t.steady()
        assert ss.x.min() >= 0 and np.isfinite(ss.p80_um)
        assert t.calibration.breakage(ore).se_1mm_t_kwh > 0  # the default map reaches any mineralogy


def test_simulate_refuses_a_blend_that_does_not_sum_to_one_naming_the_time():
    """The issue's case: a blend summing to 1.4 ran with a 27 % mass error."""
    from twin.errors import TwinInputError

    t = Twin(["B", "D"], effects=["breakage", "transport"])
    with pytest.raises(TwinInputError, match=r"'blend' parameter of Twin .*summing to 1 within 0\.001\. "
                                             r"Got \[1\.0, 0\.4\].*"
                                             r"at t = 0\.5 h"):
        t.simulate(1.0, 0.1, blend=lambda th: [1.0, 0.0] if th < 0.5 else [1.0, 0.4])


def test_simulate_refuses_a_speed_in_percent_with_the_hint():
    from twin.errors import TwinInputError

    t = Twin("B", effects=["breakage", "transport", "speed"])
    with pytest.raises(TwinInputError, match=r"speed_frac_critical.*\(0, 1\) \(a fraction of critical speed, "
                                             r"not percent\)\. Got 72.*at t = 0 h"):
        t.simulate(1.0, 0.1, speed_frac_critical=72)


def test_a_ramp_is_integrated_as_the_ramp_it_is():
    """Inputs are linear between samples: a ramp sampled every 6 min gives the run sampled every
    22.5 s (the same ramp, 16x finer); held per sample (a staircase) it was O(dt) off."""
    t = Twin(["B", "D"], mill="industrial")
    x0 = t.steady(feed_tph=30.0, blend=[1.0, 0.0]).x

    def ramp(th):
        w = min(max((th - 0.5) / 0.5, 0.0), 1.0)
        return [1.0 - 0.4 * w, 0.4 * w]

    coarse = t.simulate(2.0, 0.1, feed_tph=30.0, blend=ramp, x0=x0)
    fine = t.simulate(2.0, 0.1 / 16, feed_tph=30.0, blend=ramp, x0=x0)
    p80_fine = fine.frame["p80_um"].to_numpy()[::16]
    np.testing.assert_allclose(coarse.frame["p80_um"], p80_fine, rtol=1e-6)
    np.testing.assert_allclose(coarse.fed_t, fine.fed_t[::16], rtol=1e-9)
    assert coarse.mass_balance_error() < 1e-8


def test_only_jumps_and_bends_restart_the_integrator():
    """A 30-min ramp on one-minute samples is three stretches (before, ramp, after), not one
    per sample; a step is two; a staircase held per sample restarts at every step of it."""
    from twin.solve.simulate import JUMP_PROBE_FRAC, input_stretches

    dt, n = 1 / 60, 480
    times = np.arange(n + 1) * dt

    def stretches(fn):
        values = np.array([[fn(t)] for t in times])
        before = np.array([[fn(t - JUMP_PROBE_FRAC * dt)] for t in times[1:]])
        return input_stretches(values, before)

    assert stretches(lambda t: min(max((t - 3.0) / 0.5, 0.0), 1.0)) == [(0, 180), (180, 210), (210, 240),
                                                                          (240, 480)]
    assert stretches(lambda t: 0.0 if t < 3.0 - 1e-12 else 1.0) == [(0, 180), (180, 240), (240, 480)]
    assert len(stretches(lambda t: np.floor(t / dt + 1e-9) % 2)) == n



@pytest.mark.parametrize("dead_time_h", [1e-5, 1e-7, 1e-9])
def test_a_stiff_analyser_lag_does_not_stop_the_steady_state(dead_time_h):
    """The analyser's lag chain (sensor_delay) makes no difference at steady state, however short
    its dead time: Newton converges (its residual is weighed per state, by the state's own rate)
    and gives the masses of the twin without the lag. With every residual weighed by the nominal
    flow, the lag's round-off alone could stay above the tolerance: at 1e-7 and 1e-9 h Newton
    failed at some of these feeds and the fallback integration (IDAS) did too."""
    grid = SizeGrid(6700.0, 2.5, 7)
    plain = Twin(["B", "D"], mill="industrial", grid=grid)
    lagged = Twin(["B", "D"], mill="industrial", grid=grid, effects=list(DEFAULT_EFFECTS) + ["sensor_delay"],
                  effect_options={"sensor_delay": {"dead_time_h": dead_time_h}})
    n = lagged.model.n_mass
    for feed in (20.0, 21.0, 26.0, 28.0, 30.0):
        ref = plain.steady(feed_tph=feed, speed_frac_critical=0.7, blend=[1.0, 0.0])
        ss = lagged.steady(feed_tph=feed, speed_frac_critical=0.7, blend=[1.0, 0.0])
        assert ss.method == "newton"
        np.testing.assert_allclose(ss.x[:n], ref.x[:n], rtol=1e-8, atol=1e-12 * ref.x[:n].max())
        # the analyser's lag of the model's smooth P80
        assert ss.outputs["p80_measured_um"] == pytest.approx(ss.outputs["p80_smooth_um"], rel=1e-9)


def test_a_steady_state_newton_cannot_find_says_where_the_mill_was_going(monkeypatch):
    """When Newton failed after the long integration and the mill had not overloaded, the error said only that
    Newton failed: now the hold-up it was at and its rate of change (here, a Newton made to fail at a state
    that is steady: the nominal lab mill's own hold-up, changing by nothing)."""
    from twin.errors import SolverError
    from twin.solve import steady

    twin = Twin("B", mill="lab")
    ss = twin.steady(feed_tph=0.031, speed_frac_critical=0.70)
    monkeypatch.setattr(steady, "_newton", lambda model, x, u, d: (x, None, False))
    with pytest.raises(SolverError) as info:
        twin.steady(feed_tph=0.031, speed_frac_critical=0.70)
    text = str(info.value)
    held = float(text.split("By then the mill held ")[1].split(" t ")[0])
    assert held == pytest.approx(ss.outputs["holdup_t"], rel=5e-3)  # printed to 3 digits
    rate = float(text.split("changing by ")[1].split(" t/h")[0])
    assert abs(rate) < 1e-9 * 0.031
