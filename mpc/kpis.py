"""Key performance indicators of a run, one definition each, used by closed loops, scene runs
and benchmarks alike. Integrals of an output over time are trapezoidal over the samples; the fed
tonnage is the plant's own tally, or the feed integrated as held (:func:`fresh_feed_t`)."""

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


def held_cumulative(time_h, rate) -> np.ndarray:
    """The integral of a sampled-and-held rate from the first sample to every sample: each
    sample's value holds until the next sample (a zero-order hold), so the last sample's value
    lies beyond the last time and does not count."""
    t, r = _samples(time_h, rate)
    return np.concatenate([[0.0], np.cumsum(r[:-1] * np.diff(t))])


def held_integral(time_h, rate) -> float:
    """Integral of a sampled-and-held rate over the samples' span [rate x h]
    (:func:`held_cumulative`)."""
    return float(held_cumulative(time_h, rate)[-1])


def fresh_feed_t(frame: pd.DataFrame) -> float:
    """Fresh feed [t] over a frame's span: the plant's own tally (column ``fed_t``, cumulative,
    integrated by the plant with its input as it was applied) when the frame has it, else the
    ``feed_tph`` column integrated as held (:func:`held_integral`); NaN with neither.

    Held, not trapezoidal: a closed loop's feed rate is a move, made at its sample and held until
    the next one (the plant's ``fed_t`` of such a run is exactly the held sum). The trapezoid
    averaged each move with the next one and counted half of the last row's move, a move made at
    the end of the run and never applied within it."""
    if "fed_t" in frame:
        fed = frame["fed_t"].to_numpy(float)
        return float(fed[-1] - fed[0])
    if "feed_tph" in frame:
        return held_integral(frame["time_h"], frame["feed_tph"])
    return math.nan


def specific_energy_kwh_t(frame: pd.DataFrame) -> float:
    """Specific energy of a run [kWh/t]: energy drawn over the frame's span (its ``power_kw``
    samples, trapezoidal: a power is a reading of a state that moves continuously between
    samples) over the fresh feed over the same span (:func:`fresh_feed_t`); NaN when nothing
    was fed or without a power column. The one definition of closed loops
    (:func:`loop_kpis`) and scene runs alike."""
    fed = fresh_feed_t(frame)
    if "power_kw" not in frame or not fed > 0:
        return math.nan
    return integral(frame["time_h"], frame["power_kw"]) / fed


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
    exact P80 from target [um h], share within +-10 um, largest error [um], specific energy
    (:func:`specific_energy_kwh_t`) [kWh/t], throughput = product [t], standard deviations of the P80 [um]
    and of the load over the samples (industry's variability measures), share of samples with the
    load outside its band, controller solve-time median and 95th percentile [s], and the steps on which the
    controller fell back to a held input."""
    t = frame["time_h"].to_numpy(float)
    target = frame["p80_target_um"].to_numpy(float)
    p80 = frame["p80_um"].to_numpy(float)
    st = frame["solve_time_s"].to_numpy(float)
    return {
        "p80_iae_um_h": p80_iae_um_h(t, p80, target),
        "p80_within_10um_frac": within_band_frac(p80, target),
        "p80_max_abs_err_um": float(np.max(np.abs(p80 - target))),
        "specific_energy_kwh_t": specific_energy_kwh_t(frame),
        "throughput_t": integral(t, frame["throughput_tph"]),
        "p80_std_um": float(np.std(p80)),
        "load_std_frac": float(np.std(frame["load_frac"].to_numpy(float))),
        "load_outside_band_frac": outside_band_frac(frame["load_frac"], load_band),
        "solve_time_median_s": float(np.median(st)),
        "solve_time_p95_s": float(np.percentile(st, 95)),
        "fallback_steps": int(frame["fallback"].notna().sum()),
    }
