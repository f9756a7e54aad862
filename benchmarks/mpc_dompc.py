"""Our NMPC beside do-mpc on the reference case of issue 5: solve time and closed-loop cost.

Issue 5: "Side by side with do-mpc on the same CasADi model and the same horizon: solve time
and closed-loop cost. Goals for the reference case on this machine: median step at most
50 ms, at least 3x faster than do-mpc at equal closed-loop cost."

Both controllers get the same controller model (``model.f(x, u, d)``, time in hours: 10
classes of ratio 2 x 1 mixer + analyser lag), the same objective weights, bounds and horizon
(20 samples of 0.05 h), the same plant twin (25 classes x 3 mixers), sensors, EKF, preview
(0.5 h lead) and seed; the set-up is imported from ``benchmarks/mpc_reference_case.py``.

do-mpc (``pip install grindtwin[bench]``; a benchmark-only dependency) is wrapped in
:class:`DoMpcController` with the verb of ours, ``make_step(x_est, d_preview, u_prev, y_meas)``
-> :class:`mpc.results.ControllerStepResult`. The model is a ``do_mpc.model.Model`` whose
right-hand side is ``model.f``; the disturbances (blend fractions and hardness) are
time-varying parameters filled from the preview at every step. Differences of formulation
that do-mpc imposes are listed in :data:`DIFFERENCES` and in the result's header.

Configurations on the command line, comma-separated, each ``head+key=value+...``:

- ``--ours``: ``head`` a solver name of :class:`mpc.nmpc.NmpcSettings` (``ipopt``, ``rti``,
  ...), ``key=value`` any NmpcSettings field, passed through unchecked (a field this script
  does not know works; one NmpcSettings does not know is reported as skipped). ``auto``:
  ``ipopt``, plus ``rti`` when :data:`mpc.nmpc.SOLVERS` has it.
- ``--dompc``: ``head`` ``colloc`` (do-mpc's default orthogonal collocation, Radau degree 2,
  one finite element per sample) or ``rk4`` (a discrete do-mpc model whose step is our RK4 map,
  :func:`mpc.discretize.rk4_map`, ``rk4_substeps`` of ours: the discretisation closest to
  ours); ``key=value`` with a dot goes to ``nlpsol_opts`` (e.g. ``ipopt.tol=1e-6``), without
  one to ``mpc.settings`` (e.g. ``collocation_deg=3``).

Times: "step" is the wall time of the whole ``make_step`` (what a plant computer waits for),
"solver" the wall time of the NLP solver call alone (ours: the ``nlpsol`` call; do-mpc: the
call of its ``nlpsol``, timed the same way). Closed-loop cost: the NMPC stage cost evaluated on what the plant
did, sample by sample (:func:`realised_cost`), the plant's true passing fraction obtained by
re-simulating the plant from the recorded inputs (deterministic: the noise is in the sensors).

Writes benchmarks/results/mpc_dompc.csv (one row per controller), mpc_dompc.md (table, pair
ratios, set-up) and mpc_dompc_runs.csv (one row per sample and controller).

    PYTHONPATH=. python benchmarks/mpc_dompc.py [--duration-h 8] [--ours auto] [--dompc colloc,rk4]
"""

from __future__ import annotations

import argparse
import ast
import hashlib
import math
import os
import platform
import subprocess
import sys
import time
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from mpc_reference_case import (LEAD_H, OUT, TARGET_UM, add_case_arguments,  # noqa: E402
                                reference_ekf, reference_sensors, reference_setup, schedule)

from mpc import LoopSettings, run_closed_loop  # noqa: E402
from mpc.discretize import rk4_map  # noqa: E402
from mpc.errors import MpcInputError  # noqa: E402
from mpc.nmpc import PASSING_TARGET, Controller, NmpcSettings  # noqa: E402
from mpc.results import ControllerStepResult  # noqa: E402
from dem_common import TAG  # noqa: E402


def import_do_mpc():
    """do_mpc, or exit with a message (it is an optional, benchmark-only dependency)."""
    try:
        with warnings.catch_warnings():  # optional features (ONNX, opcua, torch) not installed
            warnings.simplefilter("ignore")
            import do_mpc
    except ImportError as exc:
        sys.exit(f"benchmarks/mpc_dompc.py needs do-mpc, which is not installed ({exc}). "
                 "Install the benchmark extra: pip install -e '.[bench]' (or pip install do-mpc).")
    return do_mpc


DIFFERENCES = [
    "discretisation: ours direct multiple shooting with one RK4 map per sample (3 sub-steps); "
    "do-mpc 'colloc' orthogonal collocation (Radau, degree 2, 1 finite element per sample: its "
    "defaults), do-mpc 'rk4' a discrete model whose step is the same RK4 map as ours",
    "stage cost: ours evaluates passing fraction and specific energy at (x_{k+1}, u_k, d_k), "
    "k = 0..N-1; do-mpc's lterm is at (x_k, u_k, d_k) and its mterm at x_N. The passing fraction "
    "depends on x only, so lterm at x_0..x_{N-1} plus mterm at x_N is ours plus a constant; the "
    "energy term (weight 0.01 per kWh/t) is shifted by one state",
    "input moves: do-mpc's rterm with factors (weight_du_feed, 1e4 weight_du_speed) on "
    "(u_k - u_{k-1})^2 with u_{-1} the applied input: the same as ours",
    "load band: ours one slack per stage with l1 (100) + quadratic (1e4) penalty at x_{k+1}; "
    "do-mpc set_nl_cons(soft_constraint=True): one slack per side and stage with the l1 "
    "penalty only (do-mpc has no quadratic slack penalty), at x_k (nl_cons_check_colloc_points "
    "False, its default)",
    "rate limits (20 t/h per h, 0.10 of critical per h): hard constraints in ours; do-mpc has "
    "none and they are omitted there (the applied moves beyond them are counted)",
    "state scaling: the same x_scale as ours (do-mpc's mpc.scaling['_x'])",
    "solver: ours IPOPT tol 1e-6, adaptive mu, warm start of primal and dual shifted by one "
    "sample; do-mpc IPOPT with its defaults (tol 1e-8, mumps, monotone mu), warm start from "
    "the previous solution unshifted (dual passed, but IPOPT's warm_start_init_point is off)",
    "failures: both apply the previous plan shifted by one sample, then hold the input "
    "(do-mpc itself would apply the failed iterate)",
]


# ---------------------------------------------------------------------- do-mpc controller
class _TimedSolver:
    """Stands in for do-mpc's ``mpc.S`` (a casadi nlpsol) and times each call, as ours does."""

    def __init__(self, solver):
        self.solver, self.last_s = solver, math.nan

    def __call__(self, **kwargs):
        t0 = time.perf_counter()
        try:
            return self.solver(**kwargs)
        finally:
            self.last_s = time.perf_counter() - t0

    def __getattr__(self, name):  # stats(), ...
        return getattr(self.solver, name)


class DoMpcController:
    """do-mpc's MPC on a twin model, with the verb of :class:`mpc.nmpc.Controller`.

    ``settings`` is an :class:`NmpcSettings` (weights, bounds, horizon, sample, target; the
    solver fields are ours and unused). ``discretization``: ``"colloc"`` or ``"rk4"`` (see
    the module docstring); ``mpc_settings`` set on ``mpc.settings``; ``nlpsol_opts`` update
    do-mpc's defaults.
    """

    input_names = ("feed_tph", "speed_frac_critical")

    def __init__(self, model, settings: NmpcSettings, discretization: str = "colloc",
                 mpc_settings: dict | None = None, nlpsol_opts: dict | None = None, x_scale=None):
        do_mpc = import_do_mpc()
        self.model = model
        self.settings = s = settings
        if discretization not in ("colloc", "rk4"):
            raise MpcInputError(f"The 'discretization' parameter of DoMpcController must be "
                                f"'colloc' or 'rk4'. Got {discretization!r}.")
        self.nx, self.nu, self.nd = model.f.size1_in(0), model.f.size1_in(1), model.f.size1_in(2)
        N = s.horizon_steps
        if x_scale is None:  # as ours
            x_scale = np.maximum(np.abs(model.initial_state(None)), 1e-3 * model.spec.holdup_nominal_t)
        self.x_scale = np.asarray(x_scale, float).reshape(-1)

        dm = do_mpc.model.Model("continuous" if discretization == "colloc" else "discrete", "SX")
        x = dm.set_variable("_x", "x", shape=(self.nx, 1))
        u = ca.vertcat(dm.set_variable("_u", "feed_tph"), dm.set_variable("_u", "speed_frac_critical"))
        d = dm.set_variable("_tvp", "d", shape=(self.nd, 1))
        if discretization == "colloc":
            dm.set_rhs("x", model.f(x, u, d))
        else:
            dm.set_rhs("x", rk4_map(model.f, s.dt_h, s.rk4_substeps).expand()(x, u, d))
        dm.setup()

        mpc = do_mpc.controller.MPC(dm)
        mpc.settings.n_horizon = N
        mpc.settings.t_step = s.dt_h
        mpc.settings.store_full_solution = False
        mpc.settings.supress_ipopt_output()
        for k, v in (mpc_settings or {}).items():
            if not hasattr(mpc.settings, k):
                raise MpcInputError(f"do-mpc's MPC settings have no field {k!r}.")
            setattr(mpc.settings, k, v)
        mpc.settings.nlpsol_opts.update(nlpsol_opts or {})

        xs, us, ds = dm.x["x"], ca.vertcat(dm.u["feed_tph"], dm.u["speed_frac_critical"]), dm.tvp["d"]
        passing = model.passing_function(s.target_p80_um)
        track = lambda xx: s.weight_p80 * (100.0 * (passing(xx, ca.DM.zeros(self.nu), ds) - PASSING_TARGET)) ** 2  # noqa: E731
        se = model.outputs["specific_energy_kwh_t"](xs, us, ds)
        mpc.set_objective(lterm=track(xs) + s.weight_energy * se, mterm=track(xs))
        mpc.set_rterm(feed_tph=s.weight_du_feed, speed_frac_critical=1e4 * s.weight_du_speed)
        load = model.outputs["load_frac"](xs, us, ds)
        lo, hi = s.load_band_frac
        mpc.set_nl_cons("load_hi", load, ub=float(hi), soft_constraint=True,
                        penalty_term_cons=s.load_penalty_lin)
        mpc.set_nl_cons("load_lo", -load, ub=-float(lo), soft_constraint=True,
                        penalty_term_cons=s.load_penalty_lin)
        if math.isfinite(s.power_max_kw):
            mpc.set_nl_cons("power", model.outputs["power_kw"](xs, us, ds), ub=float(s.power_max_kw),
                            soft_constraint=True, penalty_term_cons=s.power_penalty_lin)
        mpc.bounds["lower", "_u", "feed_tph"] = s.feed_tph_min
        mpc.bounds["upper", "_u", "feed_tph"] = s.feed_tph_max
        mpc.bounds["lower", "_u", "speed_frac_critical"] = s.speed_min
        mpc.bounds["upper", "_u", "speed_frac_critical"] = s.speed_max
        mpc.scaling["_x", "x"] = self.x_scale
        self._tvp = mpc.get_tvp_template()
        mpc.set_tvp_fun(lambda t_now: self._tvp)
        t0 = time.perf_counter()
        mpc.setup()
        self.build_time_s = time.perf_counter() - t0
        mpc.S = _TimedSolver(mpc.S)  # the solver call's wall time (IPOPT's stats here lack a total)
        self.mpc = mpc
        self._obj = ca.Function("obj", [mpc.nlp["x"], mpc.nlp["p"]], [mpc.nlp["f"]])
        self._p80 = model.outputs["p80_um"]
        self.n_decision = int(mpc.nlp["x"].numel())
        self.n_constraints = int(mpc.nlp["g"].numel())
        self._started = False
        self._plan_prev, self._plan_age = None, 0
        self.last_info: dict = {}

    def make_step(self, x_est, d_preview, u_prev, y_meas=None) -> ControllerStepResult:
        s, mpc, N = self.settings, self.mpc, self.settings.horizon_steps
        x = np.asarray(x_est, float).reshape(-1, 1)
        u_prev = np.asarray(u_prev, float).reshape(-1)
        D = np.asarray(d_preview, float)
        D = np.repeat(D.reshape(-1, 1), N, axis=1) if D.ndim == 1 else D
        if not s.preview:
            D = np.repeat(D[:, :1], N, axis=1)
        if D.shape[1] < N:
            D = np.hstack([D, np.repeat(D[:, -1:], N - D.shape[1], axis=1)])
        for k in range(N + 1):
            self._tvp["_tvp", k, "d"] = D[:, min(k, N - 1)]
        mpc.u0 = u_prev.reshape(-1, 1)  # u_{-1} of the rterm: the input applied last
        if not self._started:
            mpc.x0 = x
            mpc.set_initial_guess()
            self._started = True
        try:
            mpc.make_step(x)
            st = mpc.solver_stats
            ok, status = bool(st.get("success", False)), str(st.get("return_status", "unknown"))
            iters, t_solve = int(st.get("iter_count", -1)), mpc.S.last_s
        except RuntimeError as exc:
            ok, status, iters, t_solve = False, f"error: {exc}", -1, math.nan
        if not ok:
            return self._fallback(status, iters, t_solve, u_prev)
        sol = mpc.opt_x_num_unscaled
        plan = np.array([np.asarray(sol["_u", k, 0], float).ravel() for k in range(N)])
        states = np.array([np.asarray(sol["_x", k, 0, -1], float).ravel() for k in range(N + 1)])
        cost = float(self._obj(mpc.opt_x_num, mpc.opt_p_num))
        self._plan_prev, self._plan_age = plan, 0
        self.last_info = {"p80_end_um": float(self._p80(states[-1], plan[-1], D[:, -1]))}
        return ControllerStepResult(True, status, cost, iters, t_solve, plan[0].copy(), plan,
                                    None, states)

    def _fallback(self, status, iters, t_solve, u_prev) -> ControllerStepResult:
        """As ours: the previous plan shifted by one sample while it lasts, then hold."""
        s = self.settings
        if self._plan_prev is not None and self._plan_age + 1 < s.horizon_steps:
            self._plan_age += 1
            plan = np.vstack([self._plan_prev[self._plan_age:],
                              np.repeat(self._plan_prev[-1:], self._plan_age, axis=0)])
            self.last_info = {"fallback": "shifted_plan"}
            return ControllerStepResult(False, status, math.nan, iters, t_solve, plan[0].copy(),
                                        plan, "shifted_plan", None)
        self._plan_prev = None
        self.last_info = {"fallback": "hold_input"}
        plan = np.repeat(u_prev[None, :], s.horizon_steps, axis=0)
        return ControllerStepResult(False, status, math.nan, iters, t_solve, u_prev.copy(), plan,
                                    "hold_input", None)


# ---------------------------------------------------------------------- helpers
class StepTimer:
    """Wraps a controller; records the wall time of each whole ``make_step``."""

    def __init__(self, ctrl):
        self.ctrl, self.step_s = ctrl, []

    def make_step(self, *args, **kwargs):
        t0 = time.perf_counter()
        r = self.ctrl.make_step(*args, **kwargs)
        self.step_s.append(time.perf_counter() - t0)
        return r

    def __getattr__(self, name):  # settings, last_info, ...
        return getattr(self.ctrl, name)


def _value(text: str):
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def parse_configs(spec: str) -> list[tuple[str, str | None, dict]]:
    """``"ipopt,rti+rti_iterations=2"`` -> [(label, head, {key: value}), ...]."""
    out = []
    for tok in (t.strip() for t in spec.split(",")):
        if not tok:
            continue
        parts = tok.split("+")
        head = None if "=" in parts[0] else parts.pop(0)
        opts = {}
        for p in parts:
            if "=" not in p:
                raise SystemExit(f"Configuration {tok!r}: {p!r} is not key=value.")
            k, v = p.split("=", 1)
            opts[k.strip()] = _value(v.strip())
        out.append((tok, head, opts))
    return out


def realised_cost(plant_model, frame: pd.DataFrame, x_loop0, u0, s: NmpcSettings,
                  dt_h: float) -> tuple[float, float]:
    """The NMPC stage cost on what the plant did, summed over the run's samples:
    ``w_p80 (100 (passing_k - 0.80))^2 + w_du_feed dfeed_k^2 + w_du_speed (100 dspeed_k)^2
    + w_energy SE_k + l1/quadratic penalty of the load-band violation``, with the plant's true
    passing fraction at the target, re-simulated from the recorded inputs (the plant is
    deterministic). Returns (cost, largest |P80 re-simulated - P80 recorded| [um], a check)."""
    from twin.solve.simulate import step
    from twin.sizes import pxx_um

    passing = plant_model.passing_function(s.target_p80_um)
    psd_fn = plant_model.product_psd_function()
    x = np.asarray(x_loop0, float).copy()
    u_last = np.asarray(u0, float)
    lo, hi = s.load_band_frac
    cost, worst = 0.0, 0.0
    names = list(plant_model.spec.component_names)
    for _, r in frame.iterrows():
        blend = np.array([r[f"blend_{n}_frac"] for n in names])
        d = plant_model.d_vector(blend, r["hardness_scale"])
        u = np.array([r["feed_tph"], r["speed_frac_critical"]])
        pas = float(passing(x, u_last, d))
        psd = np.asarray(psd_fn(x, u_last, d), float).ravel()
        worst = max(worst, abs(pxx_um(plant_model.spec.grid, psd) - r["p80_um"]))
        du = u - u_last
        viol = max(0.0, lo - r["load_frac"], r["load_frac"] - hi)
        cost += (s.weight_p80 * (100.0 * (pas - PASSING_TARGET)) ** 2
                 + s.weight_du_feed * du[0] ** 2 + s.weight_du_speed * (100.0 * du[1]) ** 2
                 + s.weight_energy * r["specific_energy_kwh_t"]
                 + s.load_penalty_lin * viol + s.load_penalty_quad * viol ** 2)
        x, _, _ = step(plant_model, x, u, d, dt_h)
        u_last = u
    return float(cost), float(worst)


def plant_state_after_warmup(plant_model, x0, u0, dt_h, warmup_h):
    """The plant state the loop starts from (run_closed_loop's warm-up holds u0 on schedule(0))."""
    from twin.solve.simulate import step

    x = np.asarray(x0, float).copy()
    d0 = plant_model.d_vector(np.asarray(schedule(0.0), float), 1.0)
    for _ in range(int(round(warmup_h / dt_h))):
        x, _, _ = step(plant_model, x, u0, d0, dt_h)
    return x


def rate_excess(frame, u0, s: NmpcSettings, dt_h: float) -> dict:
    """Applied moves beyond the rate limits of ours (do-mpc has none)."""
    out = {}
    for col, i, lim in (("feed_tph", 0, s.feed_rate_max_tph_per_h), ("speed_frac_critical", 1,
                                                                      s.speed_rate_max_per_h)):
        du = np.abs(np.diff(np.r_[u0[i], frame[col].to_numpy()])) / dt_h
        out[f"{col}_rate_max_per_h"] = float(du.max())
        out[f"{col}_rate_excess_steps"] = int((du > lim * (1 + 1e-6) + 1e-9).sum())
    return out


def _git_state() -> str:
    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, text=True,
                              capture_output=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "mpc"], cwd=root, text=True,
                               capture_output=True, check=True).stdout.split()
        dirty = [p for p in dirty if p.endswith(".py")]
        if not dirty:
            return head
        sums = [f"{q} sha256 {hashlib.sha256((root / q).read_bytes()).hexdigest()[:12]}"
                for q in dirty if (root / q).exists()]
        return head + f" with uncommitted changes ({'; '.join(sums)})"
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


# ---------------------------------------------------------------------- main
def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_case_arguments(ap)
    ap.add_argument("--ours", default="auto",
                    help="our configurations: solver[+field=value...],... (auto: ipopt, and rti "
                         "when NmpcSettings has it)")
    ap.add_argument("--dompc", default="colloc,rk4",
                    help="do-mpc configurations: colloc|rk4[+setting=value|+ipopt.opt=value...],...")
    ap.add_argument("--tag", default="", type=TAG, help="suffix of the result files")
    ap.add_argument("--lockstep", action="store_true",
                    help="ours (the reference scene's RTI, condensed, compiled) and do-mpc (collocation) "
                         "stepped in lock-step on one closed loop, interleaved: mpc_dompc_lockstep.md")
    args = ap.parse_args(argv)
    if args.lockstep:
        return lockstep_main(args)
    do_mpc = import_do_mpc()
    # do-mpc calls numpy on casadi DMs; casadi 3.8 warns once that it keeps the legacy behaviour
    warnings.filterwarnings("ignore", message=r"\s*casadi: a numpy function", category=FutureWarning)
    dt, N = args.dt_h, args.horizon
    ours_spec = args.ours
    if ours_spec == "auto":
        ours_spec = "ipopt,rti"
    ours, dompcs = parse_configs(ours_spec), parse_configs(args.dompc)

    sensors = reference_sensors()
    plant, ss, ctw, css = reference_setup(sensors, args)
    base = dict(horizon_steps=N, dt_h=dt, target_p80_um=TARGET_UM,
                weight_du_feed=args.weight_du_feed, weight_du_speed=args.weight_du_speed,
                preview=True)
    ref_settings = NmpcSettings(**base)
    x_loop0 = plant_state_after_warmup(plant.model, ss.x, ss.u, dt, args.warmup_h)
    print(f"casadi {ca.__version__}, do-mpc {do_mpc.__version__}; ours: {ours_spec}; "
          f"do-mpc: {args.dompc}; {args.duration_h} h", flush=True)

    jobs = [("ours", *c) for c in ours] + [("do-mpc", *c) for c in dompcs]
    rows, runs, skipped = [], [], []
    for family, label, head, opts in jobs:
        name = f"{family} {label}"
        t0 = time.perf_counter()
        try:
            if family == "ours":
                kw = dict(base, **({"solver": head} if head else {}), **opts)
                ctrl = Controller(ctw.model, NmpcSettings(**kw))
            else:
                mset = {k: v for k, v in opts.items() if "." not in k}
                nopt = {k: v for k, v in opts.items() if "." in k}
                ctrl = DoMpcController(ctw.model, ref_settings, head or "colloc", mset, nopt)
        except Exception as exc:  # a configuration this build cannot make: reported, not fatal
            msg = f"{type(exc).__name__}: {str(exc)[-400:]}"
            print(f"{name}: skipped, {msg}", flush=True)
            skipped.append((name, msg))
            continue
        build_s = time.perf_counter() - t0
        if family == "ours":
            cs = ctrl.settings
            conf = f"solver={cs.solver}" + ("" if cs.solver == "ipopt" else f", qpsol={cs.qpsol}")
            conf += "".join(f", {k}={getattr(cs, k)}" for k in ("rti_iterations",)
                            if cs.solver == "rti" and hasattr(cs, k))
            conf += f", tol={cs.tol}, max_iter={cs.max_iter}, rk4_substeps={cs.rk4_substeps}"
        else:
            ms = ctrl.mpc.settings
            conf = ("orthogonal collocation, Radau degree "
                    f"{ms.collocation_deg}, {ms.collocation_ni} finite element(s) per sample"
                    if (head or "colloc") == "colloc" else
                    f"discrete model, RK4 map with {ref_settings.rk4_substeps} sub-steps")
            conf += f"; nlpsol_opts {ms.nlpsol_opts}"
        print(f"{name}: built in {build_s:.1f} s ({conf})", flush=True)
        timer = StepTimer(ctrl)
        est = reference_ekf(ctw, css, dt, args.hardness_noise)
        t0 = time.perf_counter()
        res = run_closed_loop(plant.model, timer, est, schedule, sensors, ss.x, ss.u,
                              LoopSettings(args.duration_h, dt, seed=args.seed, preview_lead_h=LEAD_H,
                                           target_p80_um=TARGET_UM, estimator_warmup_h=args.warmup_h))
        run_s = time.perf_counter() - t0
        fr = res.frame
        cost, resim_err = realised_cost(plant.model, fr, x_loop0, ss.u, ref_settings, dt)
        step_s = np.asarray(timer.step_s)
        k = res.kpis
        row = {"controller": name, "family": family, "configuration": conf,
               "build_s": build_s, "run_s": run_s,
               "step_time_median_s": float(np.median(step_s)),
               "step_time_p95_s": float(np.percentile(step_s, 95)),
               "solver_time_median_s": float(np.nanmedian(fr["solve_time_s"])),
               "solver_time_p95_s": float(np.nanpercentile(fr["solve_time_s"], 95)),
               "iterations_median": float(fr["iterations"].median()),
               "failed_steps": int((~fr["success"].astype(bool)).sum()),
               "fallback_steps": k["fallback_steps"],
               "p80_iae_um_h": k["p80_iae_um_h"], "p80_within_10um_frac": k["p80_within_10um_frac"],
               "p80_max_abs_err_um": k["p80_max_abs_err_um"],
               "specific_energy_kwh_t": k["specific_energy_kwh_t"], "throughput_t": k["throughput_t"],
               "load_outside_band_frac": k["load_outside_band_frac"],
               "closed_loop_cost": cost, "resim_p80_max_err_um": resim_err,
               **rate_excess(fr, ss.u, ref_settings, dt),
               "n_decision": getattr(ctrl, "n_decision", getattr(ctrl, "_nw", math.nan)),
               "statuses": "; ".join(f"{s} x{n}" for s, n in fr["status"].str.slice(0, 60)
                                     .value_counts().items())}
        print({k2: v for k2, v in row.items() if k2 != "statuses"}, flush=True)
        print(f"  statuses: {row['statuses']}", flush=True)
        rows.append(row)
        runs.append(fr.assign(controller=name, step_time_s=step_s))
        del ctrl, timer

    table = pd.DataFrame(rows)
    ref_d = table[table.family == "do-mpc"].iloc[0] if (table.family == "do-mpc").any() else None
    if ref_d is not None:
        table["dompc_step_median_over_this"] = ref_d["step_time_median_s"] / table["step_time_median_s"]
        table["cost_over_dompc"] = table["closed_loop_cost"] / ref_d["closed_loop_cost"]
    pairs = []
    for _, d in table[table.family == "do-mpc"].iterrows():
        for _, o in table[table.family == "ours"].iterrows():
            pairs.append({"do-mpc": d.controller, "ours": o.controller,
                          "step median ratio do-mpc/ours": d.step_time_median_s / o.step_time_median_s,
                          "solver median ratio do-mpc/ours": d.solver_time_median_s / o.solver_time_median_s,
                          "closed-loop cost ratio do-mpc/ours": d.closed_loop_cost / o.closed_loop_cost,
                          "IAE do-mpc - ours [um h]": d.p80_iae_um_h - o.p80_iae_um_h})
    pairs = pd.DataFrame(pairs)

    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / f"mpc_dompc{args.tag}.csv", index=False)
    if runs:
        pd.concat(runs).to_csv(OUT / f"mpc_dompc{args.tag}_runs.csv", index=False)
    cols = ["controller", "build_s", "step_time_median_s", "step_time_p95_s",
            "solver_time_median_s", "solver_time_p95_s", "iterations_median", "failed_steps",
            "p80_iae_um_h", "p80_within_10um_frac", "specific_energy_kwh_t", "throughput_t",
            "load_outside_band_frac", "closed_loop_cost", "feed_tph_rate_excess_steps",
            "speed_frac_critical_rate_excess_steps"]
    cols += [c for c in ("dompc_step_median_over_this", "cost_over_dompc") if c in table]
    goal = ""
    if ref_d is not None and (table.family == "ours").any():
        o = table[table.family == "ours"].sort_values("step_time_median_s").iloc[0]
        goal = (f"Issue-5 goals against '{ref_d.controller}' (the first do-mpc row): fastest of ours "
                f"'{o.controller}' median step {1e3 * o.step_time_median_s:.0f} ms "
                f"(goal <= 50 ms: {'met' if o.step_time_median_s <= 0.05 else 'not met'}), "
                f"{o.dompc_step_median_over_this:.2f}x faster than do-mpc (goal >= 3x: "
                f"{'met' if o.dompc_step_median_over_this >= 3 else 'not met'}) at closed-loop "
                f"cost ratio ours/do-mpc {o.cost_over_dompc:.3f}.")
    md = [f"# NMPC beside do-mpc: reference case (Type B -> 60 % B / 40 % D at 3 h), horizon {N}",
          "",
          f"Set-up: {args.duration_h} h closed loop, sample {dt} h, horizon {N} samples, preview "
          f"lead {LEAD_H} h, seed {args.seed}; weights du_feed {args.weight_du_feed}, du_speed "
          f"{args.weight_du_speed}, p80 {ref_settings.weight_p80}, energy "
          f"{ref_settings.weight_energy}; EKF on the controller model (hardness noise "
          f"{args.hardness_noise}/sqrt(h), warm-up {args.warmup_h} h); plant twin 25 classes x 3 "
          "mixers; controller model 10 classes (ratio 2) x 1 mixer + analyser lag "
          f"({ctw.model.n_x} states), the same casadi.Function f(x, u, d) in both; sensors P80 "
          "noise 3 um, dead time 0.1 h, sampling 0.05 h. Versions: casadi "
          f"{ca.__version__}, do-mpc {do_mpc.__version__}, Python {platform.python_version()}, "
          f"grindtwin {_git_state()}. Machine: {os.cpu_count()} cores shared with other work "
          f"(load average at the end {os.getloadavg()[0]:.2f}); one run at a time.",
          "",
          "Times: step = wall time of the whole make_step (the per-sample wait), solver = the NLP "
          "solver call alone (ours: the nlpsol call; do-mpc: its nlpsol call, timed the same way). Closed-loop "
          "cost = the NMPC stage cost on the plant's realised trajectory (true passing fraction "
          "at the target, input moves, specific energy, load-band penalty), summed over the "
          "samples; ratios against the first do-mpc row. Rate-excess columns: applied moves "
          "beyond our rate limits (do-mpc has none).",
          "",
          "Configurations:", ""]
    md += [f"- {r.controller}: {r.configuration}; {r.n_decision} decision variables"
           for r in table.itertuples()]
    md += ["", "What differs between the formulations:", ""]
    md += [f"- {d}" for d in DIFFERENCES]
    md += ["", table[cols].to_markdown(index=False, floatfmt=".4g"), ""]
    if len(pairs):
        md += ["Pairs:", "", pairs.to_markdown(index=False, floatfmt=".4g"), ""]
    if goal:
        md += [goal, ""]
    if skipped:
        md += ["Skipped configurations:", ""] + [f"- {n}: {m}" for n, m in skipped] + [""]
    md += ["Solver statuses:", ""] + [f"- {r.controller}: {r.statuses}" for r in table.itertuples()]
    (OUT / f"mpc_dompc{args.tag}.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    return table


def lockstep_main(args) -> pd.DataFrame:
    """Ours and do-mpc's default (collocation) on the same closed loop, their steps interleaved
    (ours drives the plant; do-mpc steps on the same estimate, preview and last input): the
    per-sample step ratio and the difference of the moves they choose on the same data."""
    from mpc_compiled import lockstep

    do_mpc = import_do_mpc()
    warnings.filterwarnings("ignore", message=r"\s*casadi: a numpy function", category=FutureWarning)
    dt, N = args.dt_h, args.horizon
    plant, ss, ctw, css = reference_setup(reference_sensors(), args)
    base = dict(horizon_steps=N, dt_h=dt, target_p80_um=TARGET_UM, rk4_substeps=args.rk4_substeps,
                weight_du_feed=args.weight_du_feed, weight_du_speed=args.weight_du_speed,
                weight_energy=args.weight_energy, preview=True)
    ctrls = {"ours": Controller(ctw.model, NmpcSettings(**base, solver="rti", qpsol="condensed", codegen="on")),
             "do-mpc": DoMpcController(ctw.model, NmpcSettings(**base), "colloc")}
    fr = lockstep(plant.model, ctw, css, ss, ctrls, args.duration_h, dt, args.seed)
    o, d = (fr[fr.controller == n].set_index("time_h") for n in ("ours", "do-mpc"))
    du = np.abs(d[["u_feed", "u_speed"]].to_numpy() / o[["u_feed", "u_speed"]].to_numpy() - 1)
    table = pd.DataFrame([{
        "steps": len(o), "ours_step_median_s": o.step_s.median(), "ours_step_p95_s": o.step_s.quantile(0.95),
        "ours_step_cpu_median_s": o.step_cpu_s.median(), "dompc_step_median_s": d.step_s.median(),
        "dompc_step_cpu_median_s": d.step_cpu_s.median(),
        "dompc_over_ours_median": (d.step_s / o.step_s).median(),
        "dompc_over_ours_cpu_median": (d.step_cpu_s / o.step_cpu_s).median(),
        "move_rel_diff_median": float(np.median(du.max(axis=1))), "move_rel_diff_max": float(du.max()),
        "dompc_failed_steps": int((~d.success.astype(bool)).sum()), "load_1min_median": o.load_1min.median()}])
    print(table.T, flush=True)
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / f"mpc_dompc_lockstep{args.tag}.csv", index=False)
    load = os.getloadavg()
    md = [f"# Ours (RTI, condensed QP, compiled) and do-mpc {do_mpc.__version__} (collocation, IPOPT) in lock-step",
          "", f"The reference transition ({args.duration_h} h, 3-min samples, seed {args.seed}) on the scene's "
          f"controller model ({ctw.model.n_x} states), horizon {N}, the same weights, bounds and preview; ours "
          "drives the plant, do-mpc steps on the same estimate, preview and last input right after it "
          "(interleaved). A step is the whole `make_step` on both sides, timed by the loop (a controller's own "
          "solve_time_s is its solver call: ours 0.87 of a 1.64 ms step; before 12-06 this ratio set our solver "
          "call beside do-mpc's whole step, 552x for 298x in CPU time). `dompc_over_ours_median`: median of the "
          "per-sample ratio of the steps' wall times (`_cpu`: of their thread CPU times); `move_rel_diff`: relative difference of the moves the two choose "
          "on the same data (a collocation NLP solved to convergence against one Gauss-Newton QP on RK4: "
          f"close, not equal). Load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on 2 "
          "shared cores.", "", table.T.rename(columns={0: "value"}).to_markdown(floatfmt=".4g"), "",
          "Reproduce: `PYTHONPATH=. python benchmarks/mpc_dompc.py --lockstep"
          + (f" --tag {args.tag}`." if args.tag else "`.")]
    (OUT / f"mpc_dompc_lockstep{args.tag}.md").write_text("\n".join(md) + "\n")
    return table


if __name__ == "__main__":
    main()
