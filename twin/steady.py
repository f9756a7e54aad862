"""Steady states of the continuous mill: a direct Newton solve (CasADi rootfinder) from a
linearised guess, falling back to long integration; and the steady state at a given load."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from .effects.holdup import load_status
from .errors import SolverError, TwinInputError
from .sizes import pxx_um

#: Newton stops when the largest mass-rate residual is below this share of nominal flow [-].
RESIDUAL_REL_TOL = 1e-10
#: Negative masses down to this share of nominal hold-up are round-off and set to zero;
#: anything more negative is reported as a solver failure.
NEGATIVE_ROUNDOFF_REL = 1e-9


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
def _newton(model, with_feed: bool):
    """Rootfinder on f(x) = 0 (with_feed: unknowns [x; feed], extra equation holdup = target)."""
    p = ca.SX.sym("p", model.u.numel() + model.d.numel() + 1)
    u = p[: model.u.numel()]
    d = p[model.u.numel(): -1]
    target = p[-1]
    x = ca.SX.sym("x", model.n_x)
    scale = model.spec.holdup_nominal_t
    if with_feed:
        feed = ca.SX.sym("feed")
        z = ca.vertcat(x / scale, feed / model.spec.feed_nominal_tph)
        uu = ca.vertcat(feed, u[1])
        res = ca.vertcat(model.f(x, uu, d) / model.spec.feed_nominal_tph,
                         model.outputs["holdup_t"](x, uu, d) / scale - target)
        xs = ca.vertcat(x, feed)
        g = ca.Function("g", [xs, p], [ca.substitute(res, xs, ca.vertcat(z[:-1] * scale, z[-1] * model.spec.feed_nominal_tph))])
    else:
        g = ca.Function("g", [x, p], [model.f(x, u, d) / model.spec.feed_nominal_tph])
    opts = {"abstol": RESIDUAL_REL_TOL, "max_iter": 60, "error_on_fail": False,
            "line_search": True} if False else {"abstol": RESIDUAL_REL_TOL, "max_iter": 60, "error_on_fail": False}
    return ca.rootfinder("steady", "newton", g, opts)


def _check(model, x, u, d, how: str):
    scale = model.spec.holdup_nominal_t
    if not np.all(np.isfinite(x)):
        raise SolverError(f"Steady state ({how}) is not finite.")
    worst = x[: model.n_mass].min()
    if worst < -NEGATIVE_ROUNDOFF_REL * scale:
        raise SolverError(f"Steady state ({how}) has a negative mass {worst:.3g} t "
                          f"(allowed round-off {NEGATIVE_ROUNDOFF_REL * scale:.2g} t).")
    res = np.abs(np.asarray(model.f(x, u, d))).max() / model.spec.feed_nominal_tph
    if not res < 1e3 * RESIDUAL_REL_TOL:
        raise SolverError(f"Steady state ({how}) did not converge: residual {res:.3g} of nominal flow.")
    x = x.copy()
    x[: model.n_mass] = np.clip(x[: model.n_mass], 0.0, None)
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
    p = np.concatenate([u, d, [1.0]])
    x = np.asarray(_newton(model, False)(guess, p)).ravel()
    try:
        return _result(model, _check(model, x, u, d, "Newton"), u, d, "newton")
    except SolverError:
        from .simulate import integrate_constant

        tau = model.spec.holdup_nominal_t / max(u[0], 1e-9)
        x_long = integrate_constant(model, guess, 40.0 * tau, u, d)
        x = np.asarray(_newton(model, False)(x_long, p)).ravel()
        return _result(model, _check(model, x, u, d, "long integration + Newton"), u, d, "integration+newton")


def steady_state_at_load(model, u, d, load_frac: float = 1.0) -> SteadyState:
    """Steady state whose total hold-up is ``load_frac`` x nominal; the feed rate is solved for."""
    _require_transport(model)
    if not 0.0 < load_frac < 5.0:
        raise TwinInputError(f"The 'load_frac' must be a float in (0, 5). Got {load_frac}.")
    u, d = np.asarray(u, float), np.asarray(d, float)
    first = steady_state(model, u, d)
    guess = np.concatenate([first.x, [u[0]]])
    p = np.concatenate([u, d, [load_frac]])
    z = np.asarray(_newton(model, True)(guess, p)).ravel()
    feed = z[-1]
    if not feed > 0:
        raise SolverError(f"No positive feed rate holds the load at {load_frac} of nominal (got {feed:.3g} t/h).")
    uu = np.array([feed, u[1]])
    return _result(model, _check(model, z[:-1], uu, d, "Newton at constant load"), uu, d, "newton-load")
