"""Steady states of the continuous mill: a direct Newton solve on the sparse DAE form from a
nominal guess, falling back to long integration; the steady state at a given load; and the
exact sensitivities of a steady state to the disturbances and parameters (implicit function
theorem on the same Newton system)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from ..errors import OverloadError, SolverError, TwinInputError, check_range
from ..mill import load_status
from .numeric import Evaluator, newton_blas_threads
from .simulate import (ORE_CIRCULATING_LOAD_KEY, ORE_P80_KEY, PER_FEED_OUTPUTS, integrate_constant,
                       ore_circulating_load, ore_p80_um)
from ..sizes import pxx_um
from ..validity import nominal_pressure_kpa, nominal_pressure_note, shell_capacity_t, state_notes

#: A mass at most this share of nominal hold-up is round-off to Newton's step cut [-] (float64 carries ~16
#: digits of the hold-up; a margin of 1e4): it is set to zero where its step goes below, instead of bounding
#: the step at 95 % of the way to zero, which a 1e-41 t mass with a round-off step of -1e-15 t cut to 1e-3.
NEWTON_MASS_FLOOR_REL = 1e-12
#: Newton stops when the largest mass-rate residual is below this share of nominal flow [-].
RESIDUAL_REL_TOL = 1e-10


@dataclass
class SteadyState:
    """A steady operating point: state, inputs, disturbances and every scalar output."""

    x: np.ndarray
    u: np.ndarray
    d: np.ndarray
    outputs: dict  # ``p80_um`` the exact P80, as the field; the model's smooth one ``p80_smooth_um``
    p80_um: float  # exact interpolation of the product size distribution
    load_status: str
    psd: np.ndarray  # product flow per class [t/h]
    method: str
    notes: list = field(default_factory=list)  # where the models do not describe it (twin.validity)
    ore_p80_um: dict = field(default_factory=dict)  # each ore's own product P80 (exact), by ore name
    ore_circulating_load_frac: dict = field(default_factory=dict)  # each ore's, in a closed circuit, by ore name

    @property
    def feed_tph(self) -> float:
        return float(self.u[0])

    def summary(self) -> dict:
        """The inputs, the P80 (and :meth:`ore_summary`), the scalar outputs and the load status."""
        out = {"feed_tph": self.feed_tph, "speed_frac_critical": float(self.u[1]), "p80_um": self.p80_um}
        out |= self.ore_summary()
        out |= {k: v for k, v in self.outputs.items() if k not in ("p80_um", "p80_smooth_um")}
        out["load_status"] = self.load_status
        return out

    def ore_summary(self) -> dict:
        """Each ore's product P80 under :data:`ORE_P80_KEY` and circulating load under
        :data:`ORE_CIRCULATING_LOAD_KEY`, where more than one ore makes a product (else {})."""
        ores = {name: v for name, v in self.ore_p80_um.items() if math.isfinite(v)}
        if len(ores) < 2:
            return {}
        return ({ORE_P80_KEY.format(name): v for name, v in ores.items()}
                | {ORE_CIRCULATING_LOAD_KEY.format(name): self.ore_circulating_load_frac[name] for name in ores
                   if name in self.ore_circulating_load_frac})


@lru_cache(maxsize=64)
def _scalar_output_function(model) -> tuple[list, ca.Function]:
    """The model's scalar outputs as one Function (one call instead of one per output)."""
    names = [n for n, fn in model.outputs.items() if fn.size1_out(0) * fn.size2_out(0) == 1]
    exprs = [model.outputs[n](model.x, model.u, model.d) for n in names]
    return names, ca.Function("scalar_outputs", [model.x, model.u, model.d], [ca.vertcat(*exprs)])


#: Outputs that describe the mill's content (its size, minerals and slurry): undefined when it is empty.
CONTENT_OUTPUTS = ("content_p80_um", "soft_frac", "clay_frac", "slurry_relative_viscosity")


def _scalar_outputs(model, x, u, d) -> dict:
    names, fn = _scalar_output_function(model)
    return dict(zip(names, np.asarray(fn(x, u, d), float).ravel().tolist()))


def _filling(model) -> str:
    """The output a load target reads: ``load_frac`` (by volume) when the components' densities differ, else
    ``holdup_t`` [t] (the same load, H / H_nom)."""
    return "load_frac" if model.spec.volume_weights() is not None and "load_frac" in model.outputs else "holdup_t"


@lru_cache(maxsize=64)
def _jacobians(model) -> ca.Function:
    """On the sparse DAE form w = [x; z]: (w, u, d) -> (residual, d res/dw, d res/dfeed, dH/dw)
    with residual = [ode; z - g(x)]; the Jacobian has ~3,000 non-zeros where the plain ODE's is
    dense (the aggregates z carry the coupling)."""
    w = ca.vertcat(model.x, model.z)
    res = ca.vertcat(model.dae["ode"], model.dae["alg"])
    name = _filling(model)
    h = model.output_exprs_dae[name] * (model.spec.holdup_nominal_t if name == "load_frac" else 1)
    return ca.Function("steady_jacobians", [w, model.u, model.d],
                       [res, ca.jacobian(res, w), ca.jacobian(res, model.u[0]), ca.jacobian(h, w)])


#: Up to this many unknowns the Newton matrix is solved dense (LAPACK): for the lab twin's ~80
#: unknowns scipy's sparse construction and solve cost ~10x a dense LU.
DENSE_MAX_UNKNOWNS = 600


def _jacobian_evaluator(model) -> Evaluator:
    """:func:`_jacobians` of ``model`` evaluated on numpy: (residual, J, J_feed, dH/dw), the
    three Jacobians as arrays, or as CSC matrices above DENSE_MAX_UNKNOWNS unknowns (with the
    feed). One per solve (its buffers are its own)."""
    fn = _jacobians(model)
    return Evaluator(fn, matrices=(1, 2, 3), sparse=fn.size1_out(1) + 1 > DENSE_MAX_UNKNOWNS)


def _newton_matrix(J, ju=None, jh=None):
    """The Newton matrix [[J, J_feed], [dH/dw, 0]] (or J alone) of :func:`_jacobian_evaluator`'s
    blocks: dense when they are arrays, CSC when they are sparse."""
    if isinstance(J, np.ndarray):
        return J if ju is None else np.block([[J, ju], [jh, np.zeros((1, 1))]])
    if ju is None:
        return J
    return scipy.sparse.bmat([[J, ju], [jh, None]], format="csc")


def _solve(A, b):
    """A^-1 b for a dense or sparse Newton matrix (b a vector or a matrix of columns)."""
    if isinstance(A, np.ndarray):
        return np.linalg.solve(A, b)
    return scipy.sparse.linalg.splu(A).solve(np.asarray(b, float))


def _newton(model, x, u, d, load_target=None, max_iter: int = 60, masses_held: bool = False):
    """Damped Newton on f(x) = 0 (and holdup(x) = load_target x H_nom, solving for the feed when
    a target is given), on the sparse DAE form. Steps are cut so masses stay non-negative; with
    ``masses_held`` the masses are held where they are (an empty mill's zeros) and the other states
    solved for. Its dense solves on :data:`twin.solve.numeric.NEWTON_BLAS_THREADS` BLAS threads.
    Returns (x, u, ok)."""
    with newton_blas_threads():
        return _newton_steps(model, x, u, d, load_target, max_iter, masses_held)


def _held_rows(A, n: int):
    """The Newton matrix ``A`` with its first ``n`` rows those of the identity (those unknowns' steps 0)."""
    if isinstance(A, np.ndarray):
        A = A.copy()
        A[:n] = 0.0
        A[np.arange(n), np.arange(n)] = 1.0
        return A
    keep = scipy.sparse.diags(np.r_[np.zeros(n), np.ones(A.shape[0] - n)])
    return (keep @ A + scipy.sparse.diags(np.r_[np.ones(n), np.zeros(A.shape[0] - n)])).tocsc()


def _newton_steps(model, x, u, d, load_target, max_iter: int, masses_held: bool = False):
    jac = _jacobian_evaluator(model)
    holdup = Evaluator(model.outputs[_filling(model)]) if load_target is not None else None
    h_nom = model.spec.holdup_nominal_t
    per_h_nom = 1.0 if _filling(model) == "load_frac" else h_nom
    nm, nx = model.n_mass, model.n_x
    floor = NEWTON_MASS_FLOOR_REL * h_nom
    w = np.concatenate([x, model.z_of(x)])
    u = u.copy()
    for _ in range(max_iter):
        r, J, ju, jh = jac(w, u, d)
        scale = _row_scale(model, J)
        load_res = float(holdup(w[:nx], u, d)[0][0]) / per_h_nom - load_target if holdup is not None else 0.0
        if max(np.abs(r * scale).max(), abs(load_res)) < RESIDUAL_REL_TOL:
            return w[:nx], u, True
        try:
            if masses_held:  # round-off masses (1e-41 t) stepping below zero cut every step to 1e-3 of itself
                step = _solve(_held_rows(_newton_matrix(J), nm), -np.r_[np.zeros(nm), r[nm:]])
                dfeed = 0.0
            elif load_target is None:
                step = _solve(_newton_matrix(J), -r)
                dfeed = 0.0
            else:
                sol = _solve(_newton_matrix(J, ju, jh), -np.concatenate([r, [load_res * h_nom]]))
                step, dfeed = sol[:-1], sol[-1]
        except (RuntimeError, ValueError, np.linalg.LinAlgError):
            return w[:nx], u, False
        if not np.all(np.isfinite(step)):
            return w[:nx], u, False  # singular Jacobian: reported by the caller as non-convergence
        alpha = 1.0
        small = w[:nm] <= floor  # round-off masses: set to zero where they step below it, not bounding the step
        neg = (step[:nm] < 0) & ~small
        if np.any(neg):  # keep masses >= 0: go at most 95 % of the way to zero
            alpha = max(min(1.0, 0.95 * (w[:nm][neg] / -step[:nm][neg]).min()), 1e-3)
        if load_target is not None and u[0] + alpha * dfeed <= 0:
            alpha = min(alpha, 0.5 * u[0] / -dfeed)
        w = w + alpha * step
        w[:nm][small] = np.maximum(w[:nm][small], 0.0)
        u[0] = u[0] + alpha * dfeed
    return w[:nx], u, False


def _row_scale(model, J) -> np.ndarray:
    """Weights that make each row of the Newton residual [ode; alg] a relative error: mass rates
    [t/h] by the nominal flow, aggregates [t] by the nominal hold-up; a state beside the masses
    (an analyser's lag in um, a feed inventory in t, a log rate) by its own rate |J_ii| [1/h],
    at least the nominal residence time's, times its initial value (its unit's scale; 1 if that
    is 0). By nominal flow alone, an analyser lag of dead time 1e-7 h weighed its round-off
    (3e7/h x 1e-14 um) above the tolerance, and Newton could never converge."""
    q_nom, h_nom = model.spec.feed_nominal_tph, model.spec.holdup_nominal_t
    nm, nx = model.n_mass, model.n_x
    scale = np.concatenate([np.full(nm, 1.0 / q_nom), np.zeros(nx - nm), np.full(J.shape[0] - nx, 1.0 / h_nom)])
    if nx > nm:
        rate = np.maximum(np.abs(J[nm:nx, nm:nx].diagonal()), q_nom / h_nom)
        size = np.abs(model.initial_state()[nm:nx])
        scale[nm:nx] = 1.0 / (rate * np.where(size > 0.0, size, 1.0))
    return scale


def _check(model, x, u, d, how: str):
    x = model.checked_state(x, f"the steady state ({how})")
    w = np.concatenate([x, model.z_of(x)])
    r, J, _, _ = _jacobian_evaluator(model)(w, u, d)
    res = np.abs(r * _row_scale(model, J))[:model.n_x].max()
    if not res < 1e3 * RESIDUAL_REL_TOL:
        raise SolverError(f"Steady state ({how}) did not converge: residual {res:.3g} of nominal flow.")
    return x


def _result(model, x, u, d, method) -> SteadyState:
    outs = _scalar_outputs(model, x, u, d)
    for name in (n for n in PER_FEED_OUTPUTS if n in outs and not u[0] > 0.0):  # undefined without feed
        outs[name] = math.nan
    flows = np.asarray(model.outputs["ore_product_tph"](x, u, d), float)  # per size class and ore
    psd = flows.sum(axis=1)  # the product per size class, added as the model adds it (ore by ore)
    p80 = pxx_um(model.spec.grid, psd) if psd.sum() > 0 else math.nan
    # sizes of nothing are undefined: the model's smooth P80 gives ~1.6 um for no product, which an
    # analyser's lag (p80_measured_um) then reports; the content of an empty mill likewise (its
    # slurry's viscosity read 14.2 for a slurry that is not there)
    if "p80_um" in outs:  # one meaning per name, as a trajectory's (outputs_frame): the model's smooth P80 beside
        outs["p80_smooth_um"] = outs.pop("p80_um")
        outs["p80_um"] = p80
    undefined = [k for k in ("p80_smooth_um", "p80_measured_um") if not psd.sum() > 0]
    undefined += list(CONTENT_OUTPUTS) if not outs.get("holdup_t", 1.0) > 0.0 else []
    outs.update({k: math.nan for k in undefined if k in outs})
    status = load_status(outs["load_frac"], model.spec.mill.stable_band) if "load_frac" in outs else "n/a"
    notes = state_notes(model.spec, model.effect_names, float(u[1]), outs.get("holdup_t", 0.0), outs.get("clay_frac"),
                        outs, psd, nominal_pressure_kpa(model))
    notes.append(_undefined_note(float(u[0]), outs))
    notes = [n for n in notes if n]
    names = model.spec.component_names
    loads = {} if "ore_underflow_tph" not in model.outputs or len(names) < 2 else ore_circulating_load(
        names, model.outputs["ore_underflow_tph"](x, u, d), float(u[0]), d[:len(names)])
    return SteadyState(x, u, d, outs, p80, status, psd, method, notes, ore_p80_um(model.spec.grid, names, flows), loads)


def _undefined_note(feed_tph: float, outs: dict) -> str:
    """Which outputs a state leaves undefined (NaN) and why: without feed the steady mill is empty
    and makes no product (a Python user got NaN and no word)."""
    nan = sorted((k for k, v in outs.items() if isinstance(v, float) and math.isnan(v)),
                 key=lambda k: ("p80_um", "specific_energy_kwh_t", k).index(k))  # the headline ones first
    if not nan:
        return ""
    why = "no feed: the steady mill is empty and makes no product" if not feed_tph > 0.0 else "not finite at this state"
    return f"{', '.join(nan)} undefined (NaN): {why}"


def _require_transport(model):
    if "transport" not in model.effect_names:
        raise TwinInputError("A steady state needs the 'transport' effect (a batch mill has none: "
                             "everything ends in the finest class).")


def steady_state(model, u, d, x_guess=None) -> SteadyState:
    """Steady state at inputs u and disturbances d (Newton; long integration if Newton fails)."""
    _require_transport(model)
    u, d = np.asarray(u, float), np.asarray(d, float)
    if u[0] <= 0.0:  # no feed: the mill empties, and its other states settle with it
        x = np.zeros(model.n_x)
        x[model.n_mass:] = model.initial_state(d[:model.n_components])[model.n_mass:]
        if model.n_x > model.n_mass:  # a feed inventory drains, lags follow: their initial guess was not steady
            x, _, ok = _newton(model, x, u, d, masses_held=True)
            if not ok:
                raise SolverError(f"Steady state not found at zero feed (speed {u[1]:.3f}): Newton failed on the "
                                  "states beside the masses (feed inventory, lags).")
            x[:model.n_mass] = 0.0  # the solve's round-off (~1e-29 t) would make a product of nothing a P80
        return _result(model, _check(model, x, u, d, "empty (no feed)"), u, d, "empty (no feed)")
    guess = model.initial_state(d[:model.n_components]) if x_guess is None else np.asarray(x_guess, float)
    x, _, ok = _newton(model, guess, u, d)
    if ok:
        return _result(model, _check(model, x, u, d, "Newton"), u, d, "newton")


    tau = model.spec.holdup_nominal_t / u[0]
    try:
        x_long = integrate_constant(model, guess, 40.0 * tau, u, d)
    except SolverError as exc:
        nominal = model.spec.feed_nominal_tph
        raise SolverError(f"Steady state not found at feed {u[0]:.4g} t/h ({u[0] / nominal:.2g} of the mill's nominal "
                          f"{nominal:g} t/h), speed {u[1]:.3f}: Newton failed from the nominal guess and the "
                          f"integration over 40 nominal residence times ({40.0 * tau:.3g} h) failed too "
                          f"({str(exc).splitlines()[0][:160]}). A feed far below the nominal holds the mill "
                          "nearly empty for a very long time: give a feed nearer the mill's nominal.") from exc
    x, _, ok = _newton(model, x_long, u, d)
    if not ok:
        overload = _overload_text(model, x_long, u, d)
        raise (OverloadError if overload else SolverError)(
            "Steady state not found: Newton failed from the nominal guess and after 40 residence times of "
            f"integration at feed {u[0]:.4g} t/h, speed {u[1]:.3f}." + (overload or _drift_text(model, x_long, u, d)))
    return _result(model, _check(model, x, u, d, "long integration + Newton"), u, d, "integration+newton")


def _drift_text(model, x, u, d) -> str:
    """Where the integration's end state ``x`` was going when Newton failed from it and the mill did not
    overload: its hold-up and the hold-up's rate of change over the feed (Newton's words alone named
    neither), and cyclones no grinding cyclone is at the nominal feed (:func:`nominal_pressure_note`)."""
    held = float(model.outputs["holdup_t"](x, u, d))
    rate = float(np.sum(np.asarray(model.f(x, u, d), float).ravel()[:model.n_mass]))
    cyclones = nominal_pressure_note(model)
    return (f" By then the mill held {held:.3g} t ({held / model.spec.holdup_nominal_t:.3g}x its nominal hold-up), "
            f"changing by {rate:+.3g} t/h ({rate / u[0]:+.2g} of the feed)" + (f". {cyclones}" if cyclones else "")
            + ".")


def _overload_text(model, x, u, d) -> str:
    """What the state ``x`` at the end of the integration says when it holds more ore than the mill
    filled to its shell (:meth:`twin.Mill.max_holdup_t`): the mill overloads ("" if it does not)."""
    held = float(model.outputs["holdup_t"](x, u, d))
    load = float(model.outputs["load_frac"](x, u, d)) if "load_frac" in model.outputs else None
    shell = float(shell_capacity_t(model.spec, held, load))
    if not held > shell:
        return ""
    text = (f" The mill overloads: by then it held {held:.3g} t of ore ({held / model.spec.holdup_nominal_t:.3g}x its "
            f"nominal hold-up), more than it holds filled to its shell ({shell:.3g} t). A lower feed may have one.")
    note = nominal_pressure_note(model)
    return text + (f" {note}" if note else "")


#: Largest hold-up over nominal :func:`steady_state_at_load` solves for: above any ball mill filled to
#: its shell (:meth:`twin.Mill.max_holdup_t`: 5.6x nominal for the shipped mills), whose feed
#: the CLI names when it refuses an overflowing steady state.
MAX_LOAD_FRAC = 10.0


def steady_state_at_load(model, u, d, load_frac: float = 1.0, x_guess=None) -> SteadyState:
    """Steady state whose total hold-up is ``load_frac`` x nominal; the feed rate is solved for,
    from ``u[0]``. Newton starts from ``x_guess`` when given (e.g. a nearby solution), else from
    the steady state at feed ``u[0]``."""
    _require_transport(model)
    load_frac = check_range("steady_state_at_load", "load_frac", load_frac, 0.0, MAX_LOAD_FRAC, hi_open=False)
    u, d = np.asarray(u, float), np.asarray(d, float)
    start = steady_state(model, u, d).x if x_guess is None else np.asarray(x_guess, float)
    x, uu, ok = _newton(model, start, u, d, load_target=load_frac)
    if not ok or not uu[0] > 0:
        raise SolverError(f"No positive feed rate found that holds the load at {load_frac} of nominal "
                          f"(speed {u[1]:.3f}); last feed {uu[0]:.4g} t/h.")
    return _result(model, _check(model, x, uu, d, "Newton at constant load"), uu, d, "newton-load")


# ---------------------------------------------------------------------- sensitivities
@lru_cache(maxsize=64)
def _sensitivity_functions(model, n_d: int) -> ca.Function:
    """(w, u, d) -> (d res/dd, product psd, d psd/dx, d psd/du, d psd/dd) and, for the scalar
    outputs, their Jacobians in x, u, d (the outputs in x, aggregates substituted); derivatives
    in the first ``n_d`` entries of d."""
    w = ca.vertcat(model.x, model.z)
    dd = model.d[:n_d]
    res = ca.vertcat(model.dae["ode"], model.dae["alg"])
    psd = model.product_psd_function()(model.x, model.u, model.d)
    outs = [model.outputs[n](model.x, model.u, model.d) for n in SENSITIVITY_OUTPUTS if n in model.outputs]
    y = ca.vertcat(*outs)
    return ca.Function("steady_sensitivities", [w, model.u, model.d],
                       [ca.jacobian(res, dd), psd, ca.jacobian(psd, model.x), ca.jacobian(psd, model.u),
                        ca.jacobian(psd, dd), ca.jacobian(y, model.x), ca.jacobian(y, model.u), ca.jacobian(y, dd)])


#: The scalar outputs whose sensitivities :func:`steady_sensitivities` returns (when present).
SENSITIVITY_OUTPUTS = ("specific_energy_kwh_t", "power_kw", "throughput_tph", "load_frac")


def pxx_gradient(grid, mass, percent: float = 80.0) -> np.ndarray:
    """d Pxx / d mass [um per unit mass] of :func:`twin.sizes.pxx_um` (its interpolation, linear
    in log size between class upper sizes, differentiated; tested against its differences)."""
    m = np.asarray(mass, float)
    f = percent / 100.0
    total = m.sum()
    passing = grid.cumulative_passing(m)
    up = grid.upper_um
    n = m.size
    # d passing_i / d m_j = ([j >= i] - passing_i) / total
    dpass = (np.triu(np.ones((n, n))) - passing[:, None]) / total
    p = pxx_um(grid, m, percent)
    if passing[-1] >= f:  # inside the sink: p = up[-1] ratio^((f - P)/P)
        q = passing[-1]
        return p * math.log(grid.ratio) * (-f / q ** 2) * dpass[-1]
    k = int(np.nonzero(passing >= f)[0][-1])
    lo, hi = passing[k + 1], passing[k]
    dtheta = (-(dpass[k + 1]) * (hi - lo) - (f - lo) * (dpass[k] - dpass[k + 1])) / (hi - lo) ** 2
    return p * math.log(up[k] / up[k + 1]) * dtheta


def steady_sensitivities(model, ss: SteadyState, at_load: bool, n_d: int | None = None) -> dict:
    """Exact derivatives of a converged steady state's KPIs with respect to the disturbance
    vector d (blend, hardness scale and any parameter symbols of a parametric model; its first
    ``n_d`` entries, all by default), by the
    implicit function theorem on the Newton system of :func:`_newton`: with F(w, q; d) = 0 the
    steady-state equations (and, ``at_load``, the hold-up equation, q the feed rate solved
    for), dw/dd = -F_w^-1 F_d. Returns {name: gradient over d} for ``p80_um`` (exact
    interpolation, :func:`pxx_gradient`), ``feed_tph`` (at load) and the scalar outputs of
    :data:`SENSITIVITY_OUTPUTS` the model has."""
    x, u, d = ss.x, ss.u, ss.d
    w = np.concatenate([x, model.z_of(x)])
    _, J, ju, jh = _jacobian_evaluator(model)(w, u, d)
    n_d = model.d.numel() if n_d is None else int(n_d)
    r_d, psd, psd_x, psd_u, psd_d, y_x, y_u, y_d = _sensitivity_functions(model, n_d)(w, u, d)
    rhs = -np.asarray(ca.DM(r_d), float)
    if at_load:
        A = _newton_matrix(J, ju, jh)
        rhs = np.vstack([rhs, np.zeros((1, rhs.shape[1]))])
    else:
        A = _newton_matrix(J)
    try:
        sol = _solve(A, rhs)
    except (RuntimeError, np.linalg.LinAlgError) as exc:  # a singular Newton matrix
        raise SolverError(f"Steady-state sensitivities: the Newton matrix is singular ({exc}).") from None
    nx = model.n_x
    dx = sol[:nx]
    dq = sol[-1] if at_load else np.zeros(rhs.shape[1])

    def total(jx, ju, jd):
        jx, ju, jd = (np.asarray(ca.DM(a), float) for a in (jx, ju, jd))
        return jx @ dx + np.outer(ju[:, 0], dq) + jd

    dpsd = total(psd_x, psd_u, psd_d)
    out = {"p80_um": pxx_gradient(model.spec.grid, np.asarray(psd, float).ravel()) @ dpsd}
    if at_load:
        out["feed_tph"] = dq
    names = [n for n in SENSITIVITY_OUTPUTS if n in model.outputs]
    dy = total(y_x, y_u, y_d)
    out.update({n: dy[i] for i, n in enumerate(names)})
    return out
