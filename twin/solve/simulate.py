"""Time integration of a model: IDAS (BDF, stiff) on the model's sparse DAE form (CVODES when
it has no aggregates) with piecewise-constant inputs per sample and quadratures of fed and
produced mass for the mass balance; a fixed-step RK4 for convergence
studies; and the exact batch solution (matrix exponential) for the linear batch mill."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np
import pandas as pd
import scipy.linalg

from ..errors import SolverError, TwinInputError
from ..sizes import pxx_um

#: Default integrator tolerances (relative; absolute as a share of nominal hold-up).
RTOL = 1e-8
ATOL_REL = 1e-10


#: Below this relative tolerance IDAS's start-up on the DAE form fails; CVODES on the
#: substituted ODE (dense Jacobian, slower) is used instead.
DAE_MIN_RTOL = 1e-10


#: IDAS computes consistent initial derivatives (without it a restart from rest fails the first
#: error test) and leaves the aggregates, exact functions of x, out of its error test.
IDAS_OPTIONS = {"calc_ic": True, "suppress_algebraic": True}


def _dae(model, rtol: float, extra: dict) -> tuple[str, dict]:
    """The integrator and problem for a model: IDAS on the sparse DAE form when its aggregates
    enter the right-hand side and the tolerance allows, else CVODES on the plain ODE."""
    uses_z = model.z.numel() > 0 and ca.depends_on(model.dae["ode"], model.z)
    if uses_z and rtol >= DAE_MIN_RTOL:
        quad = extra.pop("quad_dae")
        return "idas", dict(model.dae, quad=quad, **extra)
    quad = model._substitute(extra.pop("quad_dae"))
    return "cvodes", dict(x=model.x, ode=model.xdot, quad=quad, **extra)


@lru_cache(maxsize=64)
def step_integrator(model, dt_h: float, rtol: float = RTOL, atol_rel: float = ATOL_REL) -> ca.Function:
    """IDAS (BDF) over one sample period on the model's sparse DAE form:
    (x0, z0, p=[u; d]) -> (xf, zf, qf=[fed t, produced t])."""
    produced = model.output_exprs_dae.get("throughput_tph", ca.SX(0))
    solver, dae = _dae(model, rtol, {"p": ca.vertcat(model.u, model.d),
                                     "quad_dae": ca.vertcat(model.u[0], produced)})
    opts = {"reltol": rtol, "abstol": atol_rel * model.spec.holdup_nominal_t, "max_num_steps": 100000}
    opts |= IDAS_OPTIONS if solver == "idas" else {}
    return ca.integrator("F", solver, dae, 0.0, dt_h, opts)


def _z0(F, model, x):
    """Consistent initial aggregates for IDAS; empty for CVODES."""
    return model.z_of(x) if F.size1_in("z0") else np.zeros(0)


def integrate_constant(model, x0, duration_h: float, u, d, rtol=RTOL, atol_rel=ATOL_REL) -> np.ndarray:
    """State after ``duration_h`` at constant inputs."""
    F = step_integrator(model, float(duration_h), rtol, atol_rel)
    try:
        out = F(x0=x0, z0=_z0(F, model, x0), p=np.concatenate([u, d]))
    except RuntimeError as exc:
        raise SolverError(f"The integrator failed integrating {duration_h} h: {exc}") from exc
    return model.checked_state(np.asarray(out["xf"]).ravel(), "integration")


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


@lru_cache(maxsize=32)
def grid_integrator(model, dt_h: float, n_steps: int, rtol: float = RTOL, atol_rel: float = ATOL_REL):
    """IDAS over ``n_steps`` sample periods in one call, inputs piecewise constant per period:
    (x0, z0, u=[u; d] per period) -> states at every sample and the cumulative quadratures."""
    produced = model.output_exprs_dae.get("throughput_tph", ca.SX(0))
    solver, dae = _dae(model, rtol, {"u": ca.vertcat(model.u, model.d),
                                     "quad_dae": ca.vertcat(model.u[0], produced)})
    opts = {"reltol": rtol, "abstol": atol_rel * model.spec.holdup_nominal_t, "max_num_steps": 1000000}
    opts |= IDAS_OPTIONS if solver == "idas" else {}
    return ca.integrator("G", solver, dae, 0.0, dt_h * np.arange(1, n_steps + 1), opts)


def simulate(model, x0, duration_h: float, dt_h: float, u_fn, d_fn, rtol=RTOL, atol_rel=ATOL_REL,
             exact_p80: bool = True) -> Trajectory:
    """Open-loop run, inputs held over each sample period (zero-order hold). The inputs do not
    depend on the state, so each stretch of constant inputs is one integrator call; the
    integrator restarts where the inputs jump (SUNDIALS' BDF history must not straddle a jump:
    without the restart a feed step fails the error test)."""
    if not duration_h > 0 or not dt_h > 0:
        raise TwinInputError(f"The 'duration_h' and 'dt_h' of simulate must be > 0. Got {duration_h}, {dt_h}.")
    n = int(round(duration_h / dt_h))
    x0 = model.checked_state(np.asarray(x0, float).copy(), "initial state")
    times = np.arange(n + 1) * dt_h
    us = np.array([u_fn(t) for t in times], float)
    ds = np.array([d_fn(t) for t in times], float)
    inputs = np.hstack([us[:-1], ds[:-1]])
    jumps = np.nonzero(np.any(inputs[1:] != inputs[:-1], axis=1))[0] + 1
    xs = np.empty((n + 1, model.n_x))
    xs[0] = x0
    q = np.zeros((n + 1, 2))
    for a, b in zip(np.r_[0, jumps], np.r_[jumps, n]):
        G = grid_integrator(model, float(dt_h), int(b - a), rtol, atol_rel)
        try:
            out = G(x0=xs[a], z0=_z0(G, model, xs[a]), u=np.repeat(inputs[a][:, None], b - a, axis=1))
        except RuntimeError as exc:
            raise SolverError(f"The integrator failed between t = {a * dt_h:.4g} h and {b * dt_h:.4g} h: "
                              f"{exc}") from exc
        xs[a + 1:b + 1] = np.asarray(out["xf"]).T
        q[a + 1:b + 1] = q[a] + np.asarray(out["qf"]).T
        xs[b] = model.checked_state(xs[b], f"sample {b}")
    xs = np.vstack([model.checked_state(row, f"sample {i}") for i, row in enumerate(xs)])
    frame = outputs_frame(model, xs, us, ds, times, exact_p80)
    frame["fed_t"] = q[:, 0]
    frame["produced_t"] = q[:, 1]
    return Trajectory(frame, xs, q[:, 0], q[:, 1])


@lru_cache(maxsize=64)
def _trajectory_outputs(model, n: int):
    """One Function evaluating every scalar output and the product PSD at n samples at once."""
    names = [name for name, fn in model.outputs.items() if fn.size1_out(0) == 1]
    fn = ca.Function("trajectory_outputs", [model.x, model.u, model.d],
                     [ca.vertcat(*[model.outputs[k](model.x, model.u, model.d) for k in names]),
                      model.psd_function()(model.x, model.u, model.d)])
    return names, fn.map(n)


def outputs_frame(model, xs, us, ds, time_h, exact_p80=True) -> pd.DataFrame:
    """Scalar outputs along a trajectory as a DataFrame (one row per sample)."""
    cols = {"time_h": time_h, "feed_tph": us[:, 0], "speed_frac_critical": us[:, 1]}
    for i, name in enumerate(model.spec.component_names):
        cols[f"blend_{name}_frac"] = ds[:, i]
    cols["hardness_scale"] = ds[:, -1]
    names, fn = _trajectory_outputs(model, len(time_h))
    scalars, psd = (np.asarray(v) for v in fn(xs.T, us.T, ds.T))
    cols |= {name: scalars[i] for i, name in enumerate(names)}
    if exact_p80:  # of the product, or of the mill content in a batch model
        cols["p80_exact_um" if model.psd_what == "product" else "content_p80_exact_um"] = [pxx_um(model.spec.grid, psd[:, j]) if psd[:, j].sum() > 0 else math.nan
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


def step(model, x, u, d, dt_h: float, rtol: float = RTOL, atol_rel: float = ATOL_REL):
    """Advance the plant one sample period at constant inputs (restarting the integrator, as a
    closed loop must when its inputs jump). Returns (x_next, fed_t, produced_t)."""
    F = step_integrator(model, float(dt_h), rtol, atol_rel)
    try:
        out = F(x0=x, z0=_z0(F, model, x), p=np.concatenate([np.asarray(u, float), np.asarray(d, float)]))
    except RuntimeError as exc:
        raise SolverError(f"The integrator failed over one {dt_h} h step: {exc}") from exc
    q = np.asarray(out["qf"]).ravel()
    return model.checked_state(np.asarray(out["xf"]).ravel(), "plant step"), float(q[0]), float(q[1])
