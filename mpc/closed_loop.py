"""Closed loop: plant -> sensors -> estimator -> controller -> actuators, every sample.

Every part advances with ``make_step``: the plant through the plant protocol (:mod:`mpc.plants`:
a twin's model, or an independent plant such as :class:`mpc.plants.LeRouxPlant`), the sensors
(:class:`mpc.sensors.SensorState`: noise, analyser dead time and sample-and-hold, seeded), the
estimator (:class:`mpc.estimator.Ekf` or None: then the controller gets the true state), the
controller (``make_step(x_est, d_preview, u_prev, y_meas)`` ->
:class:`mpc.results.ControllerStepResult`; the NMPC or a baseline of :mod:`mpc.baselines`).

Feed-forward: ``schedule(t_h)`` gives the blend entering the mill at ``t_h``; a belt analyser
reports it ``preview_lead_h`` ahead, so the disturbance preview over the horizon is
``schedule(min(t + j dt, t + lead))`` for stage j (unknown beyond the lead: the last known blend
is held), with the estimated hardness. KPIs: :func:`mpc.kpis.loop_kpis`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from mpc.errors import MpcInputError
from mpc.estimator import MEASUREMENTS
from mpc.kpis import loop_kpis
from mpc.plants import as_plant
from mpc.sensors import Sensors, SensorState
from twin import TwinInputError, sample_count

#: Measurements the estimator can be given (order of :meth:`mpc.estimator.Ekf.make_step`).
ESTIMATOR_MEASUREMENTS = MEASUREMENTS
#: The outputs a closed loop reads off its plant's ``measure`` every sample, besides the P80 (the
#: sensors' power and load, in :meth:`mpc.sensors.SensorState.make_step`'s order; the estimator
#: and the KPIs read them from there). A plant model without one of them cannot run a closed loop.
CLOSED_LOOP_READS = ("power_kw", "load_frac")


@dataclass(frozen=True)
class LoopSettings:
    """How a closed loop runs (everything but its parts and its initial state)."""

    duration_h: float
    """Length of the run [h]."""
    dt_h: float
    """Sample period [h]."""
    seed: int = 0
    """Seed of the sensors' noise (estimator warm-up and run share the stream)."""
    preview_lead_h: float = 0.0
    """How far ahead the belt analyser reports the feed blend [h] (0: no preview)."""
    target_p80_um: float = 210.0
    """The P80 target recorded beside the run and used by the KPIs [um]."""
    horizon_steps: int | None = None
    """Stages of the preview (default: the controller's ``settings.horizon_steps``, else 1)."""
    load_band: tuple = (0.8, 1.2)
    """Load band (hold-up / nominal) of the KPIs."""
    estimator_warmup_h: float = 0.0
    """The estimator first runs this long on the plant held at ``u0`` and ``schedule(0)``
    (as on a plant that ran before the loop closed), unrecorded."""
    estimator_measurements: tuple = ESTIMATOR_MEASUREMENTS
    """Which of :data:`ESTIMATOR_MEASUREMENTS` the estimator is given (the others as nan; e.g.
    ``("p80_um",)`` when the plant's power and load do not mean what the model's do)."""
    progress: bool = False
    """Show a progress bar."""

    def __post_init__(self):
        try:  # a whole number of samples, as Twin.simulate: 1.03 h at 0.05 h ran 1.05 h, 1 h at 2 h no sample
            sample_count("LoopSettings", self.duration_h, self.dt_h)
        except TwinInputError as exc:
            raise MpcInputError(str(exc)) from None
        if not (np.isfinite(self.preview_lead_h) and self.preview_lead_h >= 0):
            raise MpcInputError(f"The 'preview_lead_h' parameter of LoopSettings must be a float >= 0. "
                                f"Got {self.preview_lead_h!r}.")
        used = tuple(self.estimator_measurements)
        if not used or any(m not in ESTIMATOR_MEASUREMENTS for m in used):
            raise MpcInputError(f"The 'estimator_measurements' parameter of LoopSettings must be a "
                                f"non-empty subset of {ESTIMATOR_MEASUREMENTS}. Got {used!r}.")

    @property
    def n_steps(self) -> int:
        return int(round(self.duration_h / self.dt_h))

    def for_estimator(self, y) -> list:
        """The measurements ``y`` (order :data:`ESTIMATOR_MEASUREMENTS`) with the unused ones nan."""
        return [v if m in self.estimator_measurements else math.nan for v, m in zip(y, ESTIMATOR_MEASUREMENTS)]


@dataclass
class ClosedLoopResult:
    """A closed-loop run: one row per sample (unit-suffixed columns) and the KPIs."""

    frame: pd.DataFrame
    kpis: dict


def _check_sample_periods(dt_h: float, **parts) -> None:
    """Each part's sample period (``dt_h``, or its ``settings.dt_h``) is the loop's: an NMPC and EKF built for
    0.05 h ran in a 0.1 h loop, their model predicting half the sample and the feed's rate limit halved."""
    for name, part in parts.items():
        own = getattr(part, "dt_h", None) or getattr(getattr(part, "settings", None), "dt_h", None)
        if own is not None and abs(own - dt_h) > 1e-9 * dt_h:
            raise MpcInputError(f"The {name}'s sample period is {own:g} h and the loop's (LoopSettings.dt_h) "
                                f"{dt_h:g} h: build the {name} with the loop's sample period.")


def run_closed_loop(plant_model, controller, estimator, schedule: Callable, sensors: Sensors, x0, u0,
                    settings: LoopSettings, plant_hardness: float | Callable = 1.0) -> ClosedLoopResult:
    """Run the loop of ``settings`` from plant state ``x0`` with input ``u0`` before t = 0.

    ``plant_model``: the plant twin's model (may be finer than the controller's), or any plant
    following the plant protocol (:mod:`mpc.plants`); ``schedule(t_h)`` -> blend fractions (plant
    component order, shared with the controller's model); ``plant_hardness``: the plant's true
    hardness scale (a float or a callable of t_h), unknown to the controller.
    """
    _check_sample_periods(settings.dt_h, controller=controller, estimator=estimator)
    plant = as_plant(plant_model)
    rng = np.random.default_rng(settings.seed)
    hard = plant_hardness if callable(plant_hardness) else (lambda t, h=float(plant_hardness): h)
    x = np.asarray(x0, float).copy()
    u_prev = np.asarray(u0, float).reshape(-1).copy()
    d_prev_known = None
    # one analyser for the whole run, its clock started with the warm-up: a plant's analyser does
    # not restart when the controller takes over at t = 0
    sens = SensorState(sensors, rng)
    t_sens0_h = 0.0  # the analyser's time at t = 0
    if estimator is not None and settings.estimator_warmup_h > 0:
        x, d_prev_known, t_sens0_h = _warm_up(plant, estimator, schedule, sens, settings, x, u_prev, hard)
    n_preview = settings.horizon_steps or getattr(getattr(controller, "settings", None), "horizon_steps", 1)
    rows = []
    fed_t = produced_t = 0.0  # cumulative plant feed and product [t], for the mass balance
    for k in tqdm(range(settings.n_steps + 1), desc="closed loop", disable=not settings.progress):
        t = k * settings.dt_h
        blend = np.asarray(schedule(t), float)
        d_plant = plant.disturbance(t, blend, hard(t))
        vals = plant.measure(x, u_prev, d_plant)
        p80 = vals.pop("p80_um")
        p80_new, p80_held, pw_m, ld_m = sens.make_step(t_sens0_h + t, p80, *(vals[k] for k in CLOSED_LOOP_READS))
        if estimator is None:  # the controller is given the plant's state and hardness; no estimate is made
            x_est, d_est, h_est = x, None, hard(t)
        elif d_prev_known is None:
            x_est, d_est = estimator.x_est, np.r_[blend, estimator.hardness_est]
            h_est = float(d_est[-1])
        else:
            x_est, d_est = estimator.make_step(settings.for_estimator([p80_new, pw_m, ld_m]), u_prev, d_prev_known)
            h_est = float(d_est[-1])
        preview = _preview(schedule, t, settings, n_preview, h_est)
        bias = {"p80_bias_um": estimator.controller_p80_bias_um(settings.target_p80_um)} if (
            estimator is not None and getattr(controller, "accepts_p80_bias", False)) else {}
        res = controller.make_step(x_est, preview, u_prev, y_meas=p80_held, **bias)
        u = np.asarray(res.u_applied, float)
        row = {"time_h": t, "feed_tph": u[0], "speed_frac_critical": u[1], "p80_um": p80,
               "p80_measured_um": p80_held, "p80_target_um": settings.target_p80_um, **vals,
               "power_meas_kw": pw_m, "load_meas_frac": ld_m, "fed_t": fed_t, "produced_t": produced_t,
               **{f"blend_{nm}_frac": blend[i] for i, nm in enumerate(plant.component_names)},
               "hardness_scale": hard(t), "hardness_est": math.nan if estimator is None else h_est}
        row |= _estimate_columns(estimator, x_est, u, d_est) | _controller_columns(controller, res)
        rows.append(row)
        if k == settings.n_steps:
            continue  # the last row has no step after it (continue, not break: the bar reaches its end)
        # apply u over [t, t + dt): the throughput/power rows above are at the sample instant
        x, fed, produced = plant.step(x, u, d_plant, settings.dt_h)
        fed_t, produced_t = fed_t + fed, produced_t + produced
        u_prev, d_prev_known = u, blend
    frame = pd.DataFrame(rows)
    return ClosedLoopResult(frame, loop_kpis(frame, settings.load_band))


def _warm_up(plant, estimator, schedule, sens, settings, x, u0, hard):
    """Run the estimator on the plant held at ``u0`` and ``schedule(0)`` for
    ``settings.estimator_warmup_h``, read through the analyser ``sens``; returns the plant state
    at the end, the blend it saw and the analyser's time at the end."""
    b0 = np.asarray(schedule(0.0), float)
    d0 = plant.disturbance(0.0, b0, hard(0.0))
    n = int(round(settings.estimator_warmup_h / settings.dt_h))
    for k in range(n):
        m = plant.measure(x, u0, d0)
        y = sens.make_step(k * settings.dt_h, m["p80_um"], *(m[key] for key in CLOSED_LOOP_READS))
        if k > 0:
            estimator.make_step(settings.for_estimator([y[0], y[2], y[3]]), u0, b0)
        x, _, _ = plant.step(x, u0, d0, settings.dt_h)
    return x, b0, n * settings.dt_h


def _preview(schedule, t: float, settings: LoopSettings, n_stages: int, hardness: float) -> np.ndarray:
    """Disturbances over the horizon: the blend known ``preview_lead_h`` ahead (held beyond it)
    and the estimated hardness; columns are stages."""
    times = t + settings.dt_h * np.arange(n_stages)
    return np.array([np.r_[np.asarray(schedule(min(tt, t + settings.preview_lead_h)), float), hardness]
                     for tt in times]).T


def _estimate_columns(estimator, x_est, u, d_est) -> dict:
    """The estimator's P80 at the estimate (and its delayed, measured P80), its P80 bias, and
    ``p80_est_um``, what the estimator believes the plant's ``p80_um`` is (the model's plus the
    bias, through the estimator's P80 gain; with ``hardness_est`` beside the true
    ``hardness_scale``, the estimates beside their truth)."""
    if estimator is None:
        return {}
    em = estimator.model
    out = {"p80_model_um": float(em.outputs["p80_um"](x_est, u, d_est)), "p80_bias_est_um": estimator.p80_bias_um}
    out["p80_est_um"] = estimator.plant_p80_um(out["p80_model_um"])  # the estimate of the plant's p80_um
    if estimator.p80_output != "p80_um":
        out["p80_model_measured_um"] = float(em.outputs[estimator.p80_output](x_est, u, d_est))
    return out


def _controller_columns(controller, res) -> dict:
    """What the controller reports of its step: solve time, iterations, fallback, status."""
    info = getattr(controller, "last_info", None) or {}
    return {"p80_plan_end_um": info.get("p80_end_um", math.nan), "solve_time_s": res.solve_time_s,
            "iterations": res.iterations, "fallback": res.fallback_used, "success": res.success,
            "status": res.status}
