"""Nonlinear MPC of the mill: feed rate and speed that hold product P80 at target.

Formulation (direct multiple shooting; Bock & Plitt 1984, "A multiple shooting algorithm for
direct solution of optimal control problems", IFAC World Congress; Rawlings, Mayne & Diehl,
*Model Predictive Control*, 2nd ed., 2017, section 8.5):

- the controller's model ``m.f(x, u, d)`` (time in hours) is discretised over one sample period
  ``dt_h`` by ``rk4_substeps`` classical RK4 steps (:func:`mpc.discretize.rk4_map`); one shooting
  node per sample, ``X_{k+1} = F(X_k, U_k, D_k)`` as equality constraints (states scaled by a
  typical value so the NLP is well conditioned);
- move blocking (Cagienard et al. 2007, "Move blocking strategies in receding horizon control",
  J. Process Control 17, 563-570): the input is a decision variable on every stage, and equality
  constraints ``U_k = U_{k-1}`` inside each block of ``move_block`` samples keep it constant;
- controlled variable: the fraction of the product passing the target size (mass-flow weighted,
  :meth:`twin.model.Model.passing_function`, linear in the states' flows), held at 0.80, which is
  equivalent to P80 = target (interpolation of cumulative passing in log size between class
  bounds is the same in :func:`twin.sizes.pxx_um`); the exact P80 of the plan is reported
  beside it (``last_info``);
- stage cost, summed over k = 0..N-1 with outputs at ``(X_{k+1}, U_k, D_k)``::

      weight_p80 * (100 (passing_k - 0.80))^2                      [per (percentage point)^2]
    + weight_du_feed * (U_k,feed - U_{k-1},feed)^2                  [per (t/h)^2]
    + weight_du_speed * (100 (U_k,speed - U_{k-1},speed))^2         [per (% of critical)^2]
    + weight_energy * specific_energy_kwh_t_k                       [per kWh/t, economic term]
    + load_penalty_quad * s_k^2 + load_penalty_lin * s_k            [soft load band, s_k >= 0]
    + power_penalty_quad * r_k^2 + power_penalty_lin * r_k          [soft power limit, r_k >= 0]

  with ``U_{-1} = u_prev`` (the input applied last). The soft constraints
  ``lo - s_k <= load_frac_k <= hi + s_k`` and ``power_kw_k - r_k <= power_max_kw`` use an exact
  (l1) plus quadratic penalty (Kerrigan & Maciejowski 2000, "Soft constraints and exact
  penalty functions in model predictive control", UKACC Control Conference): with a linear
  weight above the constraint's Lagrange multiplier the soft constraint is met whenever the hard
  one could be;
- hard bounds on the inputs and rate limits ``|U_k - U_{k-1}| <= rate * dt_h``;
- feed-forward: the disturbance trajectory ``D_k`` (blend fractions over the horizon, as a belt
  analyser or stockpile plan foresees them, plus the estimated hardness) is a parameter of the
  NLP; without preview the current ``d`` is held over the horizon.

Layout: the NLP is written as a standard optimal-control problem so the structure-exploiting
solvers apply. The previous input and the outputs' slacks are lifted into the state,
``X~_k = [X_k / scale; U_{k-1}; S_{k-1}]`` with ``X~_{k+1} = [F(X_k, U_k, D_k) / scale; U_k;
S_k]``, so every constraint and cost term of stage k involves (X~_k, U~_k) only: the rate limit
``U_k - V_k``, the output constraints and the P80 term at ``X~_k`` (outputs at
``(X_k, U_{k-1}, D_{k-1})``, the same as above). Variables are ordered ``[X~_0, U~_0, X~_1, ...,
X~_N]`` and constraints ``[gap_0, path_0, gap_1, ..., path_N]``; the initial state and the last
applied input are equalities of ``path_0``. The problem is the same as without lifting (the
IPOPT closed loop is unchanged).

Solvers (``NmpcSettings.solver``), built once and reused:

- ``"ipopt"`` (Waechter & Biegler 2006), exact Hessian (NLP expanded to SX), warm-started from
  the previous solution shifted by one sample (primal, and the constraint and bound multipliers
  stage by stage); 2-3 iterations a sample here;
- ``"fatrop"`` (Vanroye et al. 2023, IROS, "FATROP: a fast constrained optimal control problem
  solver for robot trajectory optimization and control"), interior point on the stage structure
  (dimensions passed, no detection);
- ``"sqpmethod"`` with ``qpsol = "qrqp"``: SQP with exact Hessian. With ``"hpipm"`` it is
  refused, as measured here: ``Search_Direction_Becomes_Too_Small`` after 6 iterations, and no
  convergence in 100 with ``convexify_strategy = "regularize"`` (an indefinite exact Hessian on
  the stages is the likely cause, not confirmed); the Gauss-Newton ``"rti"`` uses HPIPM instead;
- ``"rti"``: the real-time iteration (Diehl, Bock & Schloeder 2005) with a Gauss-Newton Hessian,
  one structured QP per sample by HPIPM (Frison & Diehl 2020, "HPIPM: a high-performance
  quadratic programming framework for model predictive control", IFAC-PapersOnLine 53, 6563),
  qrqp or OSQP, or (``qpsol = "condensed"``) the same QP condensed onto the inputs
  (:mod:`mpc.condense`) and solved by the dense dual active-set method of Goldfarb & Idnani
  (mpc/c/gt_qp.c) in one compiled C call with its data (condensed by a loop over the stages,
  mpc/c/gt_cond.c, on generated stage functions; mpc/c/gt_rti.c), the code that
  ``grindtwin export-controller`` writes out (:mod:`mpc.export`). Iterations are counted per QP.

Failure handling: if the solver does not converge the controller applies the previous plan
shifted by one sample (``fallback_used="shifted_plan"``) while the old plan lasts, then holds the
previous input (``"hold_input"``). A caller that missed samples since the last step (a served
controller after an outage) passes ``samples``: the warm start and the plan move on by that many.
If the solve succeeds but the predicted passing fraction at the
end of the horizon misses 0.80 by more than ``unreachable_tol_frac`` the status says
``"target_unreachable"`` (the best plan is still applied).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields

import casadi as ca
import numpy as np

from mpc.codegen import MODES as CODEGEN_MODES
from mpc.codegen import RTI_CFLAGS, c_library, compiled
from mpc.condense import RTI_C_SOURCES, RtiLibrary, condensed_qp_function, stage_functions
from mpc.discretize import rk4_map, rk4_sensitivity_map
from mpc.errors import MpcInputError, MpcSolverError, is_blend, is_real
from mpc.qpsol import conic
from mpc.results import ControllerStepResult
from twin import centrifuging_note, pxx_um
from twin.ore import blend_sum_tolerance

SOLVERS = ("ipopt", "sqpmethod", "fatrop", "rti")
QP_SOLVERS = ("hpipm", "qrqp", "osqp", "condensed")
#: OSQP's iteration cap: ADMM converges linearly, and to its 1e-8 tolerances on the stiff
#: industrial mill's QP it needs more than OSQP's default 4,000 iterations (and a B/D twin held at its ores' own
#: densities more than a quarter of this cap on its third Gauss-Newton QP).
OSQP_MAX_ITER = 200_000
PASSING_TARGET = 0.80
#: HPIPM's stand-in for an infinite bound. Its default (1e8) keeps the interior point from
#: meeting its tolerance in 200 iterations (measured); the decision variables here are scaled
#: to O(1) (states) or are inputs and slacks below ~100, so 1e4 is inactive and converges in ~7.
HPIPM_INF = 1e4
#: HPIPM's primal regularisation of its Newton step (``reg_prim``; its default 1e-15). The
#: Gauss-Newton Hessian ``2 Jr^T Jr`` is positive semi-definite only to rounding (eigenvalues down
#: to about -1e-13 at a largest diagonal of 2e4, measured on the RTI's QPs), and the LQ
#: factorisation of the robust mode then stalls at iter_max on some QPs, far from the optimum.
#: 1e-10 covers that rounding a thousandfold. It enters the Newton step only (the residuals are
#: the QP's), so the solution is the QP's to HPIPM's tolerances (benchmarks/mpc_hpipm_regularisation.py).
HPIPM_REG_PRIM = 1e-10
HPIPM_MODES = ("robust", "balance", "speed")


#: IPOPT's Hessians (NmpcSettings.hessian)
HESSIANS = ("exact", "limited-memory")


@dataclass
class NmpcSettings:
    """Settings of :class:`Controller` (units in the names; time in hours)."""

    target_p80_um: float = 210.0
    """Product P80 target [um]; the controlled passing fraction at this size is held at 0.80."""
    horizon_steps: int = 20
    """Prediction horizon N in samples."""
    dt_h: float = 0.05
    """Sample period [h] (also the shooting interval)."""
    move_block: int = 1
    """Samples per input block (1 = a free move every sample)."""
    rk4_substeps: int = 3
    """RK4 steps per sample in the prediction model (3 is stable for the 15-class model at 0.05 h)."""
    weight_p80: float = 1.0
    """Weight on (100 (passing - 0.80))^2, per sample."""
    weight_du_feed: float = 0.1
    """Weight on (feed move [t/h])^2."""
    weight_du_speed: float = 0.1
    """Weight on (speed move [% of critical])^2."""
    weight_energy: float = 0.01
    """Economic weight on specific energy [per kWh/t], per sample."""
    feed_tph_min: float = 20.0
    """Lower bound of the feed rate [t/h]."""
    feed_tph_max: float = 45.0
    """Upper bound of the feed rate [t/h]."""
    speed_min: float = 0.60
    """Lower bound of mill speed [fraction of critical]."""
    speed_max: float = 0.85
    """Upper bound of mill speed [fraction of critical]."""
    feed_rate_max_tph_per_h: float = 20.0
    """Largest feed-rate change per hour [t/h per h]."""
    speed_rate_max_per_h: float = 0.10
    """Largest speed change per hour [fraction of critical per h]."""
    load_band_frac: tuple = (0.8, 1.2)
    """Stable band of mill load (hold-up / nominal), soft constraint."""
    load_penalty_lin: float = 100.0
    """l1 (exact) penalty on the load-band violation [per unit of load fraction]."""
    load_penalty_quad: float = 1e4
    """Quadratic penalty on the load-band violation [per (load fraction)^2]."""
    power_max_kw: float = math.inf
    """Soft upper limit of mill power [kW]; inf: no limit."""
    power_penalty_lin: float = 1.0
    """l1 penalty on the power-limit violation [per kW]."""
    power_penalty_quad: float = 0.01
    """Quadratic penalty on the power-limit violation [per kW^2]."""
    solver: str = "ipopt"
    """"ipopt" (interior point, exact Hessian), "sqpmethod" (SQP, exact Hessian, QPs by
    ``qpsol``), "fatrop" (structure-exploiting interior point) or "rti" (real-time iteration:
    ``rti_iterations`` Gauss-Newton QPs per sample by ``qpsol``)."""
    qpsol: str | None = None
    """QP solver of "rti": "hpipm" (Riccati-based interior point on the stage structure; the
    default), "qrqp" (CasADi's sparse active set), "osqp" (ADMM) or "condensed" (the QP condensed
    onto the inputs, :mod:`mpc.condense`, solved by the dense dual active-set method of Goldfarb
    & Idnani in compiled C, mpc/c; by qpOASES on the same condensed QP when nothing may be
    compiled); of "sqpmethod": "qrqp" (the default and only choice, see the module docstring)."""
    rti_iterations: int = 1
    """Gauss-Newton iterations per sample of "rti" (1 = the real-time iteration; more iterate
    towards the Gauss-Newton solution, stopping early when the step is below ``tol``)."""
    max_iter: int = 100
    """Iteration limit of the NLP solver (0 forces a failure: a test of the fallback)."""
    tol: float = 1e-6
    """Convergence tolerance of the NLP solver."""
    hessian: str = "exact"
    """IPOPT Hessian: "exact" (NLP expanded to SX; few iterations, but the build grows with the
    horizon) or "limited-memory" (L-BFGS, MX graph, quick to build, but slow to converge on the
    mill model; ``benchmarks/mpc_nmpc_build.py``)."""
    warm_start: bool = True
    """Start from the previous solution shifted by one sample (primal and dual)."""
    preview: bool = True
    """Use the disturbance preview over the horizon; False: hold the current d (feedback only)."""
    unreachable_tol_frac: float = 0.01
    """Passing-fraction miss at the horizon end above which the status says target_unreachable."""
    hpipm_mode: str = "robust"
    """HPIPM's preset (its ``mode``): "robust" (HPIPM's most careful iterations) or "speed"
    (fewer, cheaper iterations to the same tolerances; benchmarks/results/mpc_compiled.md)."""
    codegen: str = "auto"
    """Compiled QP data of "rti" (:mod:`mpc.codegen`): "auto" (compiled when a C compiler is
    found, else interpreted, warned and counted), "on" (error without a compiler), "off"."""

    def __post_init__(self) -> None:
        def bad(name, allowed):
            raise MpcInputError(f"The '{name}' parameter of NmpcSettings must be {allowed}. "
                                f"Got {getattr(self, name)!r}.")

        for name in ("horizon_steps", "move_block", "rk4_substeps", "rti_iterations"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 1:
                bad(name, "an int >= 1")
        if not isinstance(self.max_iter, (int, np.integer)) or self.max_iter < 0:
            bad("max_iter", "an int >= 0")
        if self.move_block > self.horizon_steps:
            bad("move_block", f"an int in [1, horizon_steps = {self.horizon_steps}]")
        for name in ("target_p80_um", "dt_h", "feed_rate_max_tph_per_h", "speed_rate_max_per_h",
                     "tol", "power_max_kw"):  # limits may be inf (none); the others finite
            v, limit = getattr(self, name), name in ("power_max_kw", "feed_rate_max_tph_per_h", "speed_rate_max_per_h")
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 and not math.isnan(v)
                    and (math.isfinite(v) or limit)):
                bad(name, "a float > 0 (inf: no limit)" if limit else "a finite float > 0")
        for name in ("warm_start", "preview"):  # "false" is a true string
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                bad(name, "True or False")
        if self.hessian not in HESSIANS:
            bad("hessian", f"one of {HESSIANS}")
        if not math.isfinite(self.feed_tph_max):  # (feed_tph_min < feed_tph_max is checked below)
            bad("feed_tph_max", "finite")
        for name in ("weight_p80", "weight_du_feed", "weight_du_speed", "weight_energy",
                     "load_penalty_lin", "load_penalty_quad", "power_penalty_lin",
                     "power_penalty_quad", "unreachable_tol_frac"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                bad(name, "a finite float >= 0")
        if not 0 < self.feed_tph_min < self.feed_tph_max:
            bad("feed_tph_min", f"in (0, feed_tph_max = {self.feed_tph_max})")
        if not 0 < self.speed_max < 1:  # a speed in percent (85) blamed speed_min
            percent = " (a fraction of critical speed, not percent)" if 1 < self.speed_max <= 100 else ""
            bad("speed_max", f"in (0, 1){percent}")
        if not 0 < self.speed_min < self.speed_max:
            bad("speed_min", f"in (0, speed_max = {self.speed_max})")
        lb = tuple(self.load_band_frac)
        if len(lb) != 2 or not 0 <= lb[0] < lb[1]:
            bad("load_band_frac", "a pair (lo, hi) with 0 <= lo < hi")
        if self.solver not in SOLVERS:
            bad("solver", f"one of {SOLVERS}")
        if self.hpipm_mode not in HPIPM_MODES:
            bad("hpipm_mode", f"one of {HPIPM_MODES}")
        if self.codegen not in CODEGEN_MODES:
            bad("codegen", f"one of {CODEGEN_MODES}")
        if self.qpsol is None:
            self.qpsol = "qrqp" if self.solver == "sqpmethod" else "hpipm"
        if self.qpsol not in QP_SOLVERS:
            bad("qpsol", f"one of {QP_SOLVERS}")
        if self.qpsol == "condensed" and self.solver != "rti":
            bad("qpsol", "'condensed' only with solver 'rti'")
        if self.qpsol == "condensed":  # Goldfarb-Idnani needs a positive definite Hessian
            for name in ("weight_du_feed", "weight_du_speed", "load_penalty_quad") + (
                    ("power_penalty_quad",) if math.isfinite(self.power_max_kw) else ()):
                if not getattr(self, name) > 0:
                    bad(name, "> 0 with qpsol 'condensed' (its dense QP solver needs a strictly "
                        "convex QP: every input move and slack must carry a quadratic weight)")
        if self.solver == "sqpmethod" and self.qpsol != "qrqp":
            bad("qpsol", "'qrqp' with solver 'sqpmethod' (HPIPM and OSQP fail inside this SQP, "
                "see mpc.nmpc; use solver 'rti' for them)")

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))


def speed_max_note(settings: NmpcSettings, key: str = "speed_max") -> str | None:
    """A note when ``settings.speed_max`` lies beyond the speed where the charge centrifuges
    (:data:`twin.CENTRIFUGING_FRAC_CRITICAL`, :func:`twin.centrifuging_note`), naming ``key``
    (the setting as its reader knows it), its value and the limit; else None. The controller
    would plan speeds the twin's models do not describe (breakage falls there, the power model
    has no centrifuging loss). A note, not a refusal: the twin notes such a speed and goes on
    (``grindtwin steady --speed 0.99``), and a run warns of it."""
    note = centrifuging_note(settings.speed_max)
    if note is None:
        return None
    return f"{key} = {settings.speed_max:g}: the controller may plan speeds its models do not describe; {note}"


class Controller:
    """Nonlinear MPC on a twin model (``model.f``, ``model.outputs``, ``model.passing_function``).

    ``model`` is the controller's model (typically coarser than the plant: fewer size classes
    and mixers); ``settings`` an :class:`NmpcSettings`. The NLP is built here, once.
    ``make_step(x_est, d_preview, u_prev)`` returns a :class:`ControllerStepResult`;
    ``last_info`` holds the predicted passing fraction, exact P80 and load of the plan.
    """

    input_names = ("feed_tph", "speed_frac_critical")

    def __init__(self, model, settings: NmpcSettings | None = None, x_scale=None):
        self.model = model
        self.settings = s = settings or NmpcSettings()
        if not isinstance(s, NmpcSettings):
            raise MpcInputError(f"The 'settings' parameter of Controller must be NmpcSettings. "
                                f"Got {type(s).__name__}.")
        for out in ("load_frac", "specific_energy_kwh_t", "power_kw"):
            if out not in model.outputs:
                raise MpcInputError(f"The controller's model must have the output '{out}' "
                                    f"(effects 'holdup' and 'power'). Got {sorted(model.outputs)}.")
        self.nx, self.nu, self.nd = model.f.size1_in(0), model.f.size1_in(1), model.f.size1_in(2)
        if x_scale is None:
            x_scale = np.maximum(np.abs(model.initial_state(None)), 1e-3 * model.spec.holdup_nominal_t)
        self.x_scale = np.asarray(x_scale, float).reshape(-1)
        if self.x_scale.size != self.nx or np.any(self.x_scale <= 0):
            raise MpcInputError(f"The 'x_scale' parameter must have {self.nx} entries > 0.")
        self._wpass = self._target_weights(s.target_p80_um)  # refused before the build
        self._build()
        self.reset()

    # ------------------------------------------------------------------ build
    def _build(self) -> None:
        """The NLP in optimal-control layout (see the module docstring, "Layout")."""
        s, m = self.settings, self.model
        nx, nu, nd, N = self.nx, self.nu, self.nd, s.horizon_steps
        F = rk4_map(m.f, s.dt_h, s.rk4_substeps, name="nmpc_F").expand()
        psd_fn = m.product_psd_function()
        xs, us, ds = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("d", nd)
        wpass = ca.SX.sym("wpass", m.spec.grid.count)
        psd = psd_fn(xs, us, ds)
        passing = ca.dot(wpass, psd) / (ca.sum1(psd) + 1e-12 * m.spec.holdup_nominal_t)
        self._out_fn = ca.Function("nmpc_out", [xs, us, ds, wpass],
                                   [passing, m.outputs["load_frac"](xs, us, ds),
                                    m.outputs["specific_energy_kwh_t"](xs, us, ds),
                                    m.outputs["power_kw"](xs, us, ds)])
        self._scale = ca.DM(self.x_scale)
        self._has_power = math.isfinite(s.power_max_kw)
        ns = self._n_slack = 2 if self._has_power else 1
        nxl, nul = nx + nu + ns, nu + ns  # lifted state [x/scale; u_prev; slack], control [u; slack]
        self._nxl, self._nul = nxl, nul

        p_x0, p_d = ca.MX.sym("x0", nx), ca.MX.sym("D", nd, N)
        p_uprev, p_wpass = ca.MX.sym("u_prev", nu), ca.MX.sym("wpass", m.spec.grid.count)
        P = ca.vertcat(p_x0, ca.vec(p_d), p_uprev, p_wpass)
        X = [ca.MX.sym(f"X{k}", nxl) for k in range(N + 1)]
        U = [ca.MX.sym(f"U{k}", nul) for k in range(N)]
        u_lo = np.array([s.feed_tph_min, s.speed_min])
        u_hi = np.array([s.feed_tph_max, s.speed_max])
        inf = np.inf
        gap_sign = -1.0 if s.solver == "fatrop" else 1.0
        w, lbw, ubw, g, lbg, ubg = [], [], [], [], [], []
        residuals, linear = [], 0  # cost = sum(residuals^2) + linear
        self._ix, self._iu, self._ig_gap, self._ig_path, ng_path = [], [], [], [], []
        nw = ng = 0
        for k in range(N + 1):
            Xk, Uk = X[k], (U[k] if k < N else None)
            w.append(Xk); lbw.append(-inf * np.ones(nxl)); ubw.append(inf * np.ones(nxl))
            self._ix.append(np.arange(nw, nw + nxl)); nw += nxl
            t = self._stage_terms(k, Xk, Uk, p_d[:, max(k - 1, 0)], p_x0, p_uprev, p_wpass)
            residuals += t["residuals"]
            linear = linear + t["linear"]
            if k < N:
                w.append(Uk); lbw.append(np.r_[u_lo, np.zeros(ns)]); ubw.append(np.r_[u_hi, inf * np.ones(ns)])
                self._iu.append(np.arange(nw, nw + nul)); nw += nul
                # gap first, then the stage's path constraints (the order hpipm and fatrop ask
                # for); hpipm wants F - X_{k+1}, fatrop X_{k+1} - F
                xk = Xk[:nx] * self._scale
                gap = gap_sign * (self._gap_value(F(xk, Uk[:nu], p_d[:, k]), Uk) - X[k + 1])
                g.append(gap); lbg.append(np.zeros(nxl)); ubg.append(np.zeros(nxl))
                self._ig_gap.append(np.arange(ng, ng + nxl)); ng += nxl
            g.append(t["path"]); lbg.append(t["lo"]); ubg.append(t["hi"])
            self._ig_path.append(np.arange(ng, ng + t["path"].numel())); ng += t["path"].numel()
            ng_path.append(t["path"].numel())
        self._nw = nw
        wv, gv = ca.vertcat(*w), ca.vertcat(*g)
        J = ca.sumsqr(ca.vertcat(*residuals)) + linear
        #: the whole NLP as one expression (the reference the stage-wise QP data is tested against)
        self.nlp = {"x": wv, "f": J, "g": gv, "p": P, "r": ca.vertcat(*residuals)}
        self._lbw, self._ubw = np.concatenate(lbw), np.concatenate(ubw)
        self._lbg, self._ubg = np.concatenate(lbg), np.concatenate(ubg)
        self._dims = {"N": N, "nx": [nxl] * (N + 1), "nu": [nul] * N + [0], "ng": ng_path}
        t0 = time.perf_counter()
        try:
            if s.solver == "rti":
                self._build_rti(ca.Function("rti_cost", [wv, P], [J]))
            else:
                self._solver = ca.nlpsol("nmpc", s.solver, {"x": wv, "f": J, "g": gv, "p": P},
                                         self._nlp_options())
                self.build_report = {"qp_data": "nlpsol (CasADi)"}
        except RuntimeError as exc:
            raise MpcSolverError(f"The '{s.solver}' solver (qpsol {s.qpsol!r}) could not be "
                                 f"built for this NLP. CasADi said: {str(exc)[-300:]}") from exc
        self.build_time_s = time.perf_counter() - t0

    def _gap_value(self, x_next, Uk):
        """Next lifted state ``[F / scale; u_k; s_k]`` from the model's ``x_next``."""
        return ca.vertcat(x_next / self._scale, Uk)

    def _stage_terms(self, k, Xk, Uk, d_prev, p_x0, p_uprev, p_wpass) -> dict:
        """Stage ``k``'s path constraints (with bounds), least-squares residuals and linear cost
        in the lifted variables ``Xk`` (``Uk`` None at k = N); ``d_prev`` is the disturbance
        over the interval before ``X_k`` (see the module docstring, "Layout")."""
        s, nx, nu, ns, N = self.settings, self.nx, self.nu, self._n_slack, self.settings.horizon_steps
        xk, vk, sig = Xk[:nx], Xk[nx:nx + nu], Xk[nx + nu:]
        path, lo, hi, residuals, linear = [], [], [], [], 0
        if k == 0:  # initial state, last applied input, no slack: equalities of stage 0
            path.append(Xk - ca.vertcat(p_x0 / self._scale, p_uprev, ca.DM.zeros(ns)))
            lo.append(np.zeros(Xk.numel())); hi.append(np.zeros(Xk.numel()))
        else:  # outputs at X_k with the input held over the interval before it
            pas, load, se, pw = self._out_fn(xk * self._scale, vk, d_prev, p_wpass)
            lo_band, hi_band = s.load_band_frac
            path.append(ca.vertcat(load - sig[0], load + sig[0]))
            lo.append(np.array([-np.inf, lo_band])); hi.append(np.array([hi_band, np.inf]))
            if self._has_power:
                path.append(pw - sig[1]); lo.append(np.array([-np.inf])); hi.append(np.array([s.power_max_kw]))
            residuals.append(math.sqrt(s.weight_p80) * 100.0 * (pas - PASSING_TARGET))
            linear = linear + s.weight_energy * se
        if k < N:
            uk, sk = Uk[:nu], Uk[nu:]
            du = uk - vk
            path.append(du)
            du_max = np.array([s.feed_rate_max_tph_per_h, s.speed_rate_max_per_h]) * s.dt_h
            free = k % s.move_block == 0  # inside a move block: no move
            lo.append(-du_max if free else np.zeros(nu)); hi.append(du_max if free else np.zeros(nu))
            residuals += [math.sqrt(s.weight_du_feed) * du[0],
                          math.sqrt(s.weight_du_speed) * 100.0 * du[1],
                          math.sqrt(s.load_penalty_quad) * sk[0]]
            linear = linear + s.load_penalty_lin * sk[0]
            if self._has_power:
                residuals.append(math.sqrt(s.power_penalty_quad) * sk[1])
                linear = linear + s.power_penalty_lin * sk[1]
        return {"path": ca.vertcat(*path), "lo": np.concatenate(lo), "hi": np.concatenate(hi),
                "residuals": residuals, "linear": linear}

    def _rti_stage(self, k: int, F_sens) -> ca.Function:
        """Stage ``k``'s share of the Gauss-Newton QP: gap value and Jacobian (from the RK4
        sensitivities ``F_sens`` of the sparse model), path constraints and their Jacobian,
        Hessian block ``2 Jr^T Jr`` and gradient ``2 Jr^T r + grad(linear)``."""
        nx, nu, nd, nxl, nul, N = self.nx, self.nu, self.nd, self._nxl, self._nul, self.settings.horizon_steps
        Xk, Uk = ca.MX.sym("X", nxl), (ca.MX.sym("U", nul) if k < N else ca.MX(0, 1))
        d_prev, d_k = ca.MX.sym("d_prev", nd), ca.MX.sym("d", nd)
        p_x0, p_uprev, p_wpass = ca.MX.sym("x0", nx), ca.MX.sym("u_prev", nu), ca.MX.sym("wpass", self.model.spec.grid.count)
        v = ca.vertcat(Xk, Uk)
        t = self._stage_terms(k, Xk, Uk if k < N else None, d_prev, p_x0, p_uprev, p_wpass)
        r = ca.vertcat(*t["residuals"])
        jr = ca.jacobian(r, v)
        outs = {"path": t["path"], "path_jac": ca.jacobian(t["path"], v),
                "hess": 2.0 * ca.mtimes(jr.T, jr), "grad": 2.0 * ca.mtimes(jr.T, r) + ca.gradient(t["linear"], v)}
        if k < N:
            inv_s = ca.DM(1.0 / self.x_scale)
            x_next, a, b = F_sens(Xk[:nx] * self._scale, Uk[:nu], d_k)
            a_s = ca.mtimes(ca.diag(inv_s), ca.mtimes(a, ca.diag(self._scale)))
            top = ca.horzcat(a_s, ca.MX(nx, nxl - nx), ca.mtimes(ca.diag(inv_s), b), ca.MX(nx, nul - nu))
            outs["gap"] = self._gap_value(x_next, Uk)
            outs["gap_jac"] = ca.vertcat(top, ca.horzcat(ca.MX(nul, nxl), ca.DM.eye(nul)))
        names = list(outs)
        return ca.Function(f"rti_stage{'0' if k == 0 else ('N' if k == N else '')}",
                           [Xk, Uk, d_prev, d_k, p_x0, p_uprev, p_wpass], [outs[n] for n in names],
                           ["X", "U", "d_prev", "d", "x0", "u_prev", "wpass"], names)

    def _rti_qp_function(self) -> ca.Function:
        """``qp_data(w, p) -> (H, grad, g, A)`` of the Gauss-Newton QP, assembled from the
        stage functions (the middle stages mapped over the horizon): the Jacobians are built
        once per stage from the sparse model, never expanded over the horizon."""
        s, nx, nu, nd, nxl, N = self.settings, self.nx, self.nu, self.nd, self._nxl, self.settings.horizon_steps
        F_sens = rk4_sensitivity_map(self.model, s.dt_h, s.rk4_substeps, name="nmpc_F_sens")
        w = ca.MX.sym("w", self._nw)
        p_x0, p_d = ca.MX.sym("x0", nx), ca.MX.sym("D", nd, N)
        p_uprev, p_wpass = ca.MX.sym("u_prev", nu), ca.MX.sym("wpass", self.model.spec.grid.count)
        P = ca.vertcat(p_x0, ca.vec(p_d), p_uprev, p_wpass)
        X = [w[i] for i in self._ix]
        U = [w[i] for i in self._iu] + [ca.MX(0, 1)]
        d_prev = [p_d[:, max(k - 1, 0)] for k in range(N + 1)]
        d_k = [p_d[:, min(k, N - 1)] for k in range(N + 1)]
        st = [None] * (N + 1)
        for k, fn in ((0, self._rti_stage(0, F_sens)), (N, self._rti_stage(N, F_sens))):
            st[k] = fn.call({"X": X[k], "U": U[k], "d_prev": d_prev[k], "d": d_k[k], "x0": p_x0,
                             "u_prev": p_uprev, "wpass": p_wpass})
        if N > 1:
            mid = self._rti_stage(1, F_sens).map(N - 1, "serial")
            out = mid.call({"X": ca.horzcat(*X[1:N]), "U": ca.horzcat(*U[1:N]),
                            "d_prev": ca.horzcat(*d_prev[1:N]), "d": ca.horzcat(*d_k[1:N]),
                            "x0": p_x0, "u_prev": p_uprev, "wpass": p_wpass})
            for name, val in out.items():
                parts = ca.horzsplit(val, val.size2() // (N - 1))
                for k in range(1, N):
                    st[k] = st[k] or {}
                    st[k][name] = parts[k - 1]
        H = ca.diagcat(*[st[k]["hess"] for k in range(N + 1)])
        grad = ca.vertcat(*[st[k]["grad"] for k in range(N + 1)])
        g, rows = [], []
        ncol = [nxl + (self._nul if k < N else 0) for k in range(N + 1)]
        for k in range(N + 1):
            if k < N:
                g.append(st[k]["gap"] - X[k + 1])
                blocks = [ca.MX(nxl, c) for c in ncol]
                blocks[k] = st[k]["gap_jac"]
                blocks[k + 1] = ca.horzcat(-ca.DM.eye(nxl), ca.MX(nxl, ncol[k + 1] - nxl))
                rows.append(blocks)
            g.append(st[k]["path"])
            blocks = [ca.MX(st[k]["path"].numel(), c) for c in ncol]
            blocks[k] = st[k]["path_jac"]
            rows.append(blocks)
        A = ca.blockcat(rows)
        return ca.Function("nmpc_rti_qp_data", [w, P], [H, grad, ca.vertcat(*g), A],
                           ["w", "p"], ["H", "grad", "g", "A"])

    def _qp_options(self) -> dict:
        s = self.settings
        if s.qpsol == "hpipm":  # the stage dimensions of the layout, so HPIPM's Riccati applies
            return {**self._dims, "error_on_fail": False, "inf": HPIPM_INF,
                    "hpipm": {"iter_max": 100, "mode": s.hpipm_mode, "reg_prim": HPIPM_REG_PRIM}}
        if s.qpsol == "condensed":  # the interpreted fallback's qpOASES (its banner: mpc.qpsol.conic)
            return {"printLevel": "none", "error_on_fail": False}
        if s.qpsol == "qrqp":
            return {"print_iter": False, "print_header": False, "error_on_fail": False}
        return {"error_on_fail": False, "osqp": {"verbose": False, "eps_abs": 1e-8, "eps_rel": 1e-8,
                                                 "max_iter": OSQP_MAX_ITER}}

    def _nlp_options(self) -> dict:
        s = self.settings
        opts = {"expand": s.hessian == "exact", "print_time": False}
        if s.solver == "ipopt":
            opts["ipopt"] = {"print_level": 0, "hessian_approximation": s.hessian,
                             "max_iter": int(s.max_iter), "tol": s.tol, "acceptable_tol": 1e3 * s.tol,
                             "sb": "yes", "mu_strategy": "adaptive"}
            if s.warm_start:
                opts["ipopt"].update({"warm_start_init_point": "yes", "warm_start_bound_push": 1e-6,
                                      "warm_start_mult_bound_push": 1e-6})
        elif s.solver == "sqpmethod":
            opts.update({"qpsol": s.qpsol, "qpsol_options": self._qp_options(),
                         "max_iter": int(s.max_iter), "print_header": False,
                         "print_iteration": False, "print_status": False,
                         "tol_pr": s.tol, "tol_du": s.tol, "error_on_fail": False})
        else:  # fatrop: the stage dimensions given, no detection needed
            d = self._dims
            opts.update({"structure_detection": "manual", "N": d["N"], "nx": d["nx"],
                         "nu": d["nu"], "ng": d["ng"],
                         "equality": [bool(v) for v in self._lbg == self._ubg],
                         "fatrop": {"print_level": 0, "max_iter": int(s.max_iter), "tol": s.tol},
                         "error_on_fail": False})
        return opts

    def _build_rti(self, cost_fn) -> None:
        """Real-time iteration (Diehl, Bock & Schloeder 2005, SIAM J. Control Optim. 43,
        1714-1736; Gros et al. 2020, Int. J. Control 93, 62-80): one Gauss-Newton QP per sample
        at the shifted previous solution, full step. Hessian ``2 Jr^T Jr`` of the least-squares
        residuals ``r`` (the linear energy and l1 slack terms enter the gradient only), so it is
        positive semi-definite without regularisation; the QP goes to ``qpsol``. The QP data
        and the cost are compiled (:mod:`mpc.codegen`, ``NmpcSettings.codegen``)."""
        mode = self.settings.codegen
        self._cost, rep_cost = compiled(cost_fn.expand(), mode)
        self._solver = self._rti_solve
        self._rti_c = None
        if self.settings.qpsol == "condensed":
            path, rep_qp = c_library("gt_rti", stage_functions(self), list(RTI_C_SOURCES), mode, RTI_CFLAGS)
            self.build_report = {"qp_data": rep_qp, "cost": rep_cost}
            if path is not None:
                self._rti_c = RtiLibrary(path)
                return
            cond = condensed_qp_function(self)
            # interpreted: the dense condensed QP by qpOASES, the active-set solver made for
            # condensed MPC QPs (Ferreau et al. 2014); qrqp, a sparse solver, once failed on one
            self._qp_data = cond
            self._qp = conic("rti_qp", "qpoases", {"h": cond.sparsity_out("H"), "a": cond.sparsity_out("A")},
                             self._qp_options())
            return
        qp_fn = self._rti_qp_function()
        self._qp_data, rep_qp = compiled(qp_fn, mode)
        self.build_report = {"qp_data": rep_qp, "cost": rep_cost}
        self._qp = conic("rti_qp", self.settings.qpsol,
                         {"h": qp_fn.sparsity_out("H"), "a": qp_fn.sparsity_out("A")}, self._qp_options())

    def _rti_solve(self, x0, p, lbx, ubx, lbg, ubg, **_):
        """``rti_iterations`` Gauss-Newton QPs from ``x0``; the nlpsol-like result dict. The
        stats report success only if every QP solved."""
        w = np.asarray(x0, float).copy()
        n_it = min(self.settings.rti_iterations, self.settings.max_iter)
        ok, status, it = n_it > 0, "rti" if n_it > 0 else "Maximum_Iterations_Exceeded (max_iter 0)", 0
        self.qp_iterations = 0
        self.qp_regularised = 0
        for it in range(1, n_it + 1):
            step, failure = self._rti_qp_step(w, p, lbx, ubx, lbg, ubg)
            if failure:
                ok, status = False, f"rti QP failed: {failure}"
                break
            w += step
            if np.max(np.abs(step)) < self.settings.tol:
                break
        if ok and self.qp_regularised:
            status = "rti (QP Hessian regularised)"
        self._rti_stats = {"success": ok, "return_status": status, "iter_count": it}
        f = float(self._cost(w, p)) if ok else math.nan
        n_g = self._lbg.size
        return {"x": w, "f": f, "lam_g": np.zeros(n_g), "lam_x": np.zeros(w.size)}

    def _rti_qp_step(self, w, p, lbx, ubx, lbg, ubg):
        """One Gauss-Newton QP at ``w``: ``(step, None)``, or ``(None, reason)`` if it failed."""
        if self._rti_c is not None:
            w_next, st, it = self._rti_c.step(w, p)
            self.qp_iterations += it
            self.qp_regularised += st == RtiLibrary.REGULARISED  # H semi-definite to rounding, counted
            return (w_next - w, None) if st in RtiLibrary.SOLVED else (None, RtiLibrary.STATUS.get(st, str(st)))
        if self.settings.qpsol == "condensed":
            H, grad, A, lba, uba, lbv, ubv, Gw, hw = self._qp_data(w, p)
            data, bounds = (H, grad, A), (lba, uba)
        else:
            H, grad, g, A = self._qp_data(w, p)
            g = np.asarray(g, float).ravel()
            data, bounds = (H, grad, A, g), ()
        # as the compiled step (mpc/c/gt_qp.c): a nan or an infinity in the data, or a nan bound (an
        # infinite one is none), is refused before the QP solver, which would fail on it for another reason
        if not (all(ca.DM(v).is_regular() for v in data) and not any(np.any(np.isnan(np.asarray(v, float)))
                                                                     for v in bounds)):
            return None, RtiLibrary.STATUS[RtiLibrary.NOT_FINITE]
        if self.settings.qpsol == "condensed":
            sol = self._qp(h=H, g=grad, a=A, lba=lba, uba=uba, lbx=lbv, ubx=ubv)
        else:
            sol = self._qp(h=H, g=grad, a=A, lba=lbg - g, uba=ubg - g, lbx=lbx - w, ubx=ubx - w)
        st = self._qp.stats()
        self.qp_iterations += int(st.get("iter_count", 0))
        if not st.get("success", False):
            return None, st.get("return_status", "unknown")
        if self.settings.qpsol == "condensed":
            return np.asarray(ca.mtimes(Gw, sol["x"]) + hw, float).ravel(), None
        return np.asarray(sol["x"], float).ravel(), None

    # ------------------------------------------------------------------ state
    def reset(self, u_prev=None) -> None:
        """Forget the previous solution (warm start, plan, fallback counters)."""
        self._w_prev = None
        self._lam_g_prev = None
        self._lam_x_prev = None
        self._plan_prev = None
        self._plan_age = 0
        self.last_info: dict = {}

    def set_target(self, target_p80_um: float) -> None:
        """Change the P80 target without rebuilding (the passing weights are a parameter); a refused
        target changes nothing."""
        self._wpass = self._target_weights(target_p80_um)
        self.settings.target_p80_um = float(target_p80_um)

    def _target_weights(self, target_p80_um) -> np.ndarray:
        """The passing weights of ``target_p80_um``, a size inside the grid: at or above its top every
        weight is 1, below its sink every one 0, and the P80 term is then a constant the plan cannot
        move (a 5 um target ran with no word but target_unreachable)."""
        grid = self.model.spec.grid
        lo, hi = float(grid.upper_um[-1] / grid.ratio), float(grid.upper_um[0])
        if isinstance(target_p80_um, np.ndarray) and target_p80_um.ndim == 0:  # np.array(150.0) was taken
            target_p80_um = target_p80_um.item()
        if not (is_real(target_p80_um) and lo < target_p80_um < hi):
            raise MpcInputError(f"The 'target_p80_um' parameter must be a size [um] inside the controller's size "
                                f"grid, in ({lo:.4g}, {hi:.4g}). Got {target_p80_um!r}.")
        return np.asarray(grid.passing_weights(float(target_p80_um)), float)

    def _d_traj(self, d_preview) -> np.ndarray:
        N, nd = self.settings.horizon_steps, self.nd
        d = np.asarray(d_preview, float)
        if d.ndim == 1:
            if d.size != nd:
                raise MpcInputError(f"The 'd_preview' parameter must have {nd} entries or shape "
                                    f"({nd}, {N}). Got shape {d.shape}.")
            d = np.repeat(d[:, None], N, axis=1)
        if d.ndim != 2 or d.shape[0] != nd or d.shape[1] < 1:
            raise MpcInputError(f"The 'd_preview' parameter must have shape ({nd}, {N}). "
                                f"Got {d.shape}.")
        if not self.settings.preview:
            d = np.repeat(d[:, :1], N, axis=1)
        if d.shape[1] < N:  # hold the last known value
            d = np.hstack([d, np.repeat(d[:, -1:], N - d.shape[1], axis=1)])
        if not np.all(np.isfinite(d)):
            raise MpcInputError("The 'd_preview' parameter must be finite.")
        blend, hardness = d[:-1, :N], d[-1, :N]
        if not all(is_blend(col) for col in blend.T) or not np.all(hardness > 0):  # a negative hardness: on nothing
            raise MpcInputError(f"The 'd_preview' parameter must hold blend fractions in [0, 1] summing to 1 (within "
                                f"{blend_sum_tolerance(blend.shape[0]):g}) and a hardness > 0 on every stage. Got "
                                f"blend sums {np.round(blend.sum(axis=0), 6).tolist()[:3]}..., hardness "
                                f"{hardness.min():g} at least.")
        return np.vstack([blend / blend.sum(axis=0), hardness])  # rescaled to sum to 1, as the twin's blend

    def _initial_guess(self, x0s, u_prev, samples: int = 1):
        """Primal (and, for IPOPT, dual) start: the previous solution shifted by ``samples`` samples
        (its last stage held), its first lifted state replaced by the new measurement; cold: everything
        at (x0, u_prev)."""
        N, ns, m = self.settings.horizon_steps, self._n_slack, samples
        first = np.r_[x0s, u_prev, np.zeros(ns)]
        if self.settings.warm_start and self._w_prev is not None:
            old = self._w_prev
            w0 = np.empty(self._nw)
            for k in range(N + 1):
                w0[self._ix[k]] = old[self._ix[min(k + m, N)]]
            for k in range(N):
                w0[self._iu[k]] = old[self._iu[min(k + m, N - 1)]]
            w0[self._ix[0]] = first
            lam_g = lam_x = None
            if self._lam_g_prev is not None:
                lg, lx = self._lam_g_prev, self._lam_x_prev
                lam_g, lam_x = lg.copy(), lx.copy()
                for k in range(N - 1):
                    lam_g[self._ig_gap[k]] = lg[self._ig_gap[min(k + m, N - 1)]]
                for k in range(1, N - 1):  # stages 1..N-2 take a later one's (same size)
                    lam_g[self._ig_path[k]] = lg[self._ig_path[min(k + m, N - 1)]]
                for k in range(N):
                    lam_x[self._ix[k]] = lx[self._ix[min(k + m, N)]]
                    lam_x[self._iu[k]] = lx[self._iu[min(k + m, N - 1)]]
            return w0, lam_g, lam_x
        w0 = np.empty(self._nw)
        for k in range(N + 1):
            w0[self._ix[k]] = first
        for k in range(N):
            w0[self._iu[k]] = np.r_[u_prev, np.zeros(ns)]
        return w0, None, None

    # ------------------------------------------------------------------ step
    #: make_step takes the estimator's P80 bias (the closed loop passes it)
    accepts_p80_bias = True

    def make_step(self, x_est, d_preview, u_prev, y_meas=None, p80_bias_um: float = 0.0,
                  samples: int = 1) -> ControllerStepResult:
        """One sample: from the state estimate, the disturbance preview (shape ``(n_d, N)``, or
        ``(n_d,)`` held) and the last applied input to the input to apply now.
        ``p80_bias_um``: the estimated plant-minus-model P80 bias; the model's P80 is held at
        ``target - p80_bias_um`` so that the plant's is at the target (offset-free).
        ``samples``: samples since the last step (more than 1 after missed cycles): the warm start and
        the fallback's plan move on by that many (by one, an outage longer than the horizon had a failed
        step apply a move of the expired plan, where the rule is to hold the input).
        ``y_meas`` is accepted for a common closed-loop verb and not used."""
        s = self.settings
        nx, nu = self.nx, self.nu
        x = np.asarray(x_est, float).reshape(-1)
        if x.size != nx or not np.all(np.isfinite(x)):
            raise MpcInputError(f"The 'x_est' parameter must be {nx} finite values. Got {x.size}.")
        u_prev = np.asarray(u_prev, float).reshape(-1)
        if u_prev.size != nu or not np.all(np.isfinite(u_prev)):
            raise MpcInputError(f"The 'u_prev' parameter must be {nu} finite values. Got {u_prev!r}.")
        if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
            raise MpcInputError(f"The 'samples' parameter must be an int >= 1 (samples since the last step). "
                                f"Got {samples!r}.")
        D = self._d_traj(d_preview)
        x0s = x / self.x_scale
        lo, hi = np.array([s.feed_tph_min, s.speed_min]), np.array([s.feed_tph_max, s.speed_max])
        outside = not np.all((lo <= u_prev) & (u_prev <= hi))
        if outside:  # no move from outside the bounds meets both bounds and rate limits: the QP
            note = (f"input_outside_bounds: applied {u_prev.tolist()} outside [{lo.tolist()}, {hi.tolist()}]; "
                    "planned from its projection (the first move jumps into the bounds); ")
            u_prev = np.clip(u_prev, lo, hi)  # would be infeasible on every sample
        w0, lam_g0, lam_x0 = self._initial_guess(x0s, u_prev, int(samples))
        if not math.isfinite(p80_bias_um) or p80_bias_um >= s.target_p80_um:
            raise MpcInputError(f"The 'p80_bias_um' parameter must be finite and below the target "
                                f"{s.target_p80_um} um. Got {p80_bias_um!r}.")
        wpass = self._wpass if p80_bias_um == 0.0 else np.asarray(
            self.model.spec.grid.passing_weights(s.target_p80_um - p80_bias_um), float)
        p = np.concatenate([x, D.ravel(order="F"), u_prev, wpass])
        args = dict(x0=w0, p=p, lbx=self._lbw, ubx=self._ubw, lbg=self._lbg, ubg=self._ubg)
        if lam_g0 is not None and s.solver == "ipopt":
            args["lam_g0"] = lam_g0
            args["lam_x0"] = lam_x0
        t0 = time.perf_counter()
        try:
            sol = self._solver(**args)
            stats = self._rti_stats if s.solver == "rti" else self._solver.stats()
            ok = bool(stats.get("success", False))
            status = str(stats.get("return_status", "unknown"))
            iters = int(stats.get("iter_count", -1))
        except RuntimeError as exc:  # solver raised (e.g. NaN in a function)
            sol, ok, status, iters = None, False, f"error: {exc}", -1
        dt_solve = time.perf_counter() - t0
        if ok:
            wopt = np.asarray(sol["x"], float).ravel()
            if not np.all(np.isfinite(wopt)):
                ok, status = False, "non-finite solution"
        if outside:
            status = note + status
        if not ok:
            return self._fallback(status, iters, dt_solve, u_prev, int(samples))
        self._w_prev = wopt
        self._lam_g_prev = np.asarray(sol["lam_g"], float).ravel()
        self._lam_x_prev = np.asarray(sol["lam_x"], float).ravel()
        plan = np.array([wopt[i[:nu]] for i in self._iu])
        plan = np.clip(plan, [s.feed_tph_min, s.speed_min], [s.feed_tph_max, s.speed_max])
        states = np.array([wopt[i[:nx]] * self.x_scale for i in self._ix])
        self._plan_prev = plan
        self._plan_age = 0
        info = self._plan_info(states, plan, D, wpass, p80_bias_um)
        if abs(info["passing_end"] - PASSING_TARGET) > s.unreachable_tol_frac:
            status = f"target_unreachable ({status}): predicted P80 {info['p80_end_um']:.1f} um " \
                     f"at the horizon end against {s.target_p80_um:.1f} um"
        self.last_info = info
        # the rate limits as the plant takes them: an interior point solver meets its constraints to its
        # tolerance, and IPOPT's moves exceeded the speed's by 1e-8 on 11 of 30 samples
        return ControllerStepResult(True, status, float(sol["f"]), iters, dt_solve, self._within_rates(plan[0], u_prev),
                                    plan, None, states)

    def _within_rates(self, u, u_prev) -> np.ndarray:
        """``u`` clipped to the rate limits from ``u_prev`` (one sample's move)."""
        s = self.settings
        du_max = np.array([s.feed_rate_max_tph_per_h, s.speed_rate_max_per_h]) * s.dt_h
        return np.clip(u, u_prev - du_max, u_prev + du_max)

    def _plan_info(self, states, plan, D, wpass, p80_bias_um: float) -> dict:
        """The plan's end: passing fraction (of the biased target), P80 with the bias, load..."""
        psd_fn = self.model.product_psd_function()
        x_end, u_end, d_end = states[-1], plan[-1], D[:, -1]
        pas, load, se, pw = (float(v) for v in self._out_fn(x_end, u_end, d_end, wpass))
        # a plan's states are unbounded (the NLP's lbw is -inf): a class may end slightly below zero
        psd = np.maximum(np.asarray(psd_fn(x_end, u_end, d_end), float).ravel(), 0.0)
        p80_end = pxx_um(self.model.spec.grid, psd) + p80_bias_um if psd.sum() > 0 else math.nan
        pas1 = float(self._out_fn(states[1], plan[0], D[:, 0], wpass)[0])
        return {"passing_end": pas, "passing_next": pas1, "p80_end_um": p80_end,
                "load_end_frac": load, "specific_energy_end_kwh_t": se, "power_end_kw": pw}

    def _fallback(self, status, iters, dt_solve, u_prev, samples: int = 1) -> ControllerStepResult:
        s = self.settings
        self._w_prev = None  # cold start after a failure (the old iterate may be the cause)
        self._lam_g_prev = None
        self._lam_x_prev = None
        if self._plan_prev is not None and self._plan_age + samples < s.horizon_steps:
            self._plan_age += samples
            plan = np.vstack([self._plan_prev[self._plan_age:],
                              np.repeat(self._plan_prev[-1:], self._plan_age, axis=0)])
            # the shifted plan was feasible for the old u_prev; keep the rate limit for this one
            u0 = self._within_rates(plan[0], u_prev)
            self.last_info = {"fallback": "shifted_plan"}
            return ControllerStepResult(False, status, math.nan, iters, dt_solve, u0, plan,
                                        "shifted_plan", None)
        self._plan_prev = None
        self._w_prev = None
        self.last_info = {"fallback": "hold_input"}
        plan = np.repeat(u_prev[None, :], s.horizon_steps, axis=0)
        return ControllerStepResult(False, status, math.nan, iters, dt_solve, u_prev.copy(), plan,
                                    "hold_input", None)
