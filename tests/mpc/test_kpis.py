"""mpc.kpis: the trapezoid rule against exact integrals, the fed tonnage of a held feed, and
refusals where a wrong number was silent."""

import math

import numpy as np
import pandas as pd
import pytest

from mpc import FixedInputs, LoopSettings, Sensors, run_closed_loop
from mpc.kpis import (cumulative, fresh_feed_t, held_cumulative, held_integral, integral, loop_kpis,
                      outside_band_frac, p80_iae_um_h, specific_energy_kwh_t, within_band_frac)


def test_the_trapezoid_rule_is_exact_for_piecewise_linear_rates():
    t = np.array([0.0, 0.5, 2.0, 3.0])
    assert integral(t, 2.0 * t + 1.0) == pytest.approx(3.0 ** 2 + 3.0)  # int_0^3 (2t + 1) dt
    assert integral(t, 4.0) == pytest.approx(12.0)
    np.testing.assert_allclose(cumulative(t, 2.0 * t), t ** 2)
    # |P80 - target| crossing zero between samples: the trapezoid of the absolute samples
    assert p80_iae_um_h([0.0, 1.0], [200.0, 220.0], 210.0) == pytest.approx(10.0)


def test_a_rate_of_another_length_or_shuffled_times_are_refused():
    """[0, 1, 2] h with two rates gave 3.0, and shuffled times a wrong integral, silently."""
    with pytest.raises(ValueError, match="3 times and 2 rates"):
        integral([0, 1, 2], [1, 2])
    with pytest.raises(ValueError, match="strictly increasing"):
        integral([0, 2, 1], [1, 1, 1])


def test_a_missing_sample_counts_as_outside_every_band():
    """within_band counted a NaN P80 outside and outside_band counted a NaN load inside."""
    assert within_band_frac([200.0, math.nan, 205.0, 210.0], 210.0) == 0.75
    assert outside_band_frac([1.0, math.nan, 0.5], (0.8, 1.2)) == pytest.approx(2.0 / 3.0)


def test_specific_energy_of_a_held_feed_step_by_hand():
    """1000 kW for 2 h; the feed 100 t/h over the first hour, a move to 200 t/h at 1 h held over
    the second, and a last move (50 t/h) made at 2 h, after the run: 300 t fed, 2000 kWh. The
    trapezoid of the feed made it 150 + 125 = 275 t."""
    frame = pd.DataFrame({"time_h": [0.0, 1.0, 2.0], "power_kw": 1000.0, "feed_tph": [100.0, 200.0, 50.0]})
    np.testing.assert_array_equal(held_cumulative(frame["time_h"], frame["feed_tph"]), [0.0, 100.0, 300.0])
    assert fresh_feed_t(frame) == 300.0
    assert specific_energy_kwh_t(frame) == 2000.0 / 300.0
    # the plant's own tally wins over the feed column (an open loop's ramp from 100 to 200 t/h over
    # the first hour fed 150 t there, not the held 100), over the frame's span (a tally started
    # before the frame's first row, as the plant-server's)
    frame["fed_t"] = [40.0, 190.0, 390.0]
    assert fresh_feed_t(frame) == 350.0
    assert specific_energy_kwh_t(frame) == 2000.0 / 350.0
    assert math.isnan(specific_energy_kwh_t(frame.assign(fed_t=0.0)))  # nothing fed: undefined
    assert math.isnan(specific_energy_kwh_t(frame.drop(columns="power_kw")))


def test_a_closed_loops_feed_tally_is_its_feed_integrated_as_held(plant_twin):
    """The plant's fed_t of a closed loop is exactly its moves held over their samples, and the
    loop's specific energy is the energy over that tally (a feed moved on every sample, so the
    trapezoid differs: the comparison can fail)."""
    moves = iter([30.0, 24.0, 36.0, 21.0, 33.0, 45.0])

    class StepFeed(FixedInputs):
        def make_step(self, x_est, d_preview, u_prev, y_meas=None):
            self.u_fixed = np.array([next(moves), 0.7])
            return super().make_step(x_est, d_preview, u_prev, y_meas)

    ss = plant_twin.steady(feed_tph=30.0, speed_frac_critical=0.7, blend=[1.0, 0.0])
    res = run_closed_loop(plant_twin.model, StepFeed([30.0, 0.7]), None, lambda t: [1.0, 0.0], Sensors(),
                          ss.x, ss.u, LoopSettings(0.25, 0.05, seed=1, target_p80_um=210.0))
    f = res.frame
    t, feed = f["time_h"].to_numpy(), f["feed_tph"].to_numpy()
    held = held_integral(t, feed)
    assert held == pytest.approx(0.05 * (30 + 24 + 36 + 21 + 33), rel=1e-12)
    assert f["fed_t"].iloc[-1] == pytest.approx(held, rel=1e-9)
    assert abs(integral(t, feed) - held) > 0.1  # the trapezoid: 0.75 t more (half the unapplied 45)
    assert res.kpis["specific_energy_kwh_t"] == integral(t, f["power_kw"]) / f["fed_t"].iloc[-1]
    assert loop_kpis(f.drop(columns="fed_t"))["specific_energy_kwh_t"] == pytest.approx(
        res.kpis["specific_energy_kwh_t"], rel=1e-9)
