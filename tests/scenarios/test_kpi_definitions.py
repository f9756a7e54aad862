"""One definition per KPI: a scene's run (scenarios.run.compute_kpis) and its closed loop
(mpc.loop_kpis) give the same specific energy on the same frame, the value of a case computed by
hand (they differed in how the fed tonnage was integrated: the last row's held feed)."""

import numpy as np
import pandas as pd
import pytest

from mpc import loop_kpis
from scenarios.run import compute_kpis
from scenarios.scene import load_scene


def _loop_frame(feed_tph, fed_t=None) -> pd.DataFrame:
    """A closed loop's frame over 2 h in 1 h samples at a constant 1000 kW, feed ``feed_tph``
    (each move held until the next sample) and, when given, the plant's tally ``fed_t``."""
    n = len(feed_tph)
    cols = {"time_h": np.arange(n, dtype=float), "feed_tph": feed_tph, "speed_frac_critical": 0.7,
            "power_kw": 1000.0, "p80_um": 210.0, "p80_target_um": 210.0, "throughput_tph": 100.0,
            "load_frac": 1.0, "holdup_t": 50.0, "solve_time_s": 0.01, "fallback": None}
    if fed_t is not None:
        cols["fed_t"] = fed_t
    return pd.DataFrame(cols)


@pytest.mark.parametrize("fed_t", [None, [0.0, 100.0, 300.0]], ids=["feed column", "plant tally"])
def test_scene_and_loop_kpis_give_one_specific_energy_the_hand_value(write_scene, fed_t):
    """100 t/h over the first hour, 200 t/h over the second, a last move of 50 t/h made at the
    end of the run (never applied): 2000 kWh / 300 t, from the feed column or the plant's tally."""
    scene = load_scene(write_scene())
    frame = _loop_frame([100.0, 200.0, 50.0], fed_t)
    scene_k = compute_kpis(scene, frame.copy())["specific_energy_kwh_t"]
    loop_k = loop_kpis(frame.copy())["specific_energy_kwh_t"]
    assert scene_k == loop_k == 2000.0 / 300.0


def test_p80_kpis_leave_out_the_samples_without_product(write_scene):
    """A feed stop (throughput 0.5 t/h of a 30 t/h mill at 2-4 h): the P80 of the charge grinding down (40 um)
    entered the IAE, the within-band share and the mean; now they are those of the producing samples, by hand,
    and the time left out is a KPI. Without a stop the numbers are the plain ones."""
    scene = load_scene(write_scene())
    assert scene.controller.target_p80_um == 210.0 and scene.feed.feed_tph == 30.0
    frame = _loop_frame([30.0] * 7)
    frame["p80_um"] = [210.0, 220.0, 40.0, 40.0, 40.0, 230.0, 210.0]
    frame["throughput_tph"] = [30.0, 30.0, 0.5, 0.5, 0.5, 30.0, 30.0]
    k = compute_kpis(scene, frame.copy())
    assert k["p80_iae_um_h"] == pytest.approx(0.5 * (0 + 10) + 0.5 * (20 + 0))  # 0-1 h and 5-6 h
    assert k["p80_within_10um_frac"] == pytest.approx(3 / 4)
    assert k["p80_mean_um"] == pytest.approx((210 + 220 + 230 + 210) / 4)
    assert k["p80_kpis_exclude_h"] == pytest.approx(4.0)  # the intervals 1-2 to 4-5 h touch the stop
    frame["throughput_tph"] = 30.0
    plain = compute_kpis(scene, frame.copy())
    assert plain["p80_kpis_exclude_h"] == 0.0
    assert plain["p80_mean_um"] == pytest.approx(np.mean(frame["p80_um"]))
    assert plain["p80_iae_um_h"] == pytest.approx(np.trapezoid(np.abs(frame["p80_um"] - 210.0), frame["time_h"]))


def test_p80_kpis_leave_out_a_feed_stops_draining(write_scene):
    """The feed stops after 2 h while the charge drains (product 26, then 12 t/h of a 30 t/h mill, above the
    no-product share): its P80 falling to 120 um entered the IAE as the control's; a sample whose feed over the
    interval before it was stopped is the stop's. The sample at the stop's start (fed until then) still counts."""
    scene = load_scene(write_scene())
    frame = _loop_frame([30.0, 30.0, 0.0, 0.0, 30.0, 30.0])
    frame["p80_um"] = [210.0, 220.0, 180.0, 120.0, 200.0, 210.0]
    frame["throughput_tph"] = [30.0, 30.0, 26.0, 12.0, 28.0, 30.0]
    k = compute_kpis(scene, frame.copy())
    # samples 3 and 4 were fed nothing over the interval before: 0-1 and 1-2 h remain of the IAE
    assert k["p80_kpis_exclude_h"] == pytest.approx(3.0)
    assert k["p80_iae_um_h"] == pytest.approx(0.5 * (0 + 10) + 0.5 * (10 + 30))
    assert k["p80_mean_um"] == pytest.approx((210 + 220 + 180 + 210) / 4)
