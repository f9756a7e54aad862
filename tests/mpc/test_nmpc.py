from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpc.errors import MpcInputError
from mpc.nmpc import Controller, NmpcSettings

N = 4


@pytest.fixture(scope="module")
def setup(ctrl_twin):
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    ctrl = Controller(m, NmpcSettings(horizon_steps=N, dt_h=0.05, move_block=2,
                                      feed_rate_max_tph_per_h=10.0, speed_rate_max_per_h=0.05))
    return ctrl, ss


def test_settings_errors_name_field_value_allowed():
    with pytest.raises(MpcInputError, match=r"'solver'.*one of.*Got 'cplex'"):
        NmpcSettings(solver="cplex")
    with pytest.raises(MpcInputError, match=r"'horizon_steps'.*int >= 1.*Got 0"):
        NmpcSettings(horizon_steps=0)
    with pytest.raises(MpcInputError, match="move_block"):
        NmpcSettings(horizon_steps=3, move_block=5)
    # accepted before and wrong: "false" switched the preview on, an unknown Hessian, infinities
    for kw, name in (({"preview": "false"}, "preview"), ({"warm_start": "no"}, "warm_start"),
                     ({"hessian": "bogus"}, "hessian"), ({"dt_h": float("inf")}, "dt_h"),
                     ({"target_p80_um": True}, "target_p80_um"), ({"feed_tph_max": float("inf")}, "feed_tph_max")):
        with pytest.raises(MpcInputError, match=f"'{name}'"):
            NmpcSettings(**kw)
    assert NmpcSettings(power_max_kw=float("inf")).power_max_kw == float("inf")  # no limit, as documented
    # a speed in percent blamed speed_min and its default 0.6
    with pytest.raises(MpcInputError, match=r"'speed_max' parameter of NmpcSettings must be in \(0, 1\) \(a fraction "
                                            r"of critical speed, not percent\). Got 85"):
        NmpcSettings(speed_max=85)


def test_bounds_rate_limits_and_blocking_hold(setup):
    ctrl, ss = setup
    ctrl.reset()
    s = ctrl.settings
    d = np.repeat(ctrl.model.d_vector([0.6, 0.4])[:, None], N, axis=1)  # coarsening ore ahead
    u_prev = ss.u
    for _ in range(3):
        r = ctrl.make_step(ss.x, d, u_prev)
        assert r.success, r.status
        assert r.iterations > 0
        plan = r.plan
        assert np.all(plan[:, 0] >= s.feed_tph_min - 1e-6) and np.all(plan[:, 0] <= s.feed_tph_max + 1e-6)
        assert np.all(plan[:, 1] >= s.speed_min - 1e-6) and np.all(plan[:, 1] <= s.speed_max + 1e-6)
        moves = np.diff(np.vstack([u_prev, plan]), axis=0)
        assert np.all(np.abs(moves[:, 0]) <= s.feed_rate_max_tph_per_h * s.dt_h + 1e-6)
        assert np.all(np.abs(moves[:, 1]) <= s.speed_rate_max_per_h * s.dt_h + 1e-6)
        np.testing.assert_allclose(plan[1], plan[0], atol=1e-7)  # move blocking: block of 2
        # the applied move within the limits exactly (IPOPT's moves exceeded them by 1e-8: its tolerance)
        du_max = np.array([s.feed_rate_max_tph_per_h, s.speed_rate_max_per_h]) * s.dt_h
        assert np.all(np.abs(r.u_applied - u_prev) <= du_max)
        u_prev = r.u_applied
    over = ss.u + np.array([s.feed_rate_max_tph_per_h, s.speed_rate_max_per_h]) * s.dt_h * (1 + 1e-7)
    assert np.array_equal(ctrl._within_rates(over, ss.u),
                          ss.u + np.array([s.feed_rate_max_tph_per_h, s.speed_rate_max_per_h]) * s.dt_h)
    # the model is off target at this point (P80 ~198 um on B): the controller acts
    assert np.abs(u_prev - ss.u).max() > 1e-3


def test_forced_solver_failure_shifted_plan_then_hold(setup):
    ctrl, ss = setup
    ctrl.reset()
    d = ctrl.model.d_vector([1.0, 0.0])
    good = ctrl.make_step(ss.x, d, ss.u)
    assert good.success and good.fallback_used is None
    solver = ctrl._solver

    def broken(**kwargs):
        raise RuntimeError("forced failure")

    ctrl._solver = broken
    try:
        u_prev = good.u_applied
        used = []
        for k in range(N + 1):
            r = ctrl.make_step(ss.x, d, u_prev)
            assert not r.success and "forced failure" in r.status
            used.append(r.fallback_used)
            if r.fallback_used == "shifted_plan":
                np.testing.assert_allclose(r.u_applied, good.plan[k + 1], atol=1e-9)
            u_prev = r.u_applied
        assert used[: N - 1] == ["shifted_plan"] * (N - 1)
        assert used[N - 1:] == ["hold_input"] * 2
        np.testing.assert_allclose(r.u_applied, u_prev)
    finally:
        ctrl._solver = solver
    r = ctrl.make_step(ss.x, d, u_prev)
    assert r.success and r.fallback_used is None


def test_a_step_after_missed_samples_moves_the_plan_on_by_them(setup):
    """A served controller that missed samples (an outage) passes them: its failed step applied the plan shifted by
    one, a move of a plan older than the horizon where the rule is to hold the input."""
    ctrl, ss = setup
    d = ctrl.model.d_vector([0.6, 0.4])
    solver = ctrl._solver

    def broken(**kwargs):
        raise RuntimeError("forced failure")

    for samples, fallback in ((2, "shifted_plan"), (N, "hold_input")):
        ctrl.reset()
        good = ctrl.make_step(ss.x, d, ss.u)
        assert good.success
        ctrl._solver = broken
        try:
            r = ctrl.make_step(ss.x, d, good.u_applied, samples=samples)
        finally:
            ctrl._solver = solver
        assert r.fallback_used == fallback
        expected = good.plan[samples] if fallback == "shifted_plan" else good.u_applied
        np.testing.assert_allclose(r.u_applied, expected, atol=1e-9)
        np.testing.assert_allclose(r.plan[0], expected, atol=1e-9)
    with pytest.raises(MpcInputError, match=r"'samples' parameter must be an int >= 1.*Got 0"):
        ctrl.make_step(ss.x, d, ss.u, samples=0)


@pytest.mark.parametrize("solver", ["ipopt", "rti"])
def test_max_iter_zero_fails_to_hold_input(ctrl_twin, solver):
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    ctrl = Controller(ctrl_twin.model, NmpcSettings(horizon_steps=2, dt_h=0.05, max_iter=0,
                                                    solver=solver))
    r = ctrl.make_step(ss.x, ctrl_twin.model.d_vector([0.6, 0.4]), ss.u)
    assert not r.success and r.fallback_used == "hold_input"
    np.testing.assert_allclose(r.u_applied, ss.u)
    assert "Maximum_Iterations" in r.status


def test_an_applied_input_outside_the_bounds_is_planned_from_its_projection(setup):
    """After a manual period at 50 t/h (bounds 20-45, 0.5 t/h per sample) no first move met both
    the bounds and the rate limit: the QP was infeasible on every sample and the input held at
    50 for ever. Now planned from the projection onto the bounds, and said in the status."""
    ctrl, ss = setup
    ctrl.reset()
    s = ctrl.settings
    r = ctrl.make_step(ss.x, ctrl.model.d_vector([1.0, 0.0]), np.array([50.0, 0.70]))
    assert r.success and "input_outside_bounds" in r.status and "[50.0, 0.7]" in r.status
    assert s.feed_tph_max - s.feed_rate_max_tph_per_h * s.dt_h - 1e-6 <= r.u_applied[0] <= s.feed_tph_max + 1e-6
    r = ctrl.make_step(ss.x, ctrl.model.d_vector([1.0, 0.0]), r.u_applied)
    assert r.success and "input_outside_bounds" not in r.status


def test_a_preview_that_is_no_blend_is_refused(setup):
    """Blend [5, -4] and hardness -1 were planned on (a predicted P80 of -999784 um, reported only
    as target_unreachable)."""
    ctrl, ss = setup
    ctrl.reset()
    for d in (ctrl.model.d_vector([5.0, -4.0]), ctrl.model.d_vector([1.0, 0.0], -1.0)):
        with pytest.raises(MpcInputError, match="'d_preview'.*blend fractions in \\[0, 1\\]"):
            ctrl.make_step(ss.x, d, ss.u)


def test_unreachable_target_is_reported(setup):
    ctrl, ss = setup
    ctrl.reset()
    ctrl.set_target(40.0)  # far finer than any input in bounds can grind
    try:
        r = ctrl.make_step(ss.x, ctrl.model.d_vector([1.0, 0.0]), ss.u)
        assert r.status.startswith("target_unreachable")
    finally:
        ctrl.set_target(210.0)


def test_set_target_refuses_a_size_outside_the_grid_and_changes_nothing(setup):
    """set_target(True) raised after setting the target to 1.0 (the weights the old target's); "210" raised
    numpy's TypeError; 5 um and 1e7 um were taken (every passing weight 0 or 1: a P80 term the plan
    cannot move)."""
    ctrl, _ = setup
    grid = ctrl.model.spec.grid
    before = (ctrl.settings.target_p80_um, ctrl._wpass.copy())
    for bad in (True, "210", 5.0, 1e7, float("nan"), float(grid.upper_um[0])):
        with pytest.raises(MpcInputError, match="inside the controller's size grid"):
            ctrl.set_target(bad)
        assert ctrl.settings.target_p80_um == before[0] and np.array_equal(ctrl._wpass, before[1])
    assert float(grid.upper_um[-1]) < 40.0  # test_unreachable_target_is_reported's target is in the grid
    ctrl.set_target(np.array(before[0]))  # a 0-d array, as numpy hands a number back, is a number
    assert ctrl.settings.target_p80_um == before[0] and np.array_equal(ctrl._wpass, before[1])


def test_hpipm_solves_a_qp_whose_hessian_is_semidefinite_only_to_rounding(ctrl_twin):
    """The RTI's Gauss-Newton Hessian 2 Jr'Jr is positive semi-definite only to rounding. On this
    QP (the second step of test_codegen's HPIPM-equivalence test, with a calibration refitted to
    round-off) HPIPM's robust mode with its own primal regularisation stalled at iter_max, cost
    75.9 against 1.955. With the controller's options it solves it, as qpOASES does."""
    z = np.load(Path(__file__).parent / "data" / "hpipm_semidefinite_qp.npz")
    H, A = (ca.DM(ca.Sparsity.triplet(*map(int, z[f"{k}_shape"]), z[f"{k}_row"], z[f"{k}_col"]), z[f"{k}_val"])
            for k in ("h", "a"))
    assert np.linalg.eigvalsh(H.full()).min() < 0  # the case: semi-definite to rounding
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    c = Controller(m, NmpcSettings(horizon_steps=4, dt_h=0.05, solver="rti", move_block=2, qpsol="hpipm",
                                   power_max_kw=1.02 * float(m.outputs["power_kw"](ss.x, ss.u, ss.d)),
                                   codegen="off"))
    assert c._dims == {"N": int(z["dims_N"]), **{k: z[f"dims_{k}"].tolist() for k in ("nx", "nu", "ng")}}
    args = dict(h=H, g=z["g"], a=A, lba=z["lba"], uba=z["uba"], lbx=z["lbx"], ubx=z["ubx"])
    hp = ca.conic("hp", "hpipm", {"h": H.sparsity(), "a": A.sparsity()}, c._qp_options())
    qo = ca.conic("qo", "qpoases", {"h": H.sparsity(), "a": A.sparsity()}, {"printLevel": "none"})
    a, b = hp(**args), qo(**args)
    assert hp.stats()["success"] and hp.stats()["iter_count"] < 20
    assert float(a["cost"]) == pytest.approx(float(b["cost"]), rel=1e-6)
    assert np.allclose(a["x"].full(), b["x"].full(), rtol=0, atol=1e-6)


def test_sqpmethod_with_hpipm_is_refused_clearly():
    with pytest.raises(MpcInputError, match=r"'qpsol'.*'qrqp' with solver 'sqpmethod'.*Got 'hpipm'"):
        NmpcSettings(solver="sqpmethod", qpsol="hpipm")
    assert NmpcSettings(solver="sqpmethod").qpsol == "qrqp"
    assert NmpcSettings(solver="rti").qpsol == "hpipm"


@pytest.fixture(scope="module")
def ipopt_reference(setup):
    """IPOPT's converged plan for a coarsening ore ahead (the other solvers must find it)."""
    ctrl, ss = setup
    ctrl.reset()
    d = np.repeat(ctrl.model.d_vector([0.6, 0.4])[:, None], N, axis=1)
    r = ctrl.make_step(ss.x, d, ss.u)
    assert r.success, r.status
    return d, r


@pytest.mark.parametrize("solver, qpsol, iterations", [
    ("fatrop", None, 1), ("sqpmethod", "qrqp", 1), ("rti", "hpipm", 30), ("rti", "osqp", 30)])
def test_structured_solvers_reach_the_ipopt_solution(ctrl_twin, setup, ipopt_reference,
                                                     solver, qpsol, iterations):
    """Same NLP, same optimum: fatrop and SQP converge to it; Gauss-Newton iterations (RTI run
    to convergence) reach it too, since a full-step fixed point of the QP is a KKT point of the
    NLP (only the Hessian is approximated)."""
    ctrl, ss = setup
    d, ref = ipopt_reference
    s = ctrl.settings
    other = Controller(ctrl_twin.model, NmpcSettings(
        horizon_steps=N, dt_h=0.05, move_block=2, feed_rate_max_tph_per_h=10.0,
        speed_rate_max_per_h=0.05, solver=solver, qpsol=qpsol, rti_iterations=iterations,
        tol=1e-9 if solver == "rti" else s.tol))
    r = other.make_step(ss.x, d, ss.u)
    assert r.success, r.status
    np.testing.assert_allclose(r.plan[:, 0], ref.plan[:, 0], rtol=0, atol=2e-3)  # t/h
    np.testing.assert_allclose(r.plan[:, 1], ref.plan[:, 1], rtol=0, atol=2e-5)  # of critical
    assert r.cost == pytest.approx(ref.cost, rel=1e-5)


def test_real_time_iteration_respects_bounds_rates_and_blocking(ctrl_twin, setup):
    """One QP per sample (the real-time iteration) keeps every hard constraint of the plan."""
    _, ss = setup
    ctrl = Controller(ctrl_twin.model, NmpcSettings(
        horizon_steps=N, dt_h=0.05, move_block=2, feed_rate_max_tph_per_h=10.0,
        speed_rate_max_per_h=0.05, solver="rti"))
    s = ctrl.settings
    d = np.repeat(ctrl.model.d_vector([0.6, 0.4])[:, None], N, axis=1)
    u_prev = ss.u
    for _ in range(3):
        r = ctrl.make_step(ss.x, d, u_prev)
        assert r.success and r.iterations == 1, r.status
        moves = np.diff(np.vstack([u_prev, r.plan]), axis=0)
        assert np.all(np.abs(moves[:, 0]) <= s.feed_rate_max_tph_per_h * s.dt_h + 1e-6)
        assert np.all(np.abs(moves[:, 1]) <= s.speed_rate_max_per_h * s.dt_h + 1e-6)
        assert np.all(r.plan[:, 1] >= s.speed_min - 1e-6) and np.all(r.plan[:, 1] <= s.speed_max + 1e-6)
        np.testing.assert_allclose(r.plan[1], r.plan[0], atol=1e-7)
        u_prev = r.u_applied


def test_a_speed_bound_where_the_charge_centrifuges_is_noted_with_key_value_and_limit():
    """Up to the limit no note; beyond it one naming the key given, the value and the limit."""
    from mpc.nmpc import speed_max_note
    from twin import CENTRIFUGING_FRAC_CRITICAL as LIMIT

    assert speed_max_note(NmpcSettings(speed_max=LIMIT)) is None
    note = speed_max_note(NmpcSettings(speed_max=0.99), "controller.bounds.speed_max")
    assert note.startswith("controller.bounds.speed_max = 0.99: ") and f"beyond {LIMIT} " in note
    assert speed_max_note(NmpcSettings(speed_max=0.99)).startswith("speed_max = 0.99: ")


@pytest.mark.parametrize(("qpsol", "codegen"), [("hpipm", "off"), ("condensed", "off"), ("condensed", "on")])
def test_a_prediction_that_overflows_is_reported_as_qp_data_not_finite(ctrl_twin, qpsol, codegen):
    """A state estimate far outside the model (a diverged estimator's: here 1e150 times the
    steady hold-up, finite) overflows the RK4 prediction, and nan enters the Gauss-Newton QP's
    data. The step fails as "QP data not finite", checked before the QP solver, whichever it is:
    the compiled one had reported "Hessian not positive definite" (its Cholesky failed on the nan;
    a Gauss-Newton Hessian 2 Jr' Jr is never indefinite) and the others their own failures. The
    steady state itself solves."""
    from mpc import codegen as cg

    if codegen == "on" and cg.find_compiler() is None:
        pytest.skip("no C compiler on this machine")
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    ctrl = Controller(ctrl_twin.model, NmpcSettings(horizon_steps=N, dt_h=0.05, solver="rti", qpsol=qpsol,
                                                    codegen=codegen))
    d = ctrl_twin.model.d_vector([1.0, 0.0])
    assert ctrl.make_step(ss.x, d, ss.u).success
    ctrl.reset()
    r = ctrl.make_step(ss.x * 1e150, d, ss.u)
    assert not r.success and r.status == "rti QP failed: QP data not finite (nan or inf in H, g or A)"


def test_a_preview_of_rounded_fractions_is_planned_on_rescaled_to_sum_to_one(setup):
    """A preview of [0.6004, 0.4] (within the twin's tolerance of two ores) was planned on as it was, 0.04 % more
    feed in its components than fed; now it is rescaled to sum to 1 as the twin rescales a blend, and a slip of
    [0.6, 0.397] is refused as the twin refuses it."""
    ctrl, _ = setup
    rounded = np.vstack([np.tile([[0.6004], [0.4]], (1, N)), np.full((1, N), 1.0)])
    d = ctrl._d_traj(rounded)
    assert np.allclose(d[:2].sum(axis=0), 1.0, rtol=0, atol=1e-15)
    assert np.allclose(d[:2, 0], np.array([0.6004, 0.4]) / 1.0004, rtol=1e-15) and np.all(d[2] == 1.0)
    with pytest.raises(MpcInputError, match="summing to 1 \\(within 0.001\\)"):
        ctrl._d_traj(np.vstack([np.tile([[0.6], [0.397]], (1, N)), np.full((1, N), 1.0)]))
