"""Steady states of the continuous mill: a direct Newton solve (CasADi rootfinder) from a
linearised guess, falling back to long integration; and the steady state at a given load."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from ..errors import SolverError, TwinInputError
from ..mill import load_status
from .simulate import integrate_constant
from ..sizes import pxx_um

#: Newton stops when the largest mass-rate residual is below this share of nominal flow [-].
RESIDUAL_REL_TOL = 1e-10


@dataclass
class SteadyState:
    """A steady operating point: state, inputs, disturbances and every scalar output."""

    x: np.ndarray
    u: np.ndarray
    d: np.ndarray
    outputs: dict
    p80_um: float  # exact interpolation of the product size distribution
    load_status: str
    psd: np.ndarray  # product flow per class [t/h]
    method: str

    @property
    def feed_tph(self) -> float:
        return float(self.u[0])

    def summary(self) -> dict:
        out = {"feed_tph": self.feed_tph, "speed_frac_critical": float(self.u[1]), "p80_um": self.p80_um}
        out |= {k: v for k, v in self.outputs.items() if k not in ("p80_um",)}
        out["load_status"] = self.load_status
        return out


def _scalar_outputs(model, x, u, d) -> dict:
    vals = {}
    for name, fn in model.outputs.items():
        if fn.size1_out(0) * fn.size2_out(0) == 1:
            vals[name] = float(fn(x, u, d))
    return vals


@lru_cache(maxsize=64)
def _jacobians(model) -> ca.Function:
    """On the sparse DAE form w = [x; z]: (w, u, d) -> (residual, d res/dw, d res/dfeed, dH/dw)
    with residual = [ode; z - g(x)]; the Jacobian has ~3,000 non-zeros where the plain ODE's is
    dense (the aggregates z carry the coupling)."""
    w = ca.vertcat(model.x, model.z)
    res = ca.vertcat(model.dae["ode"], model.dae["alg"])
    h = model.output_exprs_dae["holdup_t"]
    return ca.Function("steady_jacobians", [w, model.u, model.d],
                       [res, ca.jacobian(res, w), ca.jacobian(res, model.u[0]), ca.jacobian(h, w)])


def _sparse(dm) -> scipy.sparse.csc_matrix:
    return dm.sparse() if hasattr(dm, "sparse") else scipy.sparse.csc_matrix(np.asarray(dm))


def _newton(model, x, u, d, load_target=None, max_iter: int = 60):
    """Damped Newton on f(x) = 0 (and holdup(x) = load_target x H_nom, solving for the feed when
    a target is given), on the sparse DAE form. Steps are cut so masses stay non-negative.
    Returns (x, u, ok)."""
    jac = _jacobians(model)
    q_nom = model.spec.feed_nominal_tph
    h_nom = model.spec.holdup_nominal_t
    nm, nx = model.n_mass, model.n_x
    w = np.concatenate([x, model.z_of(x)])
    # row scaling: mass rates by nominal flow, aggregates by nominal hold-up
    scale = np.concatenate([np.full(nx, 1.0 / q_nom), np.full(w.size - nx, 1.0 / h_nom)])
    u = u.copy()
    for _ in range(max_iter):
        r_dm, j_dm, ju_dm, jh_dm = jac(w, u, d)
        r = np.asarray(r_dm, float).ravel()
        load_res = (float(model.outputs["holdup_t"](w[:nx], u, d)) / h_nom - load_target
                    if load_target is not None else 0.0)
        if max(np.abs(r * scale).max(), abs(load_res)) < RESIDUAL_REL_TOL:
            return w[:nx], u, True
        J = _sparse(j_dm)
        try:
            if load_target is None:
                step = scipy.sparse.linalg.spsolve(J, -r)
                dfeed = 0.0
            else:
                A = scipy.sparse.bmat([[J, _sparse(ju_dm)], [_sparse(jh_dm), None]], format="csc")
                sol = scipy.sparse.linalg.spsolve(A, -np.concatenate([r, [load_res * h_nom]]))
                step, dfeed = sol[:-1], sol[-1]
        except (RuntimeError, ValueError):
            return w[:nx], u, False
        if not np.all(np.isfinite(step)):
            return w[:nx], u, False  # singular Jacobian: reported by the caller as non-convergence
        alpha = 1.0
        neg = step[:nm] < 0
        if np.any(neg):  # keep masses >= 0: go at most 95 % of the way to zero
            room = w[:nm][neg] / -step[:nm][neg]
            room = room[room > 0]  # masses already at zero may not fall further; others bound the step
            if room.size:
                alpha = max(min(1.0, 0.95 * room.min()), 1e-3)
        if load_target is not None and u[0] + alpha * dfeed <= 0:
            alpha = min(alpha, 0.5 * u[0] / -dfeed)
        w = w + alpha * step
        u[0] = u[0] + alpha * dfeed
    return w[:nx], u, False


def _check(model, x, u, d, how: str):
    x = model.checked_state(x, f"the steady state ({how})")
    res = np.abs(np.asarray(model.f(x, u, d))).max() / model.spec.feed_nominal_tph
    if not res < 1e3 * RESIDUAL_REL_TOL:
        raise SolverError(f"Steady state ({how}) did not converge: residual {res:.3g} of nominal flow.")
    return x


def _result(model, x, u, d, method) -> SteadyState:
    outs = _scalar_outputs(model, x, u, d)
    psd = np.asarray(model.product_psd_function()(x, u, d)).ravel()
    p80 = pxx_um(model.spec.grid, psd) if psd.sum() > 0 else math.nan
    status = load_status(outs["load_frac"], model.spec.mill.stable_band) if "load_frac" in outs else "n/a"
    return SteadyState(x, u, d, outs, p80, status, psd, method)


def _require_transport(model):
    if "transport" not in model.effect_names:
        raise TwinInputError("A steady state needs the 'transport' effect (a batch mill has none: "
                             "everything ends in the finest class).")


def steady_state(model, u, d, x_guess=None) -> SteadyState:
    """Steady state at inputs u and disturbances d (Newton; long integration if Newton fails)."""
    _require_transport(model)
    u, d = np.asarray(u, float), np.asarray(d, float)
    if u[0] <= 0.0:  # no feed: the mill empties
        x = np.zeros(model.n_x)
        x[model.n_mass:] = model.initial_state(d[:-1])[model.n_mass:]
        return _result(model, x, u, d, "empty (no feed)")
    guess = model.initial_state(d[:-1]) if x_guess is None else np.asarray(x_guess, float)
    x, _, ok = _newton(model, guess, u, d)
    if ok:
        return _result(model, _check(model, x, u, d, "Newton"), u, d, "newton")


    tau = model.spec.holdup_nominal_t / u[0]
    x_long = integrate_constant(model, guess, 40.0 * tau, u, d)
    x, _, ok = _newton(model, x_long, u, d)
    if not ok:
        raise SolverError("Steady state not found: Newton failed from the nominal guess and after "
                          f"40 residence times of integration at feed {u[0]:.4g} t/h, speed {u[1]:.3f}.")
    return _result(model, _check(model, x, u, d, "long integration + Newton"), u, d, "integration+newton")


def steady_state_at_load(model, u, d, load_frac: float = 1.0) -> SteadyState:
    """Steady state whose total hold-up is ``load_frac`` x nominal; the feed rate is solved for."""
    _require_transport(model)
    if not 0.0 < load_frac < 5.0:
        raise TwinInputError(f"The 'load_frac' must be a float in (0, 5). Got {load_frac}.")
    u, d = np.asarray(u, float), np.asarray(d, float)
    first = steady_state(model, u, d)
    x, uu, ok = _newton(model, first.x, u, d, load_target=load_frac)
    if not ok or not uu[0] > 0:
        raise SolverError(f"No positive feed rate found that holds the load at {load_frac} of nominal "
                          f"(speed {u[1]:.3f}); last feed {uu[0]:.4g} t/h.")
    return _result(model, _check(model, x, uu, d, "Newton at constant load"), uu, d, "newton-load")
