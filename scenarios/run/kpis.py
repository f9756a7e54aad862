"""The KPIs of a scene's run, from its frame (one row per sample). Keys carry their units.

- ``p80_iae_um_h``: integral of |P80 - target| (plant P80 as the model computes it, not the
  analyser's; :func:`mpc.p80_iae_um_h`); NaN without ``controller.target_p80_um``.
- ``p80_within_10um_frac``: share of samples with |P80 - target| <= 10 um; NaN without target.
- ``specific_energy_kwh_t``: energy drawn / fresh feed (:func:`mpc.specific_energy_kwh_t`, the
  closed loop's own definition: the feed is the plant's tally, integrated as held); for a batch
  grind, / the charge.
- ``throughput_t``: product discharged over the run [t]; for a batch grind the charge ground.
- ``throughput_tph``: mean product rate over the run [t/h] (``throughput_t / duration_h``);
  NaN for a batch grind (no product flow).
- ``load_outside_band_frac``: share of samples whose load is outside
  ``controller.load_band_frac``; NaN for a batch grind (no load dynamics).
- ``solve_time_median_s``, ``solve_time_p95_s``: controller solve times; NaN in open loop.
- ``mass_balance_error``: max |fed - produced - (H - H0)| / (fed + H0) over the run.
- ``controller_failed_steps``, ``controller_fallback_steps``, ``estimator_resets``: samples on
  which the controller's solve failed, on which a fallback input was applied, and estimator
  resets, the estimator's warm-up on the steady plant included
  (:func:`scenarios.run.closed_loop.controller_health`); NaN in open loop.
- ``specific_energy_kwh_t`` is NaN (undefined, with a note) when nothing was fed.
- ``start_feed_tph``, ``start_p80_um``: the feed rate of the state the run started from and the
  P80 at t = 0.
- P80 KPIs read the frame's ``p80_um``: the exact interpolation of the product's size
  distribution in every mode (open loop: the model's smooth output is ``p80_smooth_um``). A continuous
  mill's IAE, within-band share and mean leave out the samples of a feed stop (:func:`feed_stopped`: its
  ``throughput_tph``, or the feed it was given over the interval before, below :data:`NO_PRODUCT_FRAC` of its
  nominal feed; the P80 is then the charge grinding down, 36 um in a replay's half-hour stop, and draining, 240 to
  72 um), an interval of the IAE when either end is; ``p80_kpis_exclude_h`` says how long that was (0 without
  stops).
- Also ``p80_final_um``, ``p80_mean_um``, ``energy_kwh``, ``fed_t``, ``duration_h``.
Integrals of outputs are trapezoidal over the samples; a feed rate without the plant's ``fed_t``
is integrated as held (:mod:`mpc.kpis`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from mpc import (cumulative, fresh_feed_t, held_cumulative, integral, outside_band_frac, p80_iae_um_h,
                 specific_energy_kwh_t, within_band_frac)
from scenarios.run.models import is_batch
from scenarios.scene import Scene
from scenarios.scene.ranges import NO_PRODUCT_FRAC, scene_nominal_feed_tph
from twin import mass_balance_error

KPI_KEYS = ("p80_iae_um_h", "p80_within_10um_frac", "specific_energy_kwh_t", "throughput_t", "throughput_tph",
            "load_outside_band_frac", "solve_time_median_s", "solve_time_p95_s",
            "mass_balance_error", "controller_failed_steps", "controller_fallback_steps", "estimator_resets")
#: KPI key -> key of the controller's health record (scenarios.run.closed_loop.controller_health).
HEALTH_KPIS = {"controller_failed_steps": "failed_steps", "controller_fallback_steps": "fallback_steps",
               "estimator_resets": "estimator_resets"}


def compute_kpis(scene: Scene, frame: pd.DataFrame, solve_times_s=None, batch_charge_t=None,
                 solve_time_median_s=None, solve_time_p95_s=None, controller_health=None,
                 start_feed_tph=None) -> dict:
    """The KPIs of a run from its frame (definitions in the module docstring). ``start_feed_tph``:
    the feed rate of the state the run started from, when the frame's first row holds a move
    made at t = 0 (a closed loop's); else the first row's."""
    t = frame["time_h"].to_numpy(float)
    p80 = frame["p80_um" if "p80_um" in frame else "content_p80_um"].to_numpy(float)  # batch: the content
    target = scene.controller.target_p80_um
    k: dict[str, Any] = {}
    stopped = feed_stopped(scene, frame)
    producing = ~stopped
    if target is not None and not is_batch(scene) and producing.any():
        k["p80_iae_um_h"] = sum(p80_iae_um_h(t[run], p80[run], target) for run in _runs(producing))
        k["p80_within_10um_frac"] = within_band_frac(p80[producing], target)
    else:
        k["p80_iae_um_h"] = math.nan
        k["p80_within_10um_frac"] = math.nan
    energy = integral(t, frame["power_kw"]) if "power_kw" in frame else math.nan
    if "fed_t" not in frame and "feed_tph" in frame:  # no tally of the plant's: the feed as held
        frame["fed_t"] = held_cumulative(t, frame["feed_tph"])
    if "produced_t" not in frame and "throughput_tph" in frame:
        frame["produced_t"] = cumulative(t, frame["throughput_tph"])
    fed = fresh_feed_t(frame)
    if batch_charge_t is not None:
        k["specific_energy_kwh_t"] = float(energy / batch_charge_t)
        k["throughput_t"] = float(batch_charge_t)
    else:
        k["specific_energy_kwh_t"] = specific_energy_kwh_t(frame)
        k["throughput_t"] = float(frame["produced_t"].iloc[-1]) if "produced_t" in frame else math.nan
    k["throughput_tph"] = (k["throughput_t"] / float(t[-1] - t[0])
                           if batch_charge_t is None and t[-1] > t[0] else math.nan)
    k["load_outside_band_frac"] = (outside_band_frac(frame["load_frac"], scene.controller.load_band_frac)
                                   if "load_frac" in frame else math.nan)
    if solve_times_s is not None and len(solve_times_s):
        k["solve_time_median_s"] = float(np.median(solve_times_s))
        k["solve_time_p95_s"] = float(np.percentile(solve_times_s, 95))
    else:
        k["solve_time_median_s"] = math.nan if solve_time_median_s is None else float(solve_time_median_s)
        k["solve_time_p95_s"] = math.nan if solve_time_p95_s is None else float(solve_time_p95_s)
    k["mass_balance_error"] = mass_balance_error(frame)
    for key, field in HEALTH_KPIS.items():
        k[key] = math.nan if controller_health is None else int(controller_health[field])
    if start_feed_tph is not None:
        k["start_feed_tph"] = float(start_feed_tph)
    else:
        k["start_feed_tph"] = float(frame["feed_tph"].iloc[0]) if "feed_tph" in frame else math.nan
    k["start_p80_um"] = float(p80[0])  # what the case started from (sweep tables compare cases)
    k["p80_final_um"] = float(p80[-1])
    k["p80_mean_um"] = float(np.nanmean(p80[producing])) if producing.any() else math.nan
    k["p80_kpis_exclude_h"] = float(np.diff(t)[stopped[1:] | stopped[:-1]].sum())
    k["energy_kwh"] = float(energy)
    k["fed_t"] = fed
    k["duration_h"] = float(t[-1])
    return k


def feed_stopped(scene: Scene, frame: pd.DataFrame) -> np.ndarray:
    """Mask of a continuous mill's samples in a feed stop: its product rate, or the fresh feed it was given over
    the interval before the sample (a frame's ``feed_tph`` is held from its sample on), below
    :data:`NO_PRODUCT_FRAC` of its nominal feed. The fed mill's draining (its product falling from 26 to 2 t/h,
    its P80 from 240 to 72 um) is the stop's, not the control's."""
    nominal = scene_nominal_feed_tph(scene)
    if is_batch(scene) or "throughput_tph" not in frame or not nominal:
        return np.zeros(len(frame), bool)
    limit = NO_PRODUCT_FRAC * nominal
    stopped = frame["throughput_tph"].to_numpy(float) < limit
    if "feed_tph" in frame:
        feed = frame["feed_tph"].to_numpy(float)
        stopped |= np.r_[feed[:1], feed[:-1]] < limit
    return stopped


def _runs(mask: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the runs of consecutive True in ``mask``."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    return [np.arange(a, b) for a, b in zip(edges[::2], edges[1::2])]
