"""The condensed QP (mpc.condense) against the sparse QP it condenses, and the Goldfarb-Idnani
solver (mpc/c/gt_qp.c) against the KKT conditions and against qpOASES."""

import ctypes
import subprocess

import casadi as ca
import numpy as np
import pytest

from mpc import Controller, NmpcSettings, codegen
from mpc.condense import OUTPUTS, RTI_C_SOURCES, condensed_qp_function, stage_functions
from mpc.errors import MpcInputError


def _perturbed_point(c, ss, rng):
    w = c._initial_guess(ss.x / c.x_scale, ss.u)[0]
    return w * (1 + 0.02 * rng.standard_normal(w.size))


@pytest.mark.parametrize("kw", [dict(horizon_steps=4, move_block=2, power_max_kw=900.0), dict(horizon_steps=6)])
def test_condensed_step_equals_the_sparse_qp_step(ctrl_twin, kw):
    """dw = Gw dV + hw from the dense QP (qpOASES) equals the sparse QP's step (qrqp), at a point
    with gaps (a perturbed warm start) and the initial state off the point. qrqp on the dense QP
    fails at horizon 6 ("Failed to calculate search direction", H positive definite)."""
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    c = Controller(m, NmpcSettings(dt_h=0.05, solver="rti", qpsol="qrqp", codegen="off", **kw))
    N = c.settings.horizon_steps
    w = _perturbed_point(c, ss, np.random.default_rng(0))
    d = np.repeat(m.d_vector([0.8, 0.2], 1.05)[:, None], N, axis=1)
    p = np.concatenate([ss.x * 1.01, d.ravel(order="F"), ss.u, c._wpass])
    H, grad, g, A = c._qp_data(w, p)
    g = np.asarray(g).ravel()
    ref = c._qp(h=H, g=grad, a=A, lba=c._lbg - g, uba=c._ubg - g, lbx=c._lbw - w, ubx=c._ubw - w)
    assert c._qp.stats()["success"]
    dw_ref = np.asarray(ref["x"]).ravel()
    f = condensed_qp_function(c)
    out = dict(zip(f.name_out(), f(w, p)))
    n = out["H"].shape[0]
    assert n == N * c._nul  # inputs and slacks only
    qp = ca.conic("dense", "qpoases", {"h": ca.Sparsity.dense(n, n), "a": out["A"].sparsity()},
                  {"printLevel": "none"})
    sol = qp(h=out["H"], g=out["g"], a=out["A"], lba=out["lba"], uba=out["uba"], lbx=out["lbx"], ubx=out["ubx"])
    dw = np.asarray(ca.mtimes(out["Gw"], sol["x"]) + out["hw"]).ravel()
    assert np.max(np.abs(dw - dw_ref)) <= 1e-9 * max(1.0, np.max(np.abs(dw_ref)))
    assert np.max(np.abs(dw_ref)) > 1e-2  # a real step: the test can fail


@pytest.mark.slow
@pytest.mark.parametrize("kw", [dict(horizon_steps=4, move_block=2, power_max_kw=900.0), dict(horizon_steps=1)])
def test_c_condensing_loop_equals_the_interpreted_condensed_qp(ctrl_twin, kw, tmp_path, monkeypatch):
    """mpc/c/gt_cond.c (the loop over the stages on the generated stage functions) gives the QP
    data of condensed_qp_function (CasADi's virtual machine), entry by entry, and its step
    w + Gw dV + hw for a given dV; with a power limit and move blocking, and at horizon 1 (no
    middle stage)."""
    if codegen.find_compiler() is None:
        pytest.skip("no C compiler on this machine")
    monkeypatch.setenv(codegen.CACHE_ENV, str(tmp_path))
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    c = Controller(m, NmpcSettings(dt_h=0.05, solver="rti", qpsol="condensed", codegen="off", **kw))
    N = c.settings.horizon_steps
    rng = np.random.default_rng(1)
    w = _perturbed_point(c, ss, rng)
    d = np.repeat(m.d_vector([0.8, 0.2], 1.05)[:, None], N, axis=1)
    p = np.concatenate([ss.x * 1.01, d.ravel(order="F"), ss.u, c._wpass])
    ref = dict(zip(OUTPUTS, (np.asarray(ca.densify(v)) for v in condensed_qp_function(c)(w, p))))
    path, rep = codegen.c_library("gt_rti", stage_functions(c), list(RTI_C_SOURCES), "on")
    so = ctypes.CDLL(str(path))
    so.gt_cond_bytes.restype, so.gt_cond_init.restype = ctypes.c_long, ctypes.c_void_p
    so.gt_cond_init.argtypes = [ctypes.c_void_p]
    so.gt_cond_eval.argtypes = [ctypes.c_void_p] + [ctypes.POINTER(ctypes.c_double)] * 9
    so.gt_cond_expand.argtypes = [ctypes.c_void_p] + [ctypes.POINTER(ctypes.c_double)] * 3
    mem = np.zeros(so.gt_cond_bytes() // 8 + 1)  # 8-byte aligned, zeroed
    h = so.gt_cond_init(mem.ctypes.data)
    assert h
    nv, mrows = ref["H"].shape[0], ref["A"].shape[0]
    got = {k: np.zeros(v.shape, order="F") for k, v in ref.items() if k not in ("Gw", "hw")}

    def ptr(a):
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
    assert so.gt_cond_eval(h, ptr(w), ptr(p), *(ptr(got[k]) for k in OUTPUTS[:7])) == 0
    for k, v in got.items():
        fin = np.isfinite(ref[k])
        assert np.array_equal(fin, np.isfinite(v)), k
        assert np.max(np.abs(v[fin] - ref[k][fin]), initial=0.0) <= 1e-11 * max(1.0, np.max(np.abs(ref[k][fin]))), k
    dv = rng.standard_normal(nv)
    w_out = np.zeros_like(w)
    so.gt_cond_expand(h, ptr(w), ptr(dv), ptr(w_out))
    dw = ref["Gw"] @ dv + ref["hw"].ravel()
    assert np.max(np.abs(w_out - w - dw)) <= 1e-11 * max(1.0, np.max(np.abs(dw)))
    assert nv == N * c._nul and mrows > 0 and np.max(np.abs(ref["H"])) > 0  # a real QP: the test can fail


def test_condensed_needs_strict_convexity():
    with pytest.raises(MpcInputError, match="weight_du_speed"):
        NmpcSettings(solver="rti", qpsol="condensed", weight_du_speed=0.0)
    with pytest.raises(MpcInputError, match="only with solver 'rti'"):
        NmpcSettings(solver="ipopt", qpsol="condensed")


@pytest.fixture(scope="module")
def gi(tmp_path_factory):
    cc = codegen.find_compiler()
    if cc is None:
        pytest.skip("no C compiler on this machine")
    lib = tmp_path_factory.mktemp("gtqp") / "libgtqp.so"
    subprocess.run([cc, "-O2", "-shared", "-fPIC", str(codegen.C_DIR / "gt_qp.c"), "-o", str(lib), "-lm"], check=True)
    so = ctypes.CDLL(str(lib))
    so.gt_qp_work_size.restype = so.gt_qp_iwork_size.restype = ctypes.c_long
    dp = ctypes.POINTER(ctypes.c_double)

    def solve(H, g, A, lba, uba, lbx, ubx):
        n, m = len(g), A.shape[0]
        work = np.zeros(so.gt_qp_work_size(n, m))
        iwork = np.zeros(so.gt_qp_iwork_size(n, m), dtype=np.int32)
        x, lam, it = np.zeros(n), np.zeros(n + m), ctypes.c_int()
        arrs = [np.asfortranarray(a, dtype=float) for a in (H, g, A, lba, uba, lbx, ubx)]
        st = so.gt_qp_solve(n, m, *[a.ctypes.data_as(dp) for a in arrs], x.ctypes.data_as(dp),
                            lam.ctypes.data_as(dp), ctypes.byref(it), 1000, work.ctypes.data_as(dp),
                            iwork.ctypes.data_as(ctypes.POINTER(ctypes.c_int)))
        return st, x, lam
    return solve


def _random_qp(rng, n, m):
    M = rng.standard_normal((n + 3, n))
    H = M.T @ M + 0.05 * np.eye(n)
    A = rng.standard_normal((m, n))
    lba, uba = -rng.random(m) - 0.05, rng.random(m) + 0.05
    lbx, ubx = -rng.random(n) - 0.05, rng.random(n) + 0.05
    uba[rng.random(m) < 0.2] = np.inf
    lbx[rng.random(n) < 0.2] = -np.inf
    eq = np.flatnonzero(rng.random(m) < 0.15)[: max(n // 3, 1)]
    lba[eq] = uba[eq] = 0.02 * rng.standard_normal(eq.size)
    return H, 5 * rng.standard_normal(n), A, lba, uba, lbx, ubx


def test_goldfarb_idnani_meets_the_kkt_conditions_and_agrees_with_qpoases(gi):
    rng = np.random.default_rng(3)
    for _ in range(60):
        n, m = int(rng.integers(2, 20)), int(rng.integers(1, 25))
        H, g, A, lba, uba, lbx, ubx = _random_qp(rng, n, m)
        st, x, lam = gi(H, g, A, lba, uba, lbx, ubx)
        ref = ca.conic("ref", "qpoases", {"h": ca.Sparsity.dense(n, n), "a": ca.Sparsity.dense(m, n)},
                       {"printLevel": "none", "error_on_fail": False})
        r = ref(h=H, g=g, a=A, lba=lba, uba=uba, lbx=lbx, ubx=ubx)
        if not ref.stats()["success"]:
            assert st == 1  # both find it infeasible
            continue
        assert st == 0
        lx, la = lam[:n], lam[n:]
        ax = A @ x
        tol = 1e-8 * (1 + np.max(np.abs(g)))
        assert np.max(np.abs(H @ x + g - A.T @ la - lx)) <= tol  # stationarity
        assert np.all(ax >= lba - 1e-9) and np.all(ax <= uba + 1e-9)  # primal feasibility
        assert np.all(x >= lbx - 1e-9) and np.all(x <= ubx + 1e-9)
        for lv, v, lo, hi in ((la, ax, lba, uba), (lx, x, lbx, ubx)):  # signs and complementarity
            assert np.all((lv <= 1e-9) | (np.abs(v - lo) <= 1e-8))
            assert np.all((lv >= -1e-9) | (np.abs(v - hi) <= 1e-8))
        assert np.max(np.abs(x - np.asarray(r["x"]).ravel())) <= 1e-7 * (1 + np.max(np.abs(x)))


def test_goldfarb_idnani_reports_infeasible_and_nonconvex(gi):
    H, g = np.eye(2), np.zeros(2)
    A = np.array([[1.0, 0.0], [1.0, 0.0]])
    st, _, _ = gi(H, g, A, np.array([1.0, -np.inf]), np.array([np.inf, 0.0]), -np.ones(2) * 5, np.ones(2) * 5)
    assert st == 1  # x0 >= 1 and x0 <= 0
    st, _, _ = gi(np.diag([1.0, -1.0]), g, np.zeros((0, 2)), np.zeros(0), np.zeros(0), -np.ones(2), np.ones(2))
    assert st == 2
    # semi-definite (exactly singular): solved on H + 1e-10 max(diag H) I, and said so
    st, x, _ = gi(np.ones((2, 2)), np.array([-1.0, -1.0]), np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                  -np.ones(2), np.ones(2))
    assert st == 5 and x[0] + x[1] == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("where", ["H", "g", "A", "lba", "ubx"])
def test_goldfarb_idnani_reports_qp_data_that_is_not_finite_as_such(gi, where):
    """A nan in the data (the prediction of an NMPC overflowed on a diverged state estimate) is
    status 6, not a Hessian that is not positive definite (2: a nan failed the Cholesky as an
    indefinite H would) nor a solution (0: a nan in g passed the Cholesky and gave a nan x); the
    same QP with an infinite bound (absent) solves."""
    data = dict(H=np.eye(2), g=np.array([1.0, -1.0]), A=np.array([[1.0, 1.0]]), lba=np.array([-1.0]),
                uba=np.array([np.inf]), lbx=-np.ones(2), ubx=np.ones(2))
    st, x, _ = gi(**data)
    assert st == 0 and np.all(np.isfinite(x))
    bad = {k: v.copy() for k, v in data.items()}
    bad[where].flat[0] = np.nan
    st, _, _ = gi(**bad)
    assert st == 6
    if where != "lba":
        bad[where].flat[0] = np.inf
        st, _, _ = gi(**bad)
        assert st == (0 if where == "ubx" else 6)
