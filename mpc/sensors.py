"""Plant sensors: the particle-size analyser (sampling, dead time, hold, noise) and the noisy
power and load readings, seeded; used by every closed loop and open-loop run."""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from mpc.errors import MpcInputError, is_real


@dataclass(frozen=True)
class Sensors:
    """Plant measurements: standard deviations of Gaussian noise, analyser dead time and period."""

    p80_noise_um: float = 3.0
    """P80 analyser noise [um]."""
    p80_dead_time_h: float = 0.1
    """Analyser dead time [h]: a sample taken at t is reported at t + dead time."""
    p80_sample_period_h: float = 0.05
    """Analyser sampling period [h]; the reading is held in between."""
    power_noise_kw: float = 5.0
    """Mill power noise [kW]."""
    load_noise_frac: float = 0.01
    """Load (hold-up / nominal) noise."""

    def __post_init__(self):
        # a string failed inside np.isfinite without the field's name; True read as a 1 h dead time
        for name in ("p80_noise_um", "p80_dead_time_h", "p80_sample_period_h", "power_noise_kw", "load_noise_frac"):
            v = getattr(self, name)
            if not is_real(v):
                raise MpcInputError(f"The '{name}' parameter of Sensors must be a float. Got {v!r}.")
            if name == "p80_sample_period_h" and not (np.isfinite(v) and v > 0):
                raise MpcInputError(f"The 'p80_sample_period_h' parameter of Sensors must be a float > 0. Got {v!r}.")
            if not (np.isfinite(v) and v >= 0):
                raise MpcInputError(f"The '{name}' parameter of Sensors must be a float >= 0. Got {v!r}.")


class SensorState:
    """What the plant's sensors report in one run: the P80 analyser takes a sample every
    ``p80_sample_period_h`` and reports it ``p80_dead_time_h`` later, held until the next report,
    with Gaussian noise; power and load readings are the true values plus noise. The one analyser
    model of grindtwin: closed loops, open-loop runs and the virtual plant all read through it.

    It keeps only the true values a later sample can still need (from the one at or before the
    last sample's time on): a run's cost per step and its memory do not grow with its length."""

    def __init__(self, sensors: Sensors, rng: np.random.Generator):
        self.s, self.rng = sensors, rng
        self.times, self.p80 = [], []
        self.last_sample = None
        self.held = math.nan

    def make_step(self, t_h: float, p80_um: float, power_kw: float, load_frac: float):
        """Record the true values at ``t_h`` (not before the previous call's); return (new P80
        reading or nan, held reading, power reading, load reading)."""
        s = self.s
        if not math.isfinite(t_h):  # a NaN first time failed later, inside math.floor, without the field's name
            raise MpcInputError(f"The 't_h' of SensorState.make_step must be a finite time. Got {t_h!r}.")
        if self.times and not t_h >= self.times[-1]:
            raise MpcInputError(f"The 't_h' of SensorState.make_step must not go back in time: got "
                                f"{t_h!r} after {self.times[-1]!r}.")
        self.times.append(t_h)
        self.p80.append(p80_um)
        j = math.floor((t_h - s.p80_dead_time_h) / s.p80_sample_period_h + 1e-9)
        new = math.nan
        if j >= 0 and j != self.last_sample:
            ts = j * s.p80_sample_period_h
            # the recorded values bracketing ts (np.interp on them is np.interp on the whole
            # record); the ones before are never needed again: later samples are taken later
            k = max(bisect.bisect_right(self.times, ts) - 1, 0)
            value = float(np.interp(ts, self.times[k:k + 2], self.p80[k:k + 2]))
            del self.times[:k], self.p80[:k]
            new = value + s.p80_noise_um * self.rng.standard_normal()
            self.last_sample, self.held = j, new
        pw = power_kw + s.power_noise_kw * self.rng.standard_normal()
        ld = load_frac + s.load_noise_frac * self.rng.standard_normal()
        return new, self.held, pw, ld
