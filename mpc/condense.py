"""The real-time iteration's Gauss-Newton QP condensed onto the inputs.

The NMPC's QP (:mod:`mpc.nmpc`, "Layout") has the lifted states ``X~_k`` and controls
``U~_k = [u_k; s_k]`` (inputs and soft-constraint slacks) as variables, linked by the linearised
gaps ``dX~_{k+1} = A~_k dX~_k + B~_k dU~_k + c_k`` and the fixed initial step
``dX~_0 = [x0/scale; u_prev; 0] - X~_0``. Condensing (Bock & Plitt 1984; Frison & Jorgensen 2013,
"A fast condensing method for solution of linear-quadratic control problems", IEEE CDC,
7715-7720) eliminates the states: ``dX~_k = T_k dV + t_k`` with ``dV = [dU~_0; ...; dU~_{N-1}]``,
propagated forward stage by stage. What is left is a dense QP in ``N (n_u + n_s)`` variables
(30 at horizon 10 with one slack) with the same solution:

- Hessian ``2 Rj^T Rj`` and gradient ``2 Rj^T R0 + sum_k [T_k; E_k]^T grad(linear_k)``, from the
  stage residuals linearised in ``dV`` (``Rj`` stacked, ``R0`` their values at the step's affine
  part), the Gauss-Newton Hessian of :mod:`mpc.nmpc` without forming a stage Hessian;
- every path constraint of stages 1..N (load band, power limit, rates, move blocks) and the rate
  constraint of stage 0 as a dense row in ``dV`` with its bounds shifted by the affine part; the
  input and slack bounds stay simple bounds;
- ``dw = Gw dV + hw`` recovers the full step of every variable (states and controls).

The propagation uses ``A_k`` only on the directions that ``dx_k`` spans (``1 + n_u k`` columns:
the affine part and the earlier input steps; :func:`mpc.discretize.rk4_directional_map`), not the
``n_x + n_u`` of a full sensitivity, and forms ``A_k`` only where that is fewer directions.

Two implementations of the same arithmetic: :func:`condensed_qp_function`, one CasADi function
(the interpreted path, without a C compiler, and the reference of the tests), and the compiled
path, mpc/c/gt_cond.c, a loop over the stages in C on the small generated functions of
:func:`stage_functions` (the model's sparse factors at one point, the stage terms), which
propagates the directions itself (always directionally: as many operations as forming ``A_k``
here) and keeps the C small whatever the horizon.
"""

from __future__ import annotations

import ctypes

import casadi as ca
import numpy as np

from mpc.discretize import _sensitivity_point, rk4_directional_map, rk4_sensitivity_map
from mpc.errors import MpcInputError

OUTPUTS = ("H", "g", "A", "lba", "uba", "lbx", "ubx", "Gw", "hw")


def _terms_function(ctrl, k: int, name: str | None = None, dense: bool = False) -> ca.Function:
    """Stage ``k``'s residuals, their Jacobian, the linear cost's gradient, the path constraints
    and their Jacobian, in ``v = [X~_k; U~_k]`` (``ctrl._stage_terms``, the NLP's own terms);
    ``dense``: the Jacobians as dense (column-major) matrices, the form mpc/c/gt_cond.c reads."""
    nx, nu, nd, nxl, nul, N = ctrl.nx, ctrl.nu, ctrl.nd, ctrl._nxl, ctrl._nul, ctrl.settings.horizon_steps
    Xk, Uk = ca.MX.sym("X", nxl), (ca.MX.sym("U", nul) if k < N else ca.MX(0, 1))
    d_prev = ca.MX.sym("d_prev", nd)
    p_x0, p_uprev = ca.MX.sym("x0", nx), ca.MX.sym("u_prev", nu)
    p_wpass = ca.MX.sym("wpass", ctrl.model.spec.grid.count)
    v = ca.vertcat(Xk, Uk)
    t = ctrl._stage_terms(k, Xk, Uk if k < N else None, d_prev, p_x0, p_uprev, p_wpass)
    r = ca.vertcat(*t["residuals"])
    lin = t["linear"] if isinstance(t["linear"], ca.MX) else ca.MX(t["linear"])
    outs = [r, ca.jacobian(r, v), ca.gradient(lin, v), t["path"], ca.jacobian(t["path"], v)]
    if dense:
        outs = [ca.densify(o) for o in outs]
    return ca.Function(name or f"cond_terms{'0' if k == 0 else ('N' if k == N else '')}",
                       [Xk, Uk, d_prev, p_x0, p_uprev, p_wpass], outs,
                       ["X", "U", "d_prev", "x0", "u_prev", "wpass"], ["r", "jr", "lg", "path", "jp"])


def _propagators(ctrl):
    """``prop(k)``: the RK4 map of stage k applied to ``1 + n_u k`` directions (directional
    while that is at most ``n_x``, else the full ``A_k`` times the directions)."""
    s, m = ctrl.settings, ctrl.model
    point = _sensitivity_point(m, m.u, "cond_F")
    full = rk4_sensitivity_map(m, s.dt_h, s.rk4_substeps, name="cond_F_full", point=point)
    cache = {}

    def prop(k: int):
        n_dir = 1 + ctrl.nu * k
        if n_dir not in cache:
            if n_dir <= ctrl.nx:
                cache[n_dir] = rk4_directional_map(m, s.dt_h, s.rk4_substeps, n_dir, name=f"cond_F{k}",
                                                   point=point)
            else:
                x, u, d = ca.MX.sym("x", ctrl.nx), ca.MX.sym("u", ctrl.nu), ca.MX.sym("d", ctrl.nd)
                S = ca.MX.sym("S", ctrl.nx, n_dir)
                xn, a, b = full(x, u, d)
                cache[n_dir] = ca.Function(f"cond_F{k}", [x, u, d, S], [xn, ca.mtimes(a, S), b],
                                           ["x", "u", "d", "S"], ["x_next", "AS", "B"])
        return cache[n_dir]
    return prop


def condensed_qp_function(ctrl) -> ca.Function:
    """``cond(w, p) -> (H, g, A, lba, uba, lbx, ubx, Gw, hw)``: the controller's Gauss-Newton QP
    at ``w`` condensed onto ``dV`` (module docstring). ``H``, ``A`` dense; the QP is
    ``min 0.5 dV' H dV + g' dV`` s.t. ``lba <= A dV <= uba``, ``lbx <= dV <= ubx``, and the
    step of all variables is ``Gw dV + hw``."""
    s = ctrl.settings
    nx, nu, nd, nxl, nul, N = ctrl.nx, ctrl.nu, ctrl.nd, ctrl._nxl, ctrl._nul, s.horizon_steps
    if np.any(np.isfinite(ctrl._lbw[np.concatenate(ctrl._ix)])) or np.any(np.isfinite(ctrl._ubw[np.concatenate(ctrl._ix)])):
        raise MpcInputError("Condensing needs unbounded lifted states (bounds on controls only).")
    n = N * nul
    scale = ctrl.x_scale
    inv_s = ca.DM(1.0 / scale)
    diag_inv_s, diag_s = ca.diag(inv_s), ca.diag(ca.DM(scale))
    w = ca.MX.sym("w", ctrl._nw)
    p_x0, p_d = ca.MX.sym("x0", nx), ca.MX.sym("D", nd, N)
    p_uprev, p_wpass = ca.MX.sym("u_prev", nu), ca.MX.sym("wpass", ctrl.model.spec.grid.count)
    P = ca.vertcat(p_x0, ca.vec(p_d), p_uprev, p_wpass)
    X = [w[i] for i in ctrl._ix]
    U = [w[i] for i in ctrl._iu]
    zero_block = ca.MX(nxl, nul)
    eye_l = ca.DM.eye(nul)

    def selector(k):  # E_k: dU~_k = E_k dV
        return ca.horzcat(ca.MX(nul, k * nul), eye_l, ca.MX(nul, (N - k - 1) * nul))

    prop = _propagators(ctrl)
    terms = {0: _terms_function(ctrl, 0), N: _terms_function(ctrl, N)}
    if N > 1:
        mid = _terms_function(ctrl, 1)
        terms.update({k: mid for k in range(1, N)})
    t_k = ca.vertcat(p_x0 / ca.DM(scale), p_uprev, ca.DM.zeros(ctrl._n_slack)) - X[0]
    Tx = []  # x rows of T_k, one nx x nu block per earlier input step
    T_k = ca.MX(nxl, n)
    Rj, R0, rows, lo, hi = [], [], [], [], []
    g = ca.MX(n, 1)
    Gw_rows, hw_rows = [], []
    for k in range(N + 1):
        Uk = U[k] if k < N else ca.MX(0, 1)
        r, jr, lg, path, jp = terms[k](X[k], Uk, p_d[:, max(k - 1, 0)], p_x0, p_uprev, p_wpass)
        M = ca.vertcat(T_k, selector(k)) if k < N else T_k
        Rj.append(ca.mtimes(jr, M))
        R0.append(r + ca.mtimes(jr[:, :nxl], t_k))
        g = g + ca.mtimes(M.T, lg)
        first = nxl if k == 0 else 0  # stage 0's initial-state rows are eliminated
        jp, path = jp[first:, :], path[first:]
        rows.append(ca.mtimes(jp, M))
        shift = path + ca.mtimes(jp[:, :nxl], t_k)
        idx = ctrl._ig_path[k][first:]
        lo.append(ca.DM(ctrl._lbg[idx]) - shift)
        hi.append(ca.DM(ctrl._ubg[idx]) - shift)
        Gw_rows.append(T_k)
        hw_rows.append(t_k)
        if k == N:
            break
        Gw_rows.append(selector(k))
        hw_rows.append(ca.MX(nul, 1))
        # dynamics: dX~_{k+1} = T_{k+1} dV + t_{k+1}
        xk = X[k][:nx] * ca.DM(scale)
        dirs = ca.mtimes(diag_s, ca.horzcat(t_k[:nx], *Tx))  # unscaled directions
        x_next, AS, B = prop(k)(xk, Uk[:nu], p_d[:, k], dirs)
        AS, B = ca.mtimes(diag_inv_s, AS), ca.mtimes(diag_inv_s, B)  # scaled again
        t_next_x = AS[:, 0] + x_next * inv_s - X[k + 1][:nx]
        Tx = [AS[:, 1 + nu * j:1 + nu * (j + 1)] for j in range(k)] + [B]
        blocks = [ca.vertcat(Tx[j], ca.MX(nxl - nx, nu)) for j in range(k + 1)]
        cols = [ca.horzcat(blocks[j], ca.MX(nxl, nul - nu)) for j in range(k)]
        cols.append(ca.horzcat(blocks[k], ca.MX(nxl, nul - nu)) + ca.vertcat(ca.MX(nx, nul), eye_l))
        T_k = ca.horzcat(*cols, *([zero_block] * (N - k - 1)))
        t_k = ca.vertcat(t_next_x, Uk - X[k + 1][nx:])
    Rj, R0 = ca.vertcat(*Rj), ca.vertcat(*R0)
    H = 2.0 * ca.mtimes(Rj.T, Rj)
    g = g + 2.0 * ca.mtimes(Rj.T, R0)
    iu = np.concatenate(ctrl._iu)
    w_u = ca.vertcat(*U)
    lbx, ubx = ca.DM(ctrl._lbw[iu]) - w_u, ca.DM(ctrl._ubw[iu]) - w_u
    order = np.argsort(np.concatenate([np.concatenate([ctrl._ix[k]] + ([ctrl._iu[k]] if k < N else []))
                                       for k in range(N + 1)]))
    Gw = ca.vertcat(*Gw_rows)[order.tolist(), :]
    hw = ca.vertcat(*hw_rows)[order.tolist()]
    outs = [ca.densify(v) for v in (H, g, ca.vertcat(*rows), ca.vertcat(*lo), ca.vertcat(*hi), lbx, ubx)]
    outs += [Gw, ca.densify(hw)]
    return ca.Function("nmpc_condensed_qp", [w, P], outs, ["w", "p"], list(OUTPUTS))


#: The C sources of the compiled RTI step (mpc/c), beside the generated stage functions.
RTI_C_SOURCES = ("gt_qp.c", "gt_cond.c", "gt_rti.c")
#: The generated functions mpc/c/gt_cond.c calls (its loop over the stages does the rest).
C_FUNCTIONS = ("gt_cond_point", "gt_cond_terms0", "gt_cond_terms", "gt_cond_termsN", "gt_cond_consts")


def stage_functions(ctrl) -> list[ca.Function]:
    """The pieces of :func:`condensed_qp_function` that mpc/c/gt_cond.c condenses in a loop over
    the stages (named as in :data:`C_FUNCTIONS`): the model's sparse DAE form at one point
    (``(x, u, d) -> (f, f_x, f_z, f_u, g_x)``, the RK4 stages' factors), the terms of stage 0,
    of a middle stage and of stage N (dense Jacobians), and the constants: dimensions, RK4 step
    lengths, state scales, the path rows' bounds, the controls' bounds. Same arithmetic as the
    interpreted function up to the order of the sums (tests/mpc/test_condense.py)."""
    s, m = ctrl.settings, ctrl.model
    nx, nu, nd, nxl, nul, N = ctrl.nx, ctrl.nu, ctrl.nd, ctrl._nxl, ctrl._nul, s.horizon_steps
    if np.any(np.isfinite(ctrl._lbw[np.concatenate(ctrl._ix)])) or np.any(np.isfinite(ctrl._ubw[np.concatenate(ctrl._ix)])):
        raise MpcInputError("Condensing needs unbounded lifted states (bounds on controls only).")
    stride = nxl + nul
    if any(ix[0] != k * stride or iu[0] != k * stride + nxl for k, (ix, iu) in enumerate(zip(ctrl._ix, ctrl._iu))):
        raise MpcInputError("Condensing in C needs the NLP's variables stage by stage ([X~_k; U~_k]).")
    point = _sensitivity_point(m, m.u, "gt_cond")  # named gt_cond_point
    terms = [_terms_function(ctrl, 0, "gt_cond_terms0", True), _terms_function(ctrl, min(1, N), "gt_cond_terms", True),
             _terms_function(ctrl, N, "gt_cond_termsN", True)]
    idx = np.concatenate([ctrl._ig_path[k][(nxl if k == 0 else 0):] for k in range(N + 1)])
    iu = np.concatenate(ctrl._iu)
    h = s.dt_h / int(s.rk4_substeps)
    n_p = nx + nd * N + nu + m.spec.grid.count
    dims = [N, nx, nu, nd, nxl, nul, int(s.rk4_substeps), n_p, ctrl._nw, idx.size, N * nul]
    consts = [dims, [h, 0.5 * h, h / 6.0], ctrl.x_scale, 1.0 / ctrl.x_scale, ctrl._lbg[idx], ctrl._ubg[idx],
              ctrl._lbw[iu], ctrl._ubw[iu]]
    cf = ca.Function("gt_cond_consts", [], [ca.DM(np.asarray(v, float)) for v in consts], [],
                     ["dims", "step", "scale", "inv_scale", "lba", "uba", "lbx", "ubx"])
    return [point, *terms, cf]


class RtiLibrary:
    """The compiled RTI step of mpc/c/gt_rti.c (condensed QP data + Goldfarb-Idnani) loaded
    by ctypes: ``step(w, p) -> (w_next, status, iterations)``, status 0 when the QP solved
    (mpc/c/gt_qp.h names the others). Allocates its C memory once, here."""

    STATUS = {0: "solved", 1: "infeasible", 2: "Hessian not positive definite", 3: "iteration limit",
              4: "dependent equality constraints", 5: "solved with a regularised Hessian",
              6: "QP data not finite (nan or inf in H, g or A)", -1: "QP data evaluation failed"}
    REGULARISED = 5  # solved on H + GT_QP_REG max(diag H) I (mpc/c/gt_qp.h)
    NOT_FINITE = 6  # a nan or an infinity in the QP data: nothing solved
    SOLVED = (0, REGULARISED)

    def __init__(self, path):
        lib = ctypes.CDLL(str(path))
        dp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
        lib.gt_rti_new.restype = ctypes.c_void_p
        lib.gt_rti_free.argtypes = [ctypes.c_void_p]
        lib.gt_rti_sizes.argtypes = [ctypes.c_void_p, ip, ip, ip, ip]
        lib.gt_rti_step.argtypes = [ctypes.c_void_p, dp, dp, dp, ip]
        lib.gt_rti_last_seconds.argtypes = [ctypes.c_void_p, dp, dp]
        self._lib, self._h = lib, lib.gt_rti_new()
        if not self._h:
            raise MpcInputError(f"gt_rti_new failed (out of memory) in {path}.")
        sz = [ctypes.c_int() for _ in range(4)]
        lib.gt_rti_sizes(self._h, *(ctypes.byref(v) for v in sz))
        self.nw, self.np, self.nv, self.m = (v.value for v in sz)
        self._it = ctypes.c_int()
        self._dp = dp

    def step(self, w, p) -> tuple[np.ndarray, int, int]:
        w = np.ascontiguousarray(w, float)
        p = np.ascontiguousarray(p, float)
        if w.size != self.nw or p.size != self.np:
            raise MpcInputError(f"RtiLibrary.step needs w of {self.nw} and p of {self.np} values. "
                                f"Got {w.size} and {p.size}.")
        out = np.empty(self.nw)
        st = self._lib.gt_rti_step(self._h, w.ctypes.data_as(self._dp), p.ctypes.data_as(self._dp),
                                   out.ctypes.data_as(self._dp), ctypes.byref(self._it))
        return out, int(st), int(self._it.value)

    def last_seconds(self) -> tuple[float, float]:
        """Wall time of the last step's QP data and QP solve [s] (measured in C)."""
        a, b = ctypes.c_double(), ctypes.c_double()
        self._lib.gt_rti_last_seconds(self._h, ctypes.byref(a), ctypes.byref(b))
        return a.value, b.value

    def __del__(self):
        if getattr(self, "_h", None):
            self._lib.gt_rti_free(self._h)
            self._h = None
