"""The P80 analyser model (mpc.SensorState): what it reports is the true trace sampled every
period, dead time later, held, plus noise; its record stays bounded however long the run."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc import Sensors, SensorState
from mpc.errors import MpcInputError


def reference_readings(sensors: Sensors, times, p80, seed: int):
    """The analyser by its definition, on the whole record: the sample of period j is the true
    P80 interpolated at j * period over everything recorded so far, reported once
    ``t - dead time`` reaches it; the noise draws in the order SensorState makes them."""
    rng = np.random.default_rng(seed)
    last, held, out = None, math.nan, []
    for n, t in enumerate(times):
        j = math.floor((t - sensors.p80_dead_time_h) / sensors.p80_sample_period_h + 1e-9)
        new = math.nan
        if j >= 0 and j != last:
            value = float(np.interp(j * sensors.p80_sample_period_h, times[:n + 1], p80[:n + 1]))
            new = value + sensors.p80_noise_um * rng.standard_normal()
            last, held = j, new
        rng.standard_normal(2)  # power and load
        out.append((new, held))
    return out


@pytest.mark.parametrize("dead_h,period_h,dt_h", [(0.1, 0.05, 1 / 60), (0.0, 0.05, 0.05), (0.1, 0.05, 0.07),
                                                  (0.25, 0.02, 0.05), (0.1, 0.05, 0.013)])
def test_readings_are_the_true_trace_sampled_dead_time_later_and_held(dead_h, period_h, dt_h):
    rng = np.random.default_rng(7)
    times = np.cumsum(rng.uniform(0.5, 1.5, 600) * dt_h)  # irregular steps, some beyond a period
    p80 = 200.0 + 20.0 * np.sin(times) + rng.normal(0.0, 1.0, times.size)
    sensors = Sensors(p80_noise_um=2.0, p80_dead_time_h=dead_h, p80_sample_period_h=period_h)
    state = SensorState(sensors, np.random.default_rng(3))
    got = [state.make_step(float(t), float(p), 100.0, 1.0)[:2] for t, p in zip(times, p80)]
    want = reference_readings(sensors, times, p80, seed=3)
    np.testing.assert_array_equal(np.array(got), np.array(want))  # bit for bit
    assert np.isfinite(np.array(got)[-50:, 1]).all()  # the held reading, once reports come


def test_the_record_stays_bounded_however_long_the_run():
    """A month of one-minute samples: the analyser keeps only the values a later sample can
    still need (dead time plus a period), so a long run or the virtual plant neither slows down
    nor grows."""
    sensors = Sensors(p80_dead_time_h=0.1, p80_sample_period_h=0.05)
    state = SensorState(sensors, np.random.default_rng(0))
    dt = 1.0 / 60.0
    most = 0
    for n in range(720 * 60):
        state.make_step(n * dt, 200.0, 100.0, 1.0)
        most = max(most, len(state.times))
    assert most <= math.ceil((sensors.p80_dead_time_h + sensors.p80_sample_period_h) / dt) + 2, most
    assert len(state.times) == len(state.p80)


def test_time_going_back_is_refused():
    state = SensorState(Sensors(), np.random.default_rng(0))
    state.make_step(1.0, 200.0, 100.0, 1.0)
    with pytest.raises(MpcInputError, match=r"'t_h'.*0\.5 after 1\.0"):
        state.make_step(0.5, 200.0, 100.0, 1.0)
    with pytest.raises(MpcInputError, match="'t_h'"):
        state.make_step(math.nan, 200.0, 100.0, 1.0)
