"""Closed loop: plant -> sensors -> estimator -> controller -> actuators, every sample.

Every part advances with ``make_step``: the plant through the small plant protocol below (a
twin's model by :func:`twin.simulate.step`, IDAS restarted each sample because the inputs jump;
or an independent plant such as :class:`mpc.leroux.LeRouxPlant`), :class:`Sensors` (noise, analyser
dead time and sample-and-hold, seeded), the estimator (:class:`mpc.estimator.Ekf` or None: then
the controller gets the true state), the controller (``make_step(x_est, d_preview, u_prev,
y_meas)`` -> :class:`mpc.results.ControllerStepResult`; the NMPC, :class:`FixedInputs` (no
control) or :class:`PiFeedback`).

Feed-forward: ``schedule(t_h)`` gives the blend entering the mill at ``t_h``; a belt analyser
reports it ``preview_lead_h`` ahead, so the disturbance preview over the horizon is
``schedule(min(t + j dt, t + lead))`` for stage j (unknown beyond the lead: the last known blend
is held), with the estimated hardness.

Plant protocol (what :func:`run_closed_loop` needs of a plant; :class:`TwinPlant` wraps a twin's
``Model``, :class:`mpc.leroux.LeRouxPlant` the le Roux et al. 2013 circuit):

- ``component_names``: names of the blend entries ``schedule(t)`` returns (the controller's
  components; recorded as ``blend_<name>_frac``);
- ``disturbance(t_h, blend, hardness) -> d``: the plant's own disturbance vector;
- ``measure(x, u, d) -> dict``: at least ``p80_um``, ``power_kw``, ``load_frac``,
  ``throughput_tph``, ``specific_energy_kwh_t`` and ``holdup_t`` (the hold-up that the
  cumulative fed and produced mass balance); any further entries become columns of the run;
- ``step(x, u, d, dt_h) -> (x_next, fed_t, produced_t)``.

KPIs (issue 5): IAE of exact P80 from target [um h] (rectangle rule over samples), fraction of
samples within +-10 um, specific energy = sum(power dt) / sum(feed dt) [kWh/t], throughput =
product mass [t], fraction of samples with load outside the stable band, solve-time median and
95th percentile [s].
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from mpc.errors import MpcInputError
from mpc.estimator import MEASUREMENTS
from mpc.results import ControllerStepResult


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
        for name in ("p80_noise_um", "p80_dead_time_h", "power_noise_kw", "load_noise_frac"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise MpcInputError(f"The '{name}' parameter of Sensors must be a float >= 0. "
                                    f"Got {v!r}.")
        if not (np.isfinite(self.p80_sample_period_h) and self.p80_sample_period_h > 0):
            raise MpcInputError(f"The 'p80_sample_period_h' parameter of Sensors must be a float "
                                f"> 0. Got {self.p80_sample_period_h!r}.")


class _SensorState:
    """Analyser history, sample-and-hold and noise generator of one run."""

    def __init__(self, sensors: Sensors, rng: np.random.Generator):
        self.s, self.rng = sensors, rng
        self.times, self.p80 = [], []
        self.last_sample = None
        self.held = math.nan

    def make_step(self, t_h: float, p80_um: float, power_kw: float, load_frac: float):
        """Record the true values at ``t_h``; return (new P80 reading or nan, held reading,
        power reading, load reading)."""
        s = self.s
        self.times.append(t_h)
        self.p80.append(p80_um)
        j = math.floor((t_h - s.p80_dead_time_h) / s.p80_sample_period_h + 1e-9)
        new = math.nan
        if j >= 0 and j != self.last_sample:
            ts = j * s.p80_sample_period_h
            value = float(np.interp(ts, self.times, self.p80))
            new = value + s.p80_noise_um * self.rng.standard_normal()
            self.last_sample, self.held = j, new
        pw = power_kw + s.power_noise_kw * self.rng.standard_normal()
        ld = load_frac + s.load_noise_frac * self.rng.standard_normal()
        return new, self.held, pw, ld


#: Outputs every plant's ``measure`` returns (the columns the KPIs use).
PLANT_OUTPUTS = ("power_kw", "load_frac", "throughput_tph", "specific_energy_kwh_t", "holdup_t")
#: Measurements the estimator can be given (order of :meth:`mpc.estimator.Ekf.make_step`).
ESTIMATOR_MEASUREMENTS = MEASUREMENTS


class TwinPlant:
    """The plant protocol (module docstring) on a twin's :class:`twin.model.Model`: P80 from the
    product size distribution (:func:`twin.sizes.pxx_um`, nan for an empty product), the
    outputs :data:`PLANT_OUTPUTS` of the model, and :func:`twin.simulate.step`."""

    def __init__(self, model):
        self.model = model
        self.component_names = tuple(model.spec.component_names)
        self._psd_fn = model.product_psd_function()
        self._outs = {k: model.outputs[k] for k in PLANT_OUTPUTS}

    def disturbance(self, t_h: float, blend, hardness: float) -> np.ndarray:
        return self.model.d_vector(blend, hardness)

    def measure(self, x, u, d) -> dict:
        from twin.sizes import pxx_um

        psd = np.asarray(self._psd_fn(x, u, d), float).ravel()
        vals = {"p80_um": pxx_um(self.model.spec.grid, psd) if psd.sum() > 0 else math.nan}
        vals.update({key: float(fn(x, u, d)) for key, fn in self._outs.items()})
        return vals

    def step(self, x, u, d, dt_h: float):
        from twin.simulate import step

        return step(self.model, x, u, d, dt_h)


def as_plant(plant):
    """``plant`` itself if it follows the plant protocol, a :class:`TwinPlant` if it is a
    twin's model; else an :class:`MpcInputError` naming what is missing."""
    needed = ("component_names", "disturbance", "measure", "step")
    if all(hasattr(plant, a) for a in needed):
        return plant
    if hasattr(plant, "product_psd_function") and hasattr(plant, "spec"):
        return TwinPlant(plant)
    raise MpcInputError(f"The 'plant_model' parameter of run_closed_loop must be a twin Model or "
                        f"have {', '.join(needed)} (the plant protocol of mpc.closed_loop). "
                        f"Got {type(plant).__name__}.")


class FixedInputs:
    """No control: the inputs stay at ``u_fixed`` (e.g. the steady-state setpoints)."""

    def __init__(self, u_fixed):
        self.u_fixed = np.asarray(u_fixed, float).reshape(-1)

    def make_step(self, x_est, d_preview, u_prev, y_meas=None) -> ControllerStepResult:
        return ControllerStepResult(True, "fixed", 0.0, 0, 0.0, self.u_fixed.copy())


class PiFeedback:
    """The reactive practice: a :class:`mpc.pi.DiscretePI` from measured P80 to feed rate, the
    speed held at ``speed_frac_critical``. Before the first analyser reading the input is held."""

    def __init__(self, pi, speed_frac_critical: float):
        self.pi = pi
        self.speed = float(speed_frac_critical)

    def make_step(self, x_est, d_preview, u_prev, y_meas=None) -> ControllerStepResult:
        if y_meas is None or not np.isfinite(y_meas):
            return ControllerStepResult(True, "no measurement", 0.0, 0, 0.0,
                                        [float(np.asarray(u_prev)[0]), self.speed])
        feed = self.pi.make_step(float(y_meas))
        r = self.pi.last_result
        return ControllerStepResult(True, r.status, r.cost, 0, r.solve_time_s, [feed, self.speed])


def pi_baseline(plant_model, steady, sensors: Sensors, dt_h: float, target_p80_um: float,
                feed_tph_min: float = 20.0, feed_tph_max: float = 45.0,
                feed_rate_max_tph_per_h: float = 20.0, tau_c_h: float | None = None):
    """PI P80 -> feed tuned by SIMC (Skogestad 2003) on the linearised plant at ``steady``
    (``plant_model``: a twin's model, or any model with ``f(x, u, d)`` and ``outputs['p80_um']``
    such as :class:`mpc.leroux.LeRouxCircuit`; ``steady``: a :class:`twin.steady.SteadyState`
    or anything with its ``x``, ``u``, ``d``): FOPDT fit of the feed -> P80 step response
    (:func:`mpc.linear.fopdt_from_model`), its dead time increased by the analyser dead time
    plus half the sampling period (the mean delay of a sample-and-hold; Seborg et al. 2011,
    sec. 17.1). Returns ``(PiFeedback, Fopdt)``."""
    from mpc.linear import Fopdt, fopdt_from_model, linearize
    from mpc.pi import DiscretePI

    sys_c, _ = linearize(plant_model.f, plant_model.outputs, steady.x, steady.u, steady.d,
                         ["p80_um"], steady_tol=1e-4)
    f = fopdt_from_model(sys_c, "feed_tph", "p80_um")
    f = Fopdt(f.gain, f.tau_h, f.delay_h + sensors.p80_dead_time_h
              + 0.5 * sensors.p80_sample_period_h, f.rms_error)
    pi = DiscretePI.from_fopdt(f, dt_h, target_p80_um, float(steady.u[0]), tau_c_h=tau_c_h,
                               u_min=feed_tph_min, u_max=feed_tph_max,
                               du_max=feed_rate_max_tph_per_h * dt_h)
    return PiFeedback(pi, float(steady.u[1])), f


@dataclass
class ClosedLoopResult:
    """A closed-loop run: one row per sample (unit-suffixed columns) and the KPIs."""

    frame: pd.DataFrame
    kpis: dict


def kpis(frame: pd.DataFrame, dt_h: float, load_band=(0.8, 1.2)) -> dict:
    """KPIs of a run frame (see the module docstring)."""
    err = (frame["p80_um"] - frame["p80_target_um"]).abs()
    feed_t = float((frame["feed_tph"] * dt_h).sum())
    st = frame["solve_time_s"].to_numpy()
    return {
        "p80_iae_um_h": float(err.sum() * dt_h),
        "p80_within_10um_frac": float((err <= 10.0).mean()),
        "p80_max_abs_err_um": float(err.max()),
        "specific_energy_kwh_t": float((frame["power_kw"] * dt_h).sum() / feed_t) if feed_t > 0 else math.nan,
        "throughput_t": float((frame["throughput_tph"] * dt_h).sum()),
        "load_outside_band_frac": float(((frame["load_frac"] < load_band[0])
                                         | (frame["load_frac"] > load_band[1])).mean()),
        "solve_time_median_s": float(np.median(st)),
        "solve_time_p95_s": float(np.percentile(st, 95)),
        "fallback_steps": int(frame["fallback"].notna().sum()),
    }


def run_closed_loop(plant_model, controller, estimator, schedule: Callable, sensors: Sensors,
                    duration_h: float, dt_h: float, x0, u0, seed: int = 0,
                    preview_lead_h: float = 0.0, target_p80_um: float = 210.0,
                    plant_hardness: float | Callable = 1.0, horizon_steps: int | None = None,
                    load_band=(0.8, 1.2), progress: bool = False,
                    estimator_warmup_h: float = 0.0,
                    estimator_measurements=ESTIMATOR_MEASUREMENTS) -> ClosedLoopResult:
    """Run the loop for ``duration_h`` at sample period ``dt_h``.

    ``plant_model``: the plant twin's model (may be finer than the controller's), or any plant
    following the plant protocol (module docstring; e.g. :class:`mpc.leroux.LeRouxPlant`);
    ``x0`` its initial state; ``u0`` the input before t = 0; ``schedule(t_h)`` -> blend fractions (plant
    component order, shared with the controller's model); ``plant_hardness``: the plant's true
    hardness scale (a float or a callable of t_h), unknown to the controller; ``horizon_steps``
    for the preview (default: the controller's settings, else 1). ``estimator_warmup_h``: the
    estimator first runs that long on the plant held at ``u0`` and ``schedule(0)`` (as on a
    plant that was running before the loop closed; same seed stream), unrecorded; the loop
    then starts from the plant state at the end of the warm-up. ``estimator_measurements``:
    which of :data:`ESTIMATOR_MEASUREMENTS` the estimator is given (the others are passed as
    nan; e.g. only ``("p80_um",)`` when the plant's power and load do not mean what the
    controller's model means by them).
    """
    if not (np.isfinite(duration_h) and duration_h > 0 and np.isfinite(dt_h) and dt_h > 0):
        raise MpcInputError(f"The 'duration_h' and 'dt_h' parameters of run_closed_loop must be "
                            f"> 0. Got {duration_h!r}, {dt_h!r}.")
    if preview_lead_h < 0:
        raise MpcInputError(f"The 'preview_lead_h' parameter of run_closed_loop must be >= 0. "
                            f"Got {preview_lead_h!r}.")
    used = tuple(estimator_measurements)
    if not used or any(m not in ESTIMATOR_MEASUREMENTS for m in used):
        raise MpcInputError(f"The 'estimator_measurements' parameter of run_closed_loop must be a "
                            f"non-empty subset of {ESTIMATOR_MEASUREMENTS}. Got {used!r}.")
    mask = np.array([m in used for m in ESTIMATOR_MEASUREMENTS])

    def for_estimator(y):
        return [v if keep else math.nan for v, keep in zip(y, mask)]

    plant = as_plant(plant_model)
    n = int(round(duration_h / dt_h))
    rng = np.random.default_rng(seed)
    sens = _SensorState(sensors, rng)
    hard = plant_hardness if callable(plant_hardness) else (lambda t, h=float(plant_hardness): h)
    N = horizon_steps or getattr(getattr(controller, "settings", None), "horizon_steps", 1)
    names = list(plant.component_names)
    x = np.asarray(x0, float).copy()
    u_prev = np.asarray(u0, float).reshape(-1).copy()
    d_prev_known = None
    n_warm = int(round(estimator_warmup_h / dt_h)) if estimator is not None else 0
    if n_warm > 0:
        warm = _SensorState(sensors, rng)
        b0 = np.asarray(schedule(0.0), float)
        d0 = plant.disturbance(0.0, b0, hard(0.0))
        xw = x.copy()
        for k in range(n_warm):
            mw = plant.measure(xw, u_prev, d0)
            y = warm.make_step(k * dt_h, mw["p80_um"], mw["power_kw"], mw["load_frac"])
            if k > 0:
                estimator.make_step(for_estimator([y[0], y[2], y[3]]), u_prev, b0)
            xw, _, _ = plant.step(xw, u_prev, d0, dt_h)
        x, d_prev_known = xw, b0
    x_est = d_est = None
    rows = []
    iterator = range(n + 1)
    if progress:
        try:
            from tqdm import tqdm
            iterator = tqdm(iterator, desc="closed loop")
        except ImportError:
            pass
    fed_t = produced_t = 0.0  # cumulative plant feed and product [t], for the mass balance
    for k in iterator:
        t = k * dt_h
        blend = np.asarray(schedule(t), float)
        d_plant = plant.disturbance(t, blend, hard(t))
        vals = plant.measure(x, u_prev, d_plant)
        p80 = vals.pop("p80_um")
        p80_new, p80_held, pw_m, ld_m = sens.make_step(t, p80, vals["power_kw"], vals["load_frac"])
        if estimator is not None:
            if d_prev_known is not None:
                x_est, d_est = estimator.make_step(for_estimator([p80_new, pw_m, ld_m]), u_prev,
                                                   d_prev_known)
            else:
                x_est, d_est = estimator.x_est, np.r_[blend, estimator.hardness_est]
            h_est = float(d_est[-1])
        else:
            x_est, h_est = x, hard(t)
        times = t + dt_h * np.arange(N)
        d_prev = np.array([np.r_[np.asarray(schedule(min(tt, t + preview_lead_h)), float), h_est]
                           for tt in times]).T
        res = controller.make_step(x_est, d_prev, u_prev, y_meas=p80_held)
        u = np.asarray(res.u_applied, float)
        row = {"time_h": t, "feed_tph": u[0], "speed_frac_critical": u[1], "p80_um": p80,
               "p80_measured_um": p80_held, "p80_target_um": target_p80_um}
        row.update(vals)
        row["power_meas_kw"], row["load_meas_frac"] = pw_m, ld_m
        row["fed_t"], row["produced_t"] = fed_t, produced_t
        for i, nm in enumerate(names):
            row[f"blend_{nm}_frac"] = blend[i]
        row["hardness_scale"] = hard(t)
        row["hardness_est"] = h_est
        if estimator is not None:
            em = estimator.model
            row["p80_model_um"] = float(em.outputs["p80_um"](x_est, u, d_est))
            if estimator.p80_output != "p80_um":
                row["p80_model_measured_um"] = float(em.outputs[estimator.p80_output](x_est, u, d_est))
        info = getattr(controller, "last_info", None) or {}
        row["p80_plan_end_um"] = info.get("p80_end_um", math.nan)
        row.update({"solve_time_s": res.solve_time_s, "iterations": res.iterations,
                    "fallback": res.fallback_used, "success": res.success, "status": res.status})
        rows.append(row)
        if k == n:
            break
        # apply u over [t, t + dt): the throughput/power rows above are at the sample instant
        x, fed, produced = plant.step(x, u, d_plant, dt_h)
        fed_t, produced_t = fed_t + fed, produced_t + produced
        u_prev, d_prev_known = u, blend
    frame = pd.DataFrame(rows)
    return ClosedLoopResult(frame, kpis(frame, dt_h, load_band))
