"""Closed loop: plant twin -> sensors -> estimator -> controller -> actuators, every sample.

Every part advances with ``make_step``: the plant by :func:`twin.simulate.step` (IDAS on the
plant model, restarted each sample because the inputs jump), :class:`Sensors` (noise, analyser
dead time and sample-and-hold, seeded), the estimator (:class:`mpc.estimator.Ekf` or None: then
the controller gets the true state), the controller (``make_step(x_est, d_preview, u_prev,
y_meas)`` -> :class:`mpc.results.ControllerStepResult`; the NMPC, :class:`FixedInputs` (no
control) or :class:`PiFeedback`).

Feed-forward: ``schedule(t_h)`` gives the blend entering the mill at ``t_h``; a belt analyser
reports it ``preview_lead_h`` ahead, so the disturbance preview over the horizon is
``schedule(min(t + j dt, t + lead))`` for stage j (unknown beyond the lead: the last known blend
is held), with the estimated hardness.

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
    """PI P80 -> feed tuned by SIMC (Skogestad 2003) on the linearised plant twin at ``steady``
    (a :class:`twin.steady.SteadyState`): FOPDT fit of the feed -> P80 step response
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
                    estimator_warmup_h: float = 0.0) -> ClosedLoopResult:
    """Run the loop for ``duration_h`` at sample period ``dt_h``.

    ``plant_model``: the plant twin's model (may be finer than the controller's); ``x0`` its
    initial state; ``u0`` the input before t = 0; ``schedule(t_h)`` -> blend fractions (plant
    component order, shared with the controller's model); ``plant_hardness``: the plant's true
    hardness scale (a float or a callable of t_h), unknown to the controller; ``horizon_steps``
    for the preview (default: the controller's settings, else 1). ``estimator_warmup_h``: the
    estimator first runs that long on the plant held at ``u0`` and ``schedule(0)`` (as on a
    plant that was running before the loop closed; same seed stream), unrecorded; the loop
    then starts from the plant state at the end of the warm-up.
    """
    from twin.simulate import step
    from twin.sizes import pxx_um

    if not (np.isfinite(duration_h) and duration_h > 0 and np.isfinite(dt_h) and dt_h > 0):
        raise MpcInputError(f"The 'duration_h' and 'dt_h' parameters of run_closed_loop must be "
                            f"> 0. Got {duration_h!r}, {dt_h!r}.")
    if preview_lead_h < 0:
        raise MpcInputError(f"The 'preview_lead_h' parameter of run_closed_loop must be >= 0. "
                            f"Got {preview_lead_h!r}.")
    n = int(round(duration_h / dt_h))
    rng = np.random.default_rng(seed)
    sens = _SensorState(sensors, rng)
    hard = plant_hardness if callable(plant_hardness) else (lambda t, h=float(plant_hardness): h)
    N = horizon_steps or getattr(getattr(controller, "settings", None), "horizon_steps", 1)
    names = list(plant_model.spec.component_names)
    psd_fn = plant_model.product_psd_function()
    outs = {k: plant_model.outputs[k] for k in
            ("power_kw", "load_frac", "throughput_tph", "specific_energy_kwh_t", "holdup_t")}
    x = np.asarray(x0, float).copy()
    u_prev = np.asarray(u0, float).reshape(-1).copy()
    d_prev_known = None
    n_warm = int(round(estimator_warmup_h / dt_h)) if estimator is not None else 0
    if n_warm > 0:
        warm = _SensorState(sensors, rng)
        b0 = np.asarray(schedule(0.0), float)
        d0 = plant_model.d_vector(b0, hard(0.0))
        xw = x.copy()
        for k in range(n_warm):
            psd = np.asarray(psd_fn(xw, u_prev, d0), float).ravel()
            p80w = pxx_um(plant_model.spec.grid, psd)
            y = warm.make_step(k * dt_h, p80w, float(outs["power_kw"](xw, u_prev, d0)),
                               float(outs["load_frac"](xw, u_prev, d0)))
            if k > 0:
                estimator.make_step([y[0], y[2], y[3]], u_prev, b0)
            xw, _, _ = step(plant_model, xw, u_prev, d0, dt_h)
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
        d_plant = plant_model.d_vector(blend, hard(t))
        psd = np.asarray(psd_fn(x, u_prev, d_plant), float).ravel()
        p80 = pxx_um(plant_model.spec.grid, psd) if psd.sum() > 0 else math.nan
        vals = {key: float(fn(x, u_prev, d_plant)) for key, fn in outs.items()}
        p80_new, p80_held, pw_m, ld_m = sens.make_step(t, p80, vals["power_kw"], vals["load_frac"])
        if estimator is not None:
            if d_prev_known is not None:
                x_est, d_est = estimator.make_step([p80_new, pw_m, ld_m], u_prev, d_prev_known)
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
        x, fed, produced = step(plant_model, x, u, d_plant, dt_h)
        fed_t, produced_t = fed_t + fed, produced_t + produced
        u_prev, d_prev_known = u, blend
    frame = pd.DataFrame(rows)
    return ClosedLoopResult(frame, kpis(frame, dt_h, load_band))
