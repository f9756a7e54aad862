"""Key performance indicators of a run, one definition each, used by closed loops, scene runs
and benchmarks alike. Integrals over time are trapezoidal over the samples."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

#: Band of P80 [um] around the target counted by ``p80_within_10um_frac``.
P80_BAND_UM = 10.0


def _samples(time_h, rate) -> tuple[np.ndarray, np.ndarray]:
    """``(t, r)`` as arrays: one rate per time, times strictly increasing (else ValueError: a
    shorter rate or a shuffled time gave a wrong integral silently)."""
    t, r = np.asarray(time_h, float).ravel(), np.asarray(rate, float)
    r = np.full(t.shape, float(r)) if r.ndim == 0 else r.ravel()
    if t.shape != r.shape:
        raise ValueError(f"a KPI integral needs one rate per time: got {t.size} times and {r.size} rates")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise ValueError("a KPI integral needs strictly increasing times")
    return t, r


def integral(time_h, rate) -> float:
    """Integral of a sampled rate over time (trapezoidal) [rate x h]."""
    t, r = _samples(time_h, rate)
    return float(np.sum(0.5 * (r[1:] + r[:-1]) * np.diff(t))) if t.size > 1 else 0.0


def cumulative(time_h, rate) -> np.ndarray:
    """The integral of a sampled rate from the first sample to every sample (trapezoidal)."""
    t, r = _samples(time_h, rate)
    return np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(t))])


def p80_iae_um_h(time_h, p80_um, target_p80_um) -> float:
    """Integral of |P80 - target| over the run [um h] (trapezoidal)."""
    return integral(time_h, np.abs(np.asarray(p80_um, float) - np.asarray(target_p80_um, float)))


def within_band_frac(p80_um, target_p80_um, band_um: float = P80_BAND_UM) -> float:
    """Share of samples with |P80 - target| <= ``band_um`` (a NaN P80 counts as outside)."""
    return float(np.mean(np.abs(np.asarray(p80_um, float) - np.asarray(target_p80_um, float)) <= band_um))


def outside_band_frac(load_frac, band) -> float:
    """Share of samples whose load (hold-up over nominal) lies outside ``band = (lo, hi)`` (a NaN
    load counts as outside, as a NaN P80 does in :func:`within_band_frac`)."""
    load = np.asarray(load_frac, float)
    return float(np.mean(~((load >= band[0]) & (load <= band[1]))))


def loop_kpis(frame: pd.DataFrame, load_band=(0.8, 1.2)) -> dict:
    """KPIs of a closed-loop frame (columns of :func:`mpc.run_closed_loop`): IAE of the plant's
    exact P80 from target [um h], share within +-10 um, largest error [um], specific energy =
    energy / fresh feed [kWh/t], throughput = product [t], standard deviations of the P80 [um]
    and of the load over the samples (industry's variability measures), share of samples with the
    load outside its band, controller solve-time median and 95th percentile [s], and the steps on which the
    controller fell back to a held input."""
    t = frame["time_h"].to_numpy(float)
    target = frame["p80_target_um"].to_numpy(float)
    p80 = frame["p80_um"].to_numpy(float)
    fed_t = integral(t, frame["feed_tph"])
    st = frame["solve_time_s"].to_numpy(float)
    return {
        "p80_iae_um_h": p80_iae_um_h(t, p80, target),
        "p80_within_10um_frac": within_band_frac(p80, target),
        "p80_max_abs_err_um": float(np.max(np.abs(p80 - target))),
        "specific_energy_kwh_t": integral(t, frame["power_kw"]) / fed_t if fed_t > 0 else math.nan,
        "throughput_t": integral(t, frame["throughput_tph"]),
        "p80_std_um": float(np.std(p80)),
        "load_std_frac": float(np.std(frame["load_frac"].to_numpy(float))),
        "load_outside_band_frac": outside_band_frac(frame["load_frac"], load_band),
        "solve_time_median_s": float(np.median(st)),
        "solve_time_p95_s": float(np.percentile(st, 95)),
        "fallback_steps": int(frame["fallback"].notna().sum()),
    }
