"""Tests of mpc.linear: linearisation, ZOH, gains, FOPDT fit, linear MPC against LQR."""

import casadi as ca
import control
import numpy as np
import pytest
import scipy.linalg

from mpc.errors import MpcInputError
from mpc.linear import (
    LinearMPC,
    Fopdt,
    discretize,
    fit_fopdt,
    fopdt_from_model,
    gain_table,
    linearize,
    step_moments,
)


def toy_mill():
    """Two-tank toy: hold-up m (t) fed at feed_tph, fines fraction z; speed speeds breakage.

    dm/dt = u0 - m / T_res, dz/dt = (k * u1 * (1 - z) - z * u0 / m) with T_res = 0.5 h.
    """
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u", 2)
    d = ca.SX.sym("d", 1)
    m, z = x[0], x[1]
    xdot = ca.vertcat(u[0] - m / 0.5, d[0] * u[1] * (1 - z) - z * u[0] / m)
    f = ca.Function("f", [x, u, d], [xdot])
    outs = {
        "holdup_t": ca.Function("h", [x, u, d], [m]),
        "passing_target_frac": ca.Function("p", [x, u, d], [1 - z]),
    }
    return f, outs


def toy_steady(u, d):
    m = u[0] * 0.5
    # d u1 (1 - z) = z u0 / m = 2 z
    z = d * u[1] / (d * u[1] + 2.0)
    return np.array([m, z])


def test_linearize_matches_analytic_jacobian_and_finite_difference():
    f, outs = toy_mill()
    u = np.array([30.0, 0.7])
    d = np.array([4.0])
    xs = toy_steady(u, d[0])
    sys, op = linearize(f, outs, xs, u, d, ["holdup_t", "passing_target_frac"])
    m, z = xs
    a_exact = np.array([[-2.0, 0.0], [z * u[0] / m**2, -d[0] * u[1] - u[0] / m]])
    np.testing.assert_allclose(sys.A, a_exact, rtol=1e-12)
    b_exact = np.array([[1.0, 0.0], [-z / m, d[0] * (1 - z)]])
    np.testing.assert_allclose(sys.B, b_exact, rtol=1e-12)
    np.testing.assert_allclose(sys.C, [[1, 0], [0, -1]], rtol=1e-12)
    # DC gain against the exact nonlinear steady-state sensitivity (central difference)
    h = 1e-5
    for j in range(2):
        du = np.zeros(2)
        du[j] = h
        dy = (toy_steady(u + du, d[0]) - toy_steady(u - du, d[0])) / (2 * h)
        dy[1] = -dy[1]
        k = np.asarray(control.dcgain(sys))[:, j]
        np.testing.assert_allclose(k, dy, rtol=1e-6, atol=1e-9)
    assert op.y_ss[1] == pytest.approx(1 - z)


def test_linearize_rejects_non_steady_point_and_unknown_output():
    f, outs = toy_mill()
    with pytest.raises(MpcInputError, match="steady state"):
        linearize(f, outs, [1.0, 0.5], [30, 0.7], [4.0], ["holdup_t"])
    xs = toy_steady([30, 0.7], 4.0)
    with pytest.raises(MpcInputError, match="p80_um"):
        linearize(f, outs, xs, [30, 0.7], [4.0], ["p80_um"])


def test_zoh_discretisation_is_exact_for_piecewise_constant_input():
    a = np.array([[-1.0, 0.3], [0.0, -0.2]])
    b = np.array([[1.0], [0.5]])
    sysc = control.ss(a, b, np.eye(2), np.zeros((2, 1)))
    dt = 0.1
    sysd = discretize(sysc, dt)
    ad_exact = scipy.linalg.expm(a * dt)
    bd_exact = np.linalg.solve(a, (ad_exact - np.eye(2))) @ b
    np.testing.assert_allclose(sysd.A, ad_exact, rtol=1e-12)
    np.testing.assert_allclose(sysd.B, bd_exact, rtol=1e-10)
    assert sysd.dt == dt
    with pytest.raises(MpcInputError, match="dt_h"):
        discretize(sysc, 0.0)


def test_gain_table_first_order_channels():
    # two decoupled first-order channels with known gains and time constants
    sysc = control.ss(np.diag([-1 / 2.0, -1 / 0.25]), np.diag([3.0 / 2.0, -0.5 / 0.25]),
                      np.eye(2), np.zeros((2, 2)), inputs=["feed_tph", "speed_frac_critical"],
                      outputs=["p80_um", "power_kw"])
    tab = gain_table(sysc).set_index(["input", "output"])
    assert tab.loc[("feed_tph", "p80_um"), "gain"] == pytest.approx(3.0, rel=1e-12)
    assert tab.loc[("speed_frac_critical", "power_kw"), "gain"] == pytest.approx(-0.5, rel=1e-12)
    assert tab.loc[("feed_tph", "p80_um"), "tau_dominant_h"] == pytest.approx(2.0, rel=1e-12)
    # t63 of a first-order step is the time constant (grid resolution 6*2/4000 h)
    assert tab.loc[("feed_tph", "p80_um"), "t63_h"] == pytest.approx(2.0, abs=0.004)
    assert tab.loc[("speed_frac_critical", "power_kw"), "t63_h"] == pytest.approx(0.25, abs=0.004)
    assert tab.loc[("feed_tph", "power_kw"), "gain"] == 0.0


def test_fopdt_fit_recovers_exact_fopdt():
    truth = Fopdt(gain=1.8, tau_h=0.7, delay_h=0.15)
    t = np.linspace(0, 6, 601)
    fit = fit_fopdt(t, truth.step(t, du=2.5), du=2.5)
    assert fit.gain == pytest.approx(1.8, rel=1e-6)
    assert fit.tau_h == pytest.approx(0.7, rel=1e-4)
    assert fit.delay_h == pytest.approx(0.15, abs=1e-4)


def test_fopdt_of_second_order_is_between_half_rule_bounds():
    # G = 1/((s+1)(0.2 s+1)): Skogestad's half rule gives tau = 1.1, theta = 0.1
    sysc = control.ss(control.tf([1.0], [0.2, 1.2, 1.0]))
    sysc = control.ss(sysc.A, sysc.B, sysc.C, sysc.D, inputs=["u"], outputs=["y"])
    fit = fopdt_from_model(sysc, "u", "y", t_final_h=8.0)
    assert fit.gain == pytest.approx(1.0, rel=5e-3)
    assert 1.0 <= fit.tau_h <= 1.2
    assert 0.05 <= fit.delay_h <= 0.2
    assert fit.rms_error < 0.02


def _siso(num, den):
    sysc = control.ss(control.tf(num, den))
    return control.ss(sysc.A, sysc.B, sysc.C, sysc.D, inputs=["u"], outputs=["y"])


@pytest.mark.parametrize("num, den, gain, mean_time", [
    ([1.8], [0.7, 1.0], 1.8, 0.7),  # first order: gain K, mean time tau
    ([-2.0], np.polymul([0.7, 1.0], [0.2, 1.0]), -2.0, 0.9),  # lags in series: the times add
    # a + (1 - a)/(tau s + 1), a = 0.3, tau = 1.3: fast and slow in parallel, (1 - a) tau
    ([0.3 * 1.3, 1.0], [1.3, 1.0], 1.0, 0.7 * 1.3),
])
def test_step_moments_are_exact_for_known_systems(num, den, gain, mean_time):
    m = step_moments(_siso(num, den), "u", "y")
    assert m.gain == pytest.approx(gain, rel=1e-12)
    assert m.mean_time_h == pytest.approx(mean_time, rel=1e-12)


def test_step_moments_equal_the_area_over_the_step_response():
    """T is the area between the normalised step response and 1 (an independent quadrature)."""
    sysc = _siso([0.5, 1.0], np.polymul([1.0, 1.0], [0.3, 0.2, 1.0]))
    t = np.linspace(0.0, 40.0, 400001)
    y = np.asarray(control.step_response(sysc, T=t).outputs).ravel()
    m = step_moments(sysc, "u", "y")
    assert m.mean_time_h == pytest.approx(np.trapezoid(1.0 - y / m.gain, t), rel=1e-6)


def test_step_moments_refuse_what_has_no_mean_time():
    with pytest.raises(MpcInputError, match="asymptotically stable"):
        step_moments(_siso([1.0], [1.0, -0.5]), "u", "y")
    with pytest.raises(MpcInputError, match="zero steady gain"):
        step_moments(_siso([1.0, 0.0], [1.0, 1.0]), "u", "y")
    with pytest.raises(MpcInputError, match="input_name"):
        step_moments(_siso([1.0], [1.0, 1.0]), "feed_tph", "y")


def random_system(seed, nx=3, nu=2, rho=1.05):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(nx, nx)) * 0.5
    a = a / np.max(np.abs(np.linalg.eigvals(a))) * rho  # rho > 1: open-loop unstable
    b = rng.normal(size=(nx, nu))
    return control.ss(a, b, np.eye(nx), np.zeros((nx, nu)), dt=0.1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_unconstrained_long_horizon_mpc_matches_dlqr(seed):
    sysd = random_system(seed)
    q = np.diag([1.0, 2.0, 0.5])
    r = np.diag([0.3, 1.0])
    k_lqr, _, _ = control.dlqr(sysd, q, r)
    mpc = LinearMPC(sysd, q, r, horizon=80, terminal="q")
    np.testing.assert_allclose(mpc.unconstrained_gain(), k_lqr, rtol=1e-7, atol=1e-9)
    # and the QP path (no active constraints) gives the same first move
    x0 = np.array([1.0, -0.5, 0.3])
    res = mpc.make_step(x0)
    assert res.success and res.fallback_used is None
    np.testing.assert_allclose(res.u_applied, -k_lqr @ x0, rtol=1e-6, atol=1e-8)


def test_short_horizon_differs_and_dare_terminal_makes_it_exact():
    sysd = random_system(0)
    q, r = np.eye(3), np.eye(2)
    k_lqr, _, _ = control.dlqr(sysd, q, r)
    short = LinearMPC(sysd, q, r, horizon=2, terminal="q").unconstrained_gain()
    assert np.max(np.abs(short - k_lqr)) > 1e-3  # the test can fail: horizon matters
    exact = LinearMPC(sysd, q, r, horizon=2, terminal="dare").unconstrained_gain()
    np.testing.assert_allclose(exact, k_lqr, rtol=1e-9, atol=1e-10)


def test_constrained_mpc_satisfies_input_rate_and_state_bounds():
    # double integrator (position, velocity), dt = 0.1: move from 1 to 0 with
    # |velocity| <= 0.5, |u| <= 1, |du| <= 0.3 per step
    dt = 0.1
    sysd = control.ss([[1.0, dt], [0.0, 1.0]], [[dt**2 / 2], [dt]], np.eye(2), np.zeros((2, 1)),
                      dt=dt)
    q, r = np.diag([100.0, 1.0]), np.array([[0.01]])
    mpc = LinearMPC(sysd, q, r, horizon=30, u_min=-1.0, u_max=1.0, du_max=0.3,
                    x_min=[-np.inf, -0.5], x_max=[np.inf, 0.5])
    x0 = np.array([1.0, 0.0])
    # the unconstrained move would violate the input bound, so constraints are active
    assert np.max(np.abs(mpc.unconstrained_gain() @ x0)) > 1.0
    x = x0.copy()
    u_prev = np.zeros(1)
    vmax, umax = 0.0, 0.0
    for _ in range(120):
        res = mpc.make_step(x)
        assert res.success, res.status
        tol = 1e-8
        assert np.all(np.abs(res.plan) <= 1.0 + tol)
        du = np.diff(np.vstack([u_prev, res.plan]), axis=0)
        assert np.all(np.abs(du) <= 0.3 + tol)
        assert np.all(np.abs(res.states_plan[1:, 1]) <= 0.5 + 1e-7)
        u_prev = res.u_applied
        x = sysd.A @ x + sysd.B @ res.u_applied
        vmax, umax = max(vmax, abs(x[1])), max(umax, abs(res.u_applied[0]))
    assert vmax == pytest.approx(0.5, abs=1e-6)  # the velocity bound was active
    assert umax == pytest.approx(1.0, abs=1e-6)  # and so was the input bound
    assert np.linalg.norm(x) < 1e-3  # and it regulates


def test_infeasible_problem_uses_stated_fallbacks():
    sysd = control.ss([[1.0]], [[1.0]], [[1.0]], [[0.0]], dt=1.0)
    mpc = LinearMPC(sysd, [[1.0]], [[1.0]], horizon=5, u_min=-1, u_max=1, x_min=-3, x_max=3)
    ok = mpc.make_step([2.0])
    assert ok.success and ok.fallback_used is None
    bad = mpc.make_step([10.0])  # cannot be brought back inside |x| <= 3 in one step
    assert not bad.success and bad.fallback_used == "shifted_plan"
    np.testing.assert_allclose(bad.u_applied, ok.plan[1])
    mpc.reset(u_prev=[0.3])
    bad2 = mpc.make_step([10.0])
    assert bad2.fallback_used == "hold_input"
    np.testing.assert_allclose(bad2.u_applied, [0.3])


def test_linear_mpc_input_validation():
    sysd = random_system(0)
    with pytest.raises(MpcInputError, match="horizon"):
        LinearMPC(sysd, np.eye(3), np.eye(2), horizon=0)
    with pytest.raises(MpcInputError, match="'r'"):
        LinearMPC(sysd, np.eye(3), np.zeros((2, 2)), horizon=3)
    with pytest.raises(MpcInputError, match="sys_d"):
        LinearMPC(control.ss(-1, 1, 1, 0), np.eye(1), np.eye(1), horizon=3)
    with pytest.raises(MpcInputError, match="solver"):
        LinearMPC(sysd, np.eye(3), np.eye(2), horizon=3, solver="nope")


def test_results_object_validates_fallback():
    from mpc.results import ControllerStepResult

    r = ControllerStepResult(True, "ok", 1.0, 3, 0.01, [1.0, 0.7])
    assert r.as_row(("feed_tph", "speed_frac_critical"))["feed_tph"] == 1.0
    with pytest.raises(MpcInputError, match="fallback_used"):
        ControllerStepResult(False, "x", 1.0, 3, 0.01, [1.0], fallback_used="magic")
    with pytest.raises(MpcInputError, match="fallback_used"):
        ControllerStepResult(True, "x", 1.0, 3, 0.01, [1.0], fallback_used="hold_input")


def test_le_roux_gain_table_matches_nonlinear_steady_states():
    from mpc.plants.leroux import DISTURBANCE_NAMES, LeRouxCircuit

    c = LeRouxCircuit()
    xs = c.steady_state()
    sys, _ = linearize(c.f, c.outputs, xs, c.u_nominal, c.d_nominal,
                       ["p80_um", "product_tph"], include_disturbances=True,
                       disturbance_names=DISTURBANCE_NAMES)
    tab = gain_table(sys).set_index(["input", "output"])
    for j, name, h in ((0, "feed_tph", 0.2), (1, "speed_frac_critical", 0.002)):
        du = np.zeros(2)
        du[j] = h
        yp = c.evaluate_outputs(c.steady_state(u=c.u_nominal + du, x0=xs), c.u_nominal + du)
        ym = c.evaluate_outputs(c.steady_state(u=c.u_nominal - du, x0=xs), c.u_nominal - du)
        fd = (yp["p80_um"] - ym["p80_um"]) / (2 * h)
        assert tab.loc[(name, "p80_um"), "gain"] == pytest.approx(fd, rel=1e-3)
    # more feed coarsens, faster mill refines, harder ore (phi_f) coarsens
    assert tab.loc[("feed_tph", "p80_um"), "gain"] > 0
    assert tab.loc[("speed_frac_critical", "p80_um"), "gain"] < 0
    assert tab.loc[("phi_f_kwh_t", "p80_um"), "gain"] > 0
    # at steady state every tonne fed leaves as product; speed does not change throughput
    assert tab.loc[("feed_tph", "product_tph"), "gain"] == pytest.approx(1.0, rel=1e-9)
    assert tab.loc[("speed_frac_critical", "product_tph"), "gain"] == 0.0
    # the P80 response is dominated by a ~1.3 h mode (mill and sump fines inventories)
    assert 0.5 < tab.loc[("feed_tph", "p80_um"), "tau_dominant_h"] < 3.0


def test_steady_target_and_linear_mpc_move_le_roux_p80():
    from mpc.plants.leroux import LeRouxCircuit
    from mpc.linear import steady_target

    dt = 0.05
    c = LeRouxCircuit(dt_h=dt)
    xs = c.steady_state()
    sysc, op = linearize(c.f, c.outputs, xs, c.u_nominal, c.d_nominal, ["p80_um", "load_frac"])
    sysd = discretize(sysc, dt)
    # feed only (speed weighted heavily): the target input is -4 um / gain
    xt, ut = steady_target(sysd, {"p80_um": -4.0}, u_weight=np.diag([1.0, 1e10]))
    yt = np.asarray(sysd.C) @ xt + np.asarray(sysd.D) @ ut
    assert yt[0] == pytest.approx(-4.0, abs=1e-9)
    np.testing.assert_allclose(np.asarray(sysd.A) @ xt + np.asarray(sysd.B) @ ut, xt, atol=1e-9)
    gain = float(np.asarray(control.dcgain(sysc))[0, 0])
    assert ut[0] == pytest.approx(-4.0 / gain, rel=1e-3)
    with pytest.raises(MpcInputError, match="y_ref"):
        steady_target(sysd, {"p81_um": 1.0})
    # closed loop on the nonlinear plant, state feedback, bounds and rate limits in force
    cp = np.asarray(sysd.C)[0]
    q = np.outer(cp, cp) + 1e-6 * np.eye(sysd.nstates)
    lo = np.array([30.0, 0.6]) - c.u_nominal
    hi = np.array([90.0, 0.8]) - c.u_nominal
    mpc = LinearMPC(sysd, q, np.diag([1e-3, 1e3]), horizon=20, u_min=lo, u_max=hi,
                    du_max=[1.0, 0.005])
    c.reset(xs)
    u_prev = np.zeros(2)
    for _ in range(60):  # 3 h
        res = mpc.make_step(c.x - xs, x_ref=xt, u_ref=ut)
        assert res.success, res.status
        assert np.all(res.u_applied >= lo - 1e-9) and np.all(res.u_applied <= hi + 1e-9)
        assert np.all(np.abs(res.u_applied - u_prev) <= np.array([1.0, 0.005]) + 1e-9)
        u_prev = res.u_applied
        y = c.make_step(c.u_nominal + res.u_applied)
    # nonlinear plant, no disturbance model: close to, not exactly at, the target
    assert y["p80_um"] - op.y_ss[0] == pytest.approx(-4.0, abs=0.3)


@pytest.mark.parametrize("solver", ["daqp", "osqp"])
def test_other_dense_qp_solvers_agree_with_qpoases(solver):
    import casadi as ca

    if not ca.has_conic(solver):
        pytest.skip(f"{solver} not installed")
    sysd = random_system(3, rho=0.95)
    kw = dict(horizon=15, u_min=-0.3, u_max=0.3, du_max=0.2)
    ref = LinearMPC(sysd, np.eye(3), np.eye(2) * 0.1, **kw).make_step([1.0, -0.8, 0.6])
    other = LinearMPC(sysd, np.eye(3), np.eye(2) * 0.1, solver=solver, **kw).make_step(
        [1.0, -0.8, 0.6])
    assert ref.success and other.success
    np.testing.assert_allclose(other.plan, ref.plan, atol=1e-5)
    assert other.cost == pytest.approx(ref.cost, rel=1e-6)


def test_sparse_ocp_solvers_are_refused_for_the_condensed_qp():
    with pytest.raises(MpcInputError, match="hpipm"):
        LinearMPC(random_system(0), np.eye(3), np.eye(2), horizon=3, solver="hpipm")


def test_reported_cost_is_the_cost_of_the_predicted_trajectory():
    sysd = random_system(5, rho=0.95)
    q, r = np.diag([1.0, 2.0, 3.0]), np.diag([0.5, 0.2])
    mpc = LinearMPC(sysd, q, r, horizon=8, terminal="dare", u_min=-0.2, u_max=0.2)
    x_ref, u_ref = np.array([0.1, 0.0, -0.1]), np.array([0.05, 0.0])
    res = mpc.make_step([1.0, -0.5, 0.5], x_ref=x_ref, u_ref=u_ref)
    assert res.success
    xs, us = res.states_plan, res.plan
    cost = sum((xs[k] - x_ref) @ q @ (xs[k] - x_ref) + (us[k] - u_ref) @ r @ (us[k] - u_ref)
               for k in range(8))
    cost += (xs[8] - x_ref) @ mpc.p @ (xs[8] - x_ref)
    assert res.cost == pytest.approx(cost, rel=1e-9)
    # the predicted states follow the model
    for k in range(8):
        np.testing.assert_allclose(xs[k + 1], sysd.A @ xs[k] + sysd.B @ us[k], atol=1e-12)
