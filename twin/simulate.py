"""Time integration of a model: CVODES (BDF, stiff) with piecewise-constant inputs per sample,
quadratures of fed and produced mass for the mass balance; a fixed-step RK4 for convergence
studies; and the exact batch solution (matrix exponential) for the linear batch mill."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np
import pandas as pd
import scipy.linalg

from .errors import SolverError, TwinInputError
from .sizes import pxx_um

#: Default integrator tolerances (relative; absolute as a share of nominal hold-up).
RTOL = 1e-8
ATOL_REL = 1e-10
#: Negative masses down to this share of nominal hold-up are round-off and clipped.
NEGATIVE_ROUNDOFF_REL = 1e-8


@lru_cache(maxsize=64)
def step_integrator(model, dt_h: float, rtol: float = RTOL, atol_rel: float = ATOL_REL) -> ca.Function:
    """CVODES over one sample period: (x0, p=[u; d]) -> (xf, qf=[fed t, produced t])."""
    p = ca.vertcat(model.u, model.d)
    fed = model.u[0]
    produced = model._asm.outputs.get("throughput_tph", ca.SX(0))
    dae = {"x": model.x, "p": p, "ode": model.xdot, "quad": ca.vertcat(fed, produced)}
    opts = {"reltol": rtol, "abstol": atol_rel * model.spec.holdup_nominal_t, "max_num_steps": 100000}
    return ca.integrator("F", "cvodes", dae, 0.0, dt_h, opts)


def integrate_constant(model, x0, duration_h: float, u, d, rtol=RTOL, atol_rel=ATOL_REL) -> np.ndarray:
    """State after ``duration_h`` at constant inputs."""
    F = step_integrator(model, float(duration_h), rtol, atol_rel)
    try:
        out = F(x0=x0, p=np.concatenate([u, d]))
    except RuntimeError as exc:
        raise SolverError(f"CVODES failed integrating {duration_h} h: {exc}") from exc
    return _clean(model, np.asarray(out["xf"]).ravel(), "integration")


def _clean(model, x, where):
    scale = model.spec.holdup_nominal_t
    if not np.all(np.isfinite(x)):
        raise SolverError(f"Non-finite state in {where}.")
    worst = x[: model.n_mass].min()
    if worst < -NEGATIVE_ROUNDOFF_REL * scale:
        raise SolverError(f"Negative mass {worst:.3g} t in {where} (beyond round-off "
                          f"{NEGATIVE_ROUNDOFF_REL * scale:.2g} t): tighten the tolerances.")
    x[: model.n_mass] = np.maximum(x[: model.n_mass], 0.0)
    return x


@dataclass
class Trajectory:
    """A run: one row per sample in ``frame`` (unit-suffixed columns), the states, and the
    cumulative fed and produced mass for the mass balance."""

    frame: pd.DataFrame
    states: np.ndarray
    fed_t: np.ndarray
    produced_t: np.ndarray

    def mass_balance_error(self) -> float:
        """max |fed - produced - (H - H0)| over the run, relative to fed + H0."""
        h = self.frame["holdup_t"].to_numpy()
        err = self.fed_t - self.produced_t - (h - h[0])
        return float(np.abs(err).max() / (self.fed_t[-1] + h[0] + 1e-300))


def simulate(model, x0, duration_h: float, dt_h: float, u_fn, d_fn, rtol=RTOL, atol_rel=ATOL_REL,
             exact_p80: bool = True) -> Trajectory:
    """Integrate with inputs held over each sample period (zero-order hold)."""
    if not duration_h > 0 or not dt_h > 0:
        raise TwinInputError(f"The 'duration_h' and 'dt_h' of simulate must be > 0. Got {duration_h}, {dt_h}.")
    n = int(round(duration_h / dt_h))
    F = step_integrator(model, float(dt_h), rtol, atol_rel)
    x = _clean(model, np.asarray(x0, float).copy(), "initial state")
    xs = np.empty((n + 1, model.n_x))
    xs[0] = x
    us = np.empty((n + 1, 2))
    ds = np.empty((n + 1, model.d.numel()))
    fed = np.zeros(n + 1)
    prod = np.zeros(n + 1)
    for k in range(n):
        t = k * dt_h
        us[k] = u_fn(t)
        ds[k] = d_fn(t)
        try:
            out = F(x0=x, p=np.concatenate([us[k], ds[k]]))
        except RuntimeError as exc:
            raise SolverError(f"CVODES failed at t = {t:.4g} h: {exc}") from exc
        x = _clean(model, np.asarray(out["xf"]).ravel(), f"step at t = {t:.4g} h")
        q = np.asarray(out["qf"]).ravel()
        xs[k + 1] = x
        fed[k + 1] = fed[k] + q[0]
        prod[k + 1] = prod[k] + q[1]
    us[n], ds[n] = u_fn(n * dt_h), d_fn(n * dt_h)
    frame = outputs_frame(model, xs, us, ds, np.arange(n + 1) * dt_h, exact_p80)
    frame["fed_t"] = fed
    frame["produced_t"] = prod
    return Trajectory(frame, xs, fed, prod)


def outputs_frame(model, xs, us, ds, time_h, exact_p80=True) -> pd.DataFrame:
    """Scalar outputs along a trajectory as a DataFrame (one row per sample)."""
    cols = {"time_h": time_h, "feed_tph": us[:, 0], "speed_frac_critical": us[:, 1]}
    for i, name in enumerate(model.spec.component_names):
        cols[f"blend_{name}_frac"] = ds[:, i]
    cols["hardness_scale"] = ds[:, -1]
    for name, fn in model.outputs.items():
        if fn.size1_out(0) == 1:
            cols[name] = np.asarray(fn.map(len(time_h))(xs.T, us.T, ds.T)).ravel()
    if exact_p80:
        psd = np.asarray(model.product_psd_function().map(len(time_h))(xs.T, us.T, ds.T))
        cols["p80_exact_um"] = [pxx_um(model.spec.grid, psd[:, j]) if psd[:, j].sum() > 0 else math.nan
                                for j in range(psd.shape[1])]
    return pd.DataFrame(cols)


def rk4_simulate(model, x0, duration_h: float, n_steps: int, u, d) -> np.ndarray:
    """Classical fixed-step RK4 at constant inputs (4th order; for convergence studies)."""
    x = ca.SX.sym("x", model.n_x)
    h = duration_h / n_steps
    f = lambda z: model.f(z, u, d)  # noqa: E731
    k1 = f(x)
    k2 = f(x + h / 2 * k1)
    k3 = f(x + h / 2 * k2)
    k4 = f(x + h * k3)
    step = ca.Function("rk4", [x], [x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
    out = step.mapaccum(n_steps)(np.asarray(x0, float))
    return np.asarray(out[:, -1]).ravel()


def batch_exact(selection_per_h: np.ndarray, b: np.ndarray, m0: np.ndarray, t_h: float) -> np.ndarray:
    """Exact batch-mill solution m(t) = expm((b - I) diag(S) t) m0 (MISSION.md eq. 5;
    Reid 1965 gives the same in closed form for distinct S)."""
    A = (b - np.eye(len(m0))) * np.asarray(selection_per_h)[None, :]
    return scipy.linalg.expm(A * t_h) @ np.asarray(m0, float)
