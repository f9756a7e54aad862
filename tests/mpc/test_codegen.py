"""Compiled controller data: the sparse RK4 sensitivities and the stage-wise QP data against
CasADi's AD of the whole expression, the disk cache, the interpreted fallback, and the compiled
controller's moves against the interpreted one's."""

import casadi as ca
import numpy as np
import pytest

from mpc import Controller, NmpcSettings, rk4_map, rk4_sensitivity_map
from mpc import codegen
from mpc.errors import MpcError, MpcInputError
from mpc.estimator import Ekf
from twin.solve.simulate import step


def test_rk4_sensitivities_equal_ad_of_the_substituted_map(ctrl_twin):
    m = ctrl_twin.model
    sens = rk4_sensitivity_map(m, 0.05, 2, with_d=True)
    F = rk4_map(m.f, 0.05, 2).expand()
    x, u, d = ca.SX.sym("x", m.n_x), ca.SX.sym("u", 2), ca.SX.sym("d", m.d.numel())
    xn = F(x, u, d)
    ref = ca.Function("ref", [x, u, d], [xn, ca.jacobian(xn, x), ca.jacobian(xn, u), ca.jacobian(xn, d)])
    x0 = m.initial_state([0.7, 0.3]) * 1.05
    args = (x0, [27.0, 0.72], m.d_vector([0.7, 0.3], 1.1))
    for a, b in zip(sens(*args), ref(*args)):
        a, b = np.asarray(a), np.asarray(b)
        assert np.max(np.abs(a - b)) <= 1e-11 * max(np.max(np.abs(b)), 1.0)


def test_stagewise_qp_data_equal_ad_of_the_whole_nlp(ctrl_twin):
    """H = 2 Jr^T Jr, the gradient, constraints and their Jacobian, from the stage functions,
    against CasADi's AD of the whole NLP expression (with a power limit and move blocking)."""
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    c = Controller(m, NmpcSettings(horizon_steps=4, dt_h=0.05, solver="rti", move_block=2,
                                   power_max_kw=900.0, codegen="off"))
    rng = np.random.default_rng(0)
    w = np.concatenate([np.r_[ss.x / c.x_scale * (1 + 0.05 * rng.standard_normal(c.nx)), ss.u, [0.01, 0.02]]
                        if i % 2 == 0 else np.r_[ss.u * 1.01, [0.03, 0.01]] for i in range(9)])
    d = np.repeat(m.d_vector([0.8, 0.2], 1.05)[:, None], 4, axis=1)
    p = np.concatenate([ss.x, d.ravel(order="F"), ss.u, c._wpass])
    nlp = c.nlp
    ref = ca.Function("ref", [nlp["x"], nlp["p"]], [ca.jacobian(nlp["r"], nlp["x"]), ca.gradient(nlp["f"], nlp["x"]),
                                                   nlp["g"], ca.jacobian(nlp["g"], nlp["x"])])
    jr, grad, g, a = (np.asarray(ca.densify(v)) for v in ref(w, p))
    got = [np.asarray(ca.densify(v)) for v in c._qp_data(w, p)]
    for x, y in zip(got, [2 * jr.T @ jr, grad, g, a]):
        assert np.max(np.abs(x - y)) <= 1e-10 * max(np.max(np.abs(y)), 1.0)


def test_compiled_function_is_cached_and_equal(tmp_path, monkeypatch):
    if codegen.find_compiler() is None:
        pytest.skip("no C compiler on this machine")
    monkeypatch.setenv(codegen.CACHE_ENV, str(tmp_path))
    x = ca.SX.sym("x", 3)
    fn = ca.Function("cg_test", [x], [ca.sin(x) * ca.sumsqr(x)])
    f1, r1 = codegen.compiled(fn, "on")
    f2, r2 = codegen.compiled(fn, "on")
    assert r1.compiled and not r1.cache_hit and r2.cache_hit and r1.path == r2.path
    assert r1.path.startswith(str(tmp_path))
    v = [0.3, -1.2, 2.0]
    assert np.allclose(np.asarray(f2(v)), np.asarray(fn(v)), rtol=1e-14, atol=0)
    other = ca.Function("cg_test", [x], [ca.cos(x)])
    assert codegen.compiled(other, "on")[1].path != r1.path  # another function, another library


def test_no_compiler_falls_back_reported_and_counted(monkeypatch):
    monkeypatch.setenv("CC", "no-such-compiler-xyz")
    monkeypatch.delenv(codegen.MODE_ENV)  # "auto" as a user has it
    x = ca.SX.sym("x")
    fn = ca.Function("cg_fallback", [x], [2 * x])
    before = sum(codegen.FALLBACKS.values())
    with pytest.warns(codegen.CompileFallbackWarning, match="no C compiler"):
        f, rep = codegen.compiled(fn, "auto")
    assert f is fn and not rep.compiled and "no C compiler" in rep.reason
    assert sum(codegen.FALLBACKS.values()) == before + 1
    with pytest.raises(MpcError, match="no C compiler"):
        codegen.compiled(fn, "on")
    with pytest.raises(MpcInputError, match="mode"):
        codegen.compiled(fn, "sometimes")


def test_an_unwritable_cache_folder_falls_back_reported_not_a_crash(monkeypatch, tmp_path):
    """A cache folder that cannot be made (a file in its place; permissions do not stop root) was an
    OSError from deep in the compile; now the same reported fallback as a missing compiler."""
    (tmp_path / "file").write_text("not a folder")
    monkeypatch.setenv(codegen.CACHE_ENV, str(tmp_path / "file" / "cache"))
    monkeypatch.delenv(codegen.MODE_ENV)
    x = ca.SX.sym("x")
    fn = ca.Function("cg_unwritable", [x], [3 * x])
    before = sum(codegen.FALLBACKS.values())
    with pytest.warns(codegen.CompileFallbackWarning, match="cannot be written.*GRINDTWIN_CACHE_DIR"):
        f, rep = codegen.compiled(fn, "auto")
    assert f is fn and not rep.compiled and str(tmp_path / "file" / "cache") in rep.reason
    assert sum(codegen.FALLBACKS.values()) == before + 1
    with pytest.raises(MpcError, match="cannot be written"):
        codegen.compiled(fn, "on")
    assert (tmp_path / "file").read_text() == "not a folder"


@pytest.mark.slow
def test_compiled_controller_moves_equal_interpreted(ctrl_twin):
    if codegen.find_compiler() is None:
        pytest.skip("no C compiler on this machine")
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    kw = dict(horizon_steps=3, dt_h=0.05, solver="rti", target_p80_um=0.9 * ss.p80_um)
    a, b = Controller(m, NmpcSettings(**kw, codegen="on")), Controller(m, NmpcSettings(**kw, codegen="off"))
    assert a.build_report["qp_data"].compiled and not b.build_report["qp_data"].compiled
    d, ua, ub = m.d_vector([0.6, 0.4]), ss.u, ss.u
    for _ in range(4):
        ra, rb = a.make_step(ss.x, d, ua), b.make_step(ss.x, d, ub)
        assert ra.success and rb.success
        assert np.allclose(ra.u_applied, rb.u_applied, rtol=1e-9, atol=0)
        ua, ub = ra.u_applied, rb.u_applied
    assert abs(ua[0] - ss.u[0]) > 0.1  # it moved towards the finer target


@pytest.mark.slow
def test_condensed_compiled_controller_moves_equal_hpipm(ctrl_twin):
    """The RTI on the condensed QP in compiled C (Goldfarb-Idnani) takes HPIPM's moves on the
    sparse QP (the same QP), step after step, including a power limit and move blocking."""
    if codegen.find_compiler() is None:
        pytest.skip("no C compiler on this machine")
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    kw = dict(horizon_steps=4, dt_h=0.05, solver="rti", move_block=2, target_p80_um=0.9 * ss.p80_um,
              power_max_kw=1.02 * float(m.outputs["power_kw"](ss.x, ss.u, ss.d)))
    a = Controller(m, NmpcSettings(**kw, qpsol="condensed", codegen="on"))
    b = Controller(m, NmpcSettings(**kw, qpsol="hpipm", codegen="off"))
    assert a._rti_c is not None and a.build_report["qp_data"].compiled
    d, u = m.d_vector([0.6, 0.4]), ss.u
    for _ in range(4):
        ra, rb = a.make_step(ss.x, d, u), b.make_step(ss.x, d, u)
        assert ra.success and rb.success
        assert np.allclose(ra.u_applied, rb.u_applied, rtol=1e-7, atol=0)
        u = ra.u_applied
    assert abs(u[0] - ss.u[0]) > 0.1  # it moved towards the finer target


@pytest.mark.parametrize("horizon", [4, 6])
def test_condensed_interpreted_fallback_moves_equal_hpipm(ctrl_twin, horizon):
    """Where nothing may be compiled, the condensed QP is solved interpreted (qpOASES); it takes
    HPIPM's moves on the sparse QP step after step, with a power limit and move blocking. (qrqp
    failed on the positive-definite condensed QP of horizon 6: "Failed to calculate search
    direction".)"""
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    kw = dict(horizon_steps=horizon, dt_h=0.05, solver="rti", move_block=2, target_p80_um=0.9 * ss.p80_um,
              power_max_kw=1.02 * float(m.outputs["power_kw"](ss.x, ss.u, ss.d)), codegen="off")
    a = Controller(m, NmpcSettings(**kw, qpsol="condensed"))
    b = Controller(m, NmpcSettings(**kw, qpsol="hpipm"))
    assert a._rti_c is None and not a.build_report["qp_data"].compiled
    d, u = m.d_vector([0.6, 0.4]), ss.u
    for _ in range(4):
        ra, rb = a.make_step(ss.x, d, u), b.make_step(ss.x, d, u)
        assert ra.success and rb.success, (a.last_info, b.last_info)
        assert np.allclose(ra.u_applied, rb.u_applied, rtol=1e-7, atol=0)
        u = ra.u_applied
    assert abs(u[0] - ss.u[0]) > 0.1  # it moved towards the finer target


def test_p80_bias_model_reads_a_bias_as_a_bias(ctrl_twin):
    """Plant = the model with its P80 analyser reading 15 um high: the p80_bias EKF finds the
    15 um and leaves hardness at 1; the hardness-only EKF reads it as a harder ore."""
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    d = m.d_vector([1.0, 0.0], 1.0)
    ekfs = {k: Ekf(m, 0.05, ss.x, disturbance_model=k, p80_noise_um=1.0) for k in ("hardness", "p80_bias")}
    x = ss.x.copy()
    for _ in range(60):
        x, _, _ = step(m, x, ss.u, d, 0.05)
        y = [float(m.outputs["p80_measured_um"](x, ss.u, d)) + 15.0, float(m.outputs["power_kw"](x, ss.u, d)),
             float(m.outputs["load_frac"](x, ss.u, d))]
        for e in ekfs.values():
            e.make_step(y, ss.u, [1.0, 0.0])
    assert abs(ekfs["p80_bias"].p80_bias_um - 15.0) < 1.5 and ekfs["p80_bias"].hardness_est == 1.0
    assert ekfs["hardness"].hardness_est > 1.05 and ekfs["hardness"].p80_bias_um == 0.0
    with pytest.raises(MpcInputError, match="disturbance_model"):
        Ekf(m, 0.05, ss.x, disturbance_model="bias")
