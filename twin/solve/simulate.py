"""Time integration of a model: IDAS (BDF, stiff) on the model's sparse DAE form (CVODES when
it has no aggregates) with quadratures of fed and produced mass for the mass balance; inputs
constant over a step (:func:`step`, the closed loop's plant) or, in an open-loop run
(:func:`simulate`), linear between samples inside one integrator call, restarted only where an
input jumps; a fixed-step RK4 for convergence studies; and the exact batch solution (matrix
exponential) for the linear batch mill."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
import threading
from functools import lru_cache

import casadi as ca
import numpy as np
import pandas as pd
import scipy.linalg

from ..errors import SolverError, bad_value, check_range
from ..model import NEGATIVE_ROUNDOFF_REL
from ..sizes import pxx_um
from ..validity import nominal_pressure_kpa, trajectory_notes

#: Default integrator tolerances (relative; absolute as a share of nominal hold-up).
RTOL = 1e-8
ATOL_REL = 1e-10


#: Below this relative tolerance IDAS's start-up on the DAE form fails; CVODES on the
#: substituted ODE (dense Jacobian, slower) is used instead.
DAE_MIN_RTOL = 1e-10


#: IDAS computes consistent initial derivatives (without it a restart from rest fails the first
#: error test) and leaves the aggregates, exact functions of x, out of its error test; its
#: Newton systems are solved by a sparse LU (CSparse) on the DAE form's sparse Jacobian, not
#: densely (faster on the replay's 300-state plant: benchmarks/results/twin_open_loop.md).
IDAS_OPTIONS = {"calc_ic": True, "suppress_algebraic": True, "linear_solver": "csparse"}

#: An open-loop input's value just before a sample is read this many sample periods before it.
JUMP_PROBE_FRAC = 1e-9
#: An input jumps at a sample when its value just before differs from its value at the sample,
#: and bends there when its change over the sample after differs from its change over the one
#: before, by more than this (relative to the largest magnitude involved, plus JUMP_ATOL): a
#: probe 1e-9 of a sample before a ramp's sample differs by ~1e-9 of the change per sample, a
#: step by all of it.
JUMP_RTOL = 1e-6
JUMP_ATOL = 1e-9
#: Longest stretch of samples in one integrator call (one integrator is built per stretch
#: length, so this bounds the lengths; a restart on a steady solution costs ~20 BDF steps).
MAX_STRETCH_SAMPLES = 240


def _dae(model, rtol: float, extra: dict) -> tuple[str, dict]:
    """The integrator and problem for a model: IDAS on the sparse DAE form when its aggregates
    enter the right-hand side and the tolerance allows, else CVODES on the plain ODE."""
    uses_z = model.z.numel() > 0 and ca.depends_on(model.dae["ode"], model.z)
    if uses_z and rtol >= DAE_MIN_RTOL:
        quad = extra.pop("quad_dae")
        return "idas", dict(model.dae, quad=quad, **extra)
    quad = model._substitute(extra.pop("quad_dae"))
    return "cvodes", dict(x=model.x, ode=model.xdot, quad=quad, **extra)


#: The cached integrators below are shared by every caller of a model: two threads in one at once
#: crashed the process (IDAS's memory is the Function's) or failed with NaN; their calls take turns.
INTEGRATOR_LOCK = threading.Lock()


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
        with INTEGRATOR_LOCK:
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
    notes: list = field(default_factory=list)  # where the models do not describe it (twin.validity)

    def mass_balance_error(self) -> float:
        """:func:`mass_balance_error` of the run's frame (the ore held ahead of the mill counted too)."""
        return mass_balance_error(self.frame)


def mass_balance_error(frame: pd.DataFrame) -> float:
    """max |fed - produced - (H - H0)| / (fed + H0) over a frame, H the ore held in the mill and, with the
    ``feed_inventory`` effect, ahead of it (``feed_inventory_t``: the quadrature ``fed_t`` counts the ore entering
    the inventory, so without it a feed step's inventory change read as an imbalance); NaN without those columns.
    One function for a run's frame and a scene's KPI (scenarios.run.kpis)."""
    if not {"fed_t", "produced_t", "holdup_t"} <= set(frame.columns):
        return math.nan
    h = frame["holdup_t"].to_numpy(float)
    if "feed_inventory_t" in frame.columns:
        h = h + frame["feed_inventory_t"].to_numpy(float)
    err = frame["fed_t"].to_numpy(float) - frame["produced_t"].to_numpy(float) - (h - h[0])
    return float(np.abs(err).max() / (frame["fed_t"].iloc[-1] + h[0] + 1e-300))


@lru_cache(maxsize=64)
def stretch_integrator(model, dt_h: float, n_steps: int, rtol: float = RTOL, atol_rel: float = ATOL_REL):
    """IDAS over ``n_steps`` sample periods in one call with the inputs linear in time:
    (x0, z0, p = [w0; slope]) -> states at every sample and the cumulative quadratures, where
    the inputs are w(t) = w0 + slope t ([u; d], slope per hour, t from the stretch's start; held
    beyond its end). Constant inputs and ramps are integrated exactly without a restart."""
    t = ca.SX.sym("t")
    n_w = model.u.numel() + model.d.numel()
    w0, slope = ca.SX.sym("w0", n_w), ca.SX.sym("slope", n_w)
    w = w0 + slope * ca.fmin(ca.fmax(t, 0.0), n_steps * dt_h)  # held beyond the end (step overshoot)
    produced = model.output_exprs_dae.get("throughput_tph", ca.SX(0))
    solver, dae = _dae(model, rtol, {"t": t, "p": ca.vertcat(w0, slope),
                                     "quad_dae": ca.vertcat(model.u[0], produced)})
    exprs = [key for key in ("ode", "alg", "quad") if key in dae]
    dae |= dict(zip(exprs, ca.substitute([dae[key] for key in exprs], [ca.vertcat(model.u, model.d)], [w])))
    opts = {"reltol": rtol, "abstol": atol_rel * model.spec.holdup_nominal_t, "max_num_steps": 1000000}
    opts |= IDAS_OPTIONS if solver == "idas" else {}
    return ca.integrator("G", solver, dae, 0.0, dt_h * np.arange(1, n_steps + 1), opts)


def input_stretches(values: np.ndarray, before: np.ndarray) -> list[tuple[int, int]]:
    """Stretches ``(a, b)`` of samples over which every input is linear in time, each one
    integrator call: cut where an input jumps (``before[k - 1]``, its value just before sample
    k, differs from ``values[k]``), where it bends (its change per sample differs on the two
    sides of k) and every :data:`MAX_STRETCH_SAMPLES`."""
    n = len(values) - 1

    def differs(a, b, scale):
        return np.any(np.abs(a - b) > JUMP_RTOL * scale + JUMP_ATOL, axis=1)

    after = before - values[:-1]  # change over [k - 1, k], up to just before k
    jumps = differs(before, values[1:], np.maximum(np.abs(before), np.abs(values[1:])))
    scale = np.maximum(np.abs(values[:-2]), np.maximum(np.abs(values[1:-1]), np.abs(before[1:])))
    bends = differs(after[1:], after[:-1], scale) if n > 1 else np.zeros(0, bool)
    cuts = set((np.nonzero(jumps[:-1])[0] + 1).tolist()) | set((np.nonzero(bends)[0] + 1).tolist())
    cuts |= set(range(MAX_STRETCH_SAMPLES, n, MAX_STRETCH_SAMPLES))
    cuts = sorted(cuts)
    return list(zip([0, *cuts], [*cuts, n]))


#: How far a run's duration may lie from a whole number of samples, relative to it: a duration
#: of 0.12 h at 0.05 h samples ran 0.1 h and returned it as the run asked for.
SAMPLE_GRID_RTOL = 1e-6


def check_run(duration_h, dt_h, rtol, atol_rel) -> int:
    """The number of samples of a run of ``duration_h`` [h] at ``dt_h`` [h]; TwinInputError naming
    the value when either is not a finite positive number, ``dt_h`` is longer than the run or does
    not divide it, or a tolerance is not in (0, 1)."""
    n = sample_count("simulate", duration_h, dt_h)
    check_range("simulate", "rtol", rtol, 0.0, 1.0)  # a negative one was CVODES's "CV_ILL_INPUT" from CasADi
    check_range("simulate", "atol_rel", atol_rel, 0.0, 1.0)
    return n


def sample_count(owner: str, duration_h, dt_h) -> int:
    """The number of samples of ``dt_h`` [h] in a run of ``duration_h`` [h]; TwinInputError naming ``owner``
    and the value when either is not a finite positive number, ``dt_h`` is longer than the run or does not
    divide it (a closed loop of 1.03 h at 0.05 h ran 1.05 h; one of 1 h at 2 h ran no sample, its IAE 0)."""
    duration = check_range(owner, "duration_h", duration_h, 0.0, math.inf)
    dt = check_range(owner, "dt_h", dt_h, 0.0, math.inf)
    if dt > duration * (1.0 + SAMPLE_GRID_RTOL):  # no sample: a reshape error deep inside
        raise bad_value(owner, "dt_h", dt_h, f"a sample period no longer than the run's duration_h ({duration:g} h)")
    n = int(round(duration / dt))
    if abs(n * dt - duration) > SAMPLE_GRID_RTOL * duration:
        raise bad_value(owner, "duration_h", duration_h, f"a whole number of samples of dt_h {dt:g} h (e.g. "
                                                         f"{n * dt:g} or {(n + 1) * dt:g} h)")
    return n


def check_initial_state(model, x0) -> np.ndarray:
    """``x0`` as the model's state vector; TwinInputError naming it when it has another length, is
    not finite or holds a negative mass (the masses come first, t)."""
    try:
        x = np.array(x0, dtype=float)
    except (TypeError, ValueError):
        raise bad_value("simulate", "x0", x0, f"a state vector of {model.n_x} numbers") from None
    if x.shape != (model.n_x,):
        raise bad_value("simulate", "x0", f"an array of shape {x.shape}",
                        f"a state vector of {model.n_x} numbers (e.g. a Trajectory's states[-1] or a SteadyState's x)")
    if not np.all(np.isfinite(x)):
        raise bad_value("simulate", "x0", f"a state with {int(np.sum(~np.isfinite(x)))} non-finite entries",
                        "finite numbers")
    worst = x[: model.n_mass].min()
    if worst < -NEGATIVE_ROUNDOFF_REL * model.spec.holdup_nominal_t:
        raise bad_value("simulate", "x0", f"a state with a mass of {worst:.3g} t", "non-negative masses [t]")
    return model.checked_state(x, "initial state")


def simulate(model, x0, duration_h: float, dt_h: float, u_fn, d_fn, rtol=RTOL, atol_rel=ATOL_REL,
             exact_p80: bool = True) -> Trajectory:
    """Open-loop run with the inputs ``u_fn(t)``, ``d_fn(t)`` (functions of time [h], state-free).

    The inputs are read at every sample and just before it (``JUMP_PROBE_FRAC`` of a sample
    earlier) and are linear between samples, so steps on the sample grid and ramps are exactly
    what the functions say. Each stretch over which they are linear is one IDAS call
    (:func:`input_stretches`); the integrator restarts only where an input jumps or bends
    (SUNDIALS' BDF history must not straddle a jump: across one a feed step fails the error
    test), the value just before held up to a jump."""
    n = check_run(duration_h, dt_h, rtol, atol_rel)
    x0 = check_initial_state(model, x0)
    times = np.arange(n + 1) * dt_h
    us = np.array([u_fn(t) for t in times], float)
    ds = np.array([d_fn(t) for t in times], float)
    values = np.hstack([us, ds])
    probe = times[1:] - JUMP_PROBE_FRAC * dt_h
    before = np.hstack([np.array([u_fn(t) for t in probe], float).reshape(n, -1),
                        np.array([d_fn(t) for t in probe], float).reshape(n, -1)])
    xs = np.empty((n + 1, model.n_x))
    xs[0] = x0
    q = np.zeros((n + 1, 2))
    for a, b in input_stretches(values, before):
        slope = (before[b - 1] - values[a]) / ((b - a) * dt_h)
        G = stretch_integrator(model, float(dt_h), int(b - a), rtol, atol_rel)
        try:
            with INTEGRATOR_LOCK:
                out = G(x0=xs[a], z0=_z0(G, model, xs[a]), p=np.concatenate([values[a], slope]))
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
    notes = trajectory_notes(frame, model.spec, model.effect_names, nominal_pressure_kpa=nominal_pressure_kpa(model))
    return Trajectory(frame, xs, q[:, 0], q[:, 1], notes)


@lru_cache(maxsize=64)
def _trajectory_outputs(model, n: int):
    """One Function evaluating every scalar output, the product PSD and (:func:`has_ore_products`) each ore's
    product per size class at n samples at once."""
    names = [name for name, fn in model.outputs.items() if fn.size1_out(0) == 1]
    args = (model.x, model.u, model.d)
    outs = [ca.vertcat(*[model.outputs[k](*args) for k in names]), model.psd_function()(*args)]
    outs += [model.outputs[k](*args) for k in _ore_outputs(model)]
    return names, ca.Function("trajectory_outputs", list(args), outs).map(n)


def _ore_outputs(model) -> list[str]:
    """The model's outputs per ore that a run's frame reads (each ore's product and, in a closed circuit, its
    underflow), where more than one ore makes a product."""
    return [k for k in ("ore_product_tph", "ore_underflow_tph") if k in model.outputs] if has_ore_products(model) else []


#: The key of one ore's product P80 in a steady state's summary and a run's frame (a unit-suffixed label, as
#: every key; no output's name starts so).
ORE_P80_KEY = "ore_{}_p80_um"


def has_ore_products(model) -> bool:
    """Whether a model makes more than one ore's product (a continuous mill of several ores), each
    of which then has its own P80 (:func:`ore_p80_um`)."""
    return len(model.spec.component_names) > 1 and "ore_product_tph" in model.outputs


#: The key of one ore's circulating load (its cyclone underflow over its fresh feed) in a steady state's summary
#: and a run's frame.
ORE_CIRCULATING_LOAD_KEY = "ore_{}_circulating_load_frac"


def ore_circulating_load(names, underflow_tph, feed_tph: float, fractions) -> dict:
    """Each ore's circulating load [-] by ore name: its underflow [t/h] (the model's ``ore_underflow_tph``) over
    its fresh feed, the feed [t/h] times its blend fraction (as ``circulating_load_frac`` is the underflow over the
    feed); NaN for an ore not fed. The ores leave the cyclones at their own cuts (a dense ore's finer: Plitt 1976),
    so a dense ore circulates more than the blend."""
    under = np.asarray(underflow_tph, float).ravel()
    fresh = [feed_tph * float(f) for f in fractions]
    return {name: under[c] / fresh[c] if fresh[c] > 0 else math.nan for c, name in enumerate(names)}


def ore_p80_um(grid, names, flows) -> dict:
    """Each ore's product P80 [um] by ore name, NaN for an ore with no product (``flows`` [t/h] per size class
    and ore, the model's ``ore_product_tph``): the ores leave a classifier at their own cuts, so a dense ore's
    product is finer than the blend's."""
    flows = np.asarray(flows, float)
    return {name: pxx_um(grid, flows[:, c]) if flows[:, c].sum() > 0 else math.nan for c, name in enumerate(names)}


#: Outputs per tonne of fresh feed, undefined without feed (the model's floor on the feed gave ~1e7 kWh/t, and a
#: circulating load of 5.7e6 through a feed stop).
PER_FEED_OUTPUTS = ("specific_energy_kwh_t", "circulating_load_frac")


def outputs_frame(model, xs, us, ds, time_h, exact_p80=True) -> pd.DataFrame:
    """Scalar outputs along a trajectory as a DataFrame (one row per sample); ``p80_um`` (a batch's
    ``content_p80_um``) exact, the model's smooth P80 ``p80_smooth_um``; without ``exact_p80`` the smooth one only.
    A mill of several ores has each ore's exact product P80 too (:data:`ORE_P80_KEY`, NaN where an ore makes none)
    and in a closed circuit each ore's circulating load (:data:`ORE_CIRCULATING_LOAD_KEY`, NaN where it is not fed)."""
    cols = {"time_h": time_h, "feed_tph": us[:, 0], "speed_frac_critical": us[:, 1]}
    for i, name in enumerate(model.spec.component_names):
        cols[f"blend_{name}_frac"] = ds[:, i]
    cols["hardness_scale"] = ds[:, -1]
    names, fn = _trajectory_outputs(model, len(time_h))
    scalars, psd, *ores = (np.asarray(v) for v in fn(xs.T, us.T, ds.T))
    cols |= {name: scalars[i] for i, name in enumerate(names)}
    for name in (n for n in PER_FEED_OUTPUTS if n in cols):
        cols[name] = np.where(us[:, 0] > 0, cols[name], np.nan)
    # one meaning per name, as SteadyState.p80_um: the P80 (of the product, or of a batch's content) is the exact
    # interpolation of its size distribution; the model's smooth output, the one controllers differentiate, is
    # ``*_smooth_um`` beside it (alone with ``exact_p80=False``)
    p80 = "p80_um" if model.psd_what == "product" else "content_p80_um"
    cols[p80.replace("_um", "_smooth_um")] = cols.pop(p80)
    if exact_p80:
        cols[p80] = [pxx_um(model.spec.grid, psd[:, j]) if psd[:, j].sum() > 0 else math.nan
                     for j in range(psd.shape[1])]
    ores = dict(zip(_ore_outputs(model), ores))
    comps = model.spec.component_names
    if exact_p80 and "ore_product_tph" in ores:  # each ore's own P80, its columns present whatever the samples' blends
        # map() puts the samples' matrices side by side
        flows = ores["ore_product_tph"].reshape(psd.shape[0], len(time_h), len(comps))
        per_sample = [ore_p80_um(model.spec.grid, comps, flows[:, j]) for j in range(len(time_h))]
        cols |= {ORE_P80_KEY.format(name): [s[name] for s in per_sample] for name in comps}
    if "ore_underflow_tph" in ores:
        per_sample = [ore_circulating_load(comps, ores["ore_underflow_tph"][:, j], us[j, 0], ds[j, :len(comps)])
                      for j in range(len(time_h))]
        cols |= {ORE_CIRCULATING_LOAD_KEY.format(name): [s[name] for s in per_sample] for name in comps}
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
        with INTEGRATOR_LOCK:
            out = F(x0=x, z0=_z0(F, model, x), p=np.concatenate([np.asarray(u, float), np.asarray(d, float)]))
    except RuntimeError as exc:
        raise SolverError(f"The integrator failed over one {dt_h} h step: {exc}") from exc
    q = np.asarray(out["qf"]).ravel()
    return model.checked_state(np.asarray(out["xf"]).ravel(), "plant step"), float(q[0]), float(q[1])
