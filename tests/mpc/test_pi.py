"""Tests of mpc.pi: SIMC numbers, zero offset on a FOPDT plant, anti-windup, le Roux loop."""

import numpy as np
import pytest

from mpc.errors import MpcInputError
from mpc.linear import Fopdt
from mpc.pi import DiscretePI, pi_from_model, simc_pi


class FopdtPlant:
    """Exact ZOH discretisation of k exp(-theta s)/(tau s + 1), delay a whole number of samples."""

    def __init__(self, model: Fopdt, dt_h: float, y0: float, u0: float):
        self.m, self.dt = model, dt_h
        self.a = np.exp(-dt_h / model.tau_h)
        self.nd = int(round(model.delay_h / dt_h))
        self.buf = [u0] * (self.nd + 1)
        self.y0, self.u0 = y0, u0
        self.dev = 0.0

    def step(self, u, load=0.0):
        self.buf.append(u)
        ud = self.buf.pop(0)
        self.dev = self.a * self.dev + self.m.gain * (1 - self.a) * (ud + load - self.u0)
        return self.y0 + self.dev


MODEL = Fopdt(gain=1.6, tau_h=1.3, delay_h=0.25)  # um per t/h, like the le Roux feed->P80 loop


def test_simc_numbers_against_hand_calculation():
    kc, ti = simc_pi(Fopdt(2.0, 1.5, 0.25))  # tau_c = theta = 0.25
    assert kc == pytest.approx(1.5 / (2.0 * 0.5))
    assert ti == pytest.approx(1.5)
    kc, ti = simc_pi(Fopdt(2.0, 8.0, 0.25), tau_c_h=0.5)  # lag dominant: Ti = 4 (tau_c+theta)
    assert kc == pytest.approx(8.0 / (2.0 * 0.75))
    assert ti == pytest.approx(3.0)
    with pytest.raises(MpcInputError, match="tau_c_h"):
        simc_pi(Fopdt(2.0, 1.5, 0.0))


def run_loop(pi, plant, y0, n, setpoint_fn=None, load_fn=None):
    y, ys, us, integrals = y0, [], [], []
    for k in range(n):
        if setpoint_fn is not None:
            pi.setpoint = setpoint_fn(k)
        u = pi.make_step(y)
        y = plant.step(u, 0.0 if load_fn is None else load_fn(k))
        ys.append(y)
        us.append(u)
        integrals.append(pi.integral)
    return np.array(ys), np.array(us), np.array(integrals)


def test_closed_loop_reaches_setpoint_with_zero_offset_and_rejects_load():
    dt = 0.05
    plant = FopdtPlant(MODEL, dt, y0=94.0, u0=65.0)
    pi = DiscretePI.from_fopdt(MODEL, dt, setpoint=100.0, u_bias=65.0, u_min=40, u_max=90,
                               du_max=2.0)
    # set point +6 um at t=0, then a feed-equivalent load of -3 t/h from t = 10 h
    ys, us, _ = run_loop(pi, plant, 94.0, 400, load_fn=lambda k: -3.0 if k >= 200 else 0.0)
    assert ys[199] == pytest.approx(100.0, abs=1e-3)  # zero offset after the set-point step
    assert ys[-1] == pytest.approx(100.0, abs=1e-3)  # and after the load step
    assert us[-1] == pytest.approx(65.0 + 6.0 / 1.6 + 3.0, abs=1e-3)  # integral did the work
    assert np.max(np.abs(np.diff(us))) <= 2.0 + 1e-12  # rate limit held
    # SIMC with tau_c = theta: overshoot is modest (< 15 %)
    assert np.max(ys[:200]) < 100.0 + 0.15 * 6.0


def windup_case(anti_windup):
    dt = 0.05
    plant = FopdtPlant(MODEL, dt, y0=94.0, u0=65.0)
    pi = DiscretePI.from_fopdt(MODEL, dt, setpoint=94.0, u_bias=65.0, u_min=40.0, u_max=70.0,
                               anti_windup=anti_windup)
    # unreachable set point for 5 h (needs 65 + 30/1.6 = 84 t/h > 70), then back to 96 um
    sp = lambda k: 124.0 if k < 100 else 96.0
    ys, us, integ = run_loop(pi, plant, 94.0, 400, setpoint_fn=sp)
    after = ys[100:]
    outside = np.nonzero(np.abs(after - 96.0) > 0.5)[0]
    settle_h = (outside[-1] + 1) * dt if outside.size else 0.0
    return ys, us, integ, settle_h


def test_anti_windup_bounds_integrator_and_recovers_faster():
    _, us_n, int_n, settle_none = windup_case("none")
    _, us_b, int_b, settle_back = windup_case("back_calculation")
    _, us_c, int_c, settle_cond = windup_case("conditional")
    assert np.all(us_b <= 70.0) and np.all(us_n <= 70.0)
    # while saturated, the plain integral keeps growing (30 um error for 5 h); with
    # anti-windup it stays bounded by |u_max - u_bias| + |Kc| max|e| (back-calculation settles
    # at I = (u_max - u_bias) - Kc e (1 - Tt/Ti))
    kc, _ = simc_pi(MODEL)
    bound = 5.0 + abs(kc) * 30.0
    assert np.max(np.abs(int_n[:100])) > bound
    assert np.max(np.abs(int_b[:100])) <= bound
    assert np.max(np.abs(int_c[:100])) <= bound
    # after the set point becomes reachable again, the anti-windup loops settle within 5 h
    # (+-0.5 um); the plain one is still unwinding at the end of the 15 h run
    assert settle_back < 5.0 and settle_cond < 5.0
    assert settle_none > 2.0 * max(settle_back, settle_cond)


def test_pi_input_validation():
    with pytest.raises(MpcInputError, match="anti_windup"):
        DiscretePI(1.0, 1.0, 0.1, 0.0, 0.0, anti_windup="clamp")
    with pytest.raises(MpcInputError, match="ti_h"):
        DiscretePI(1.0, -1.0, 0.1, 0.0, 0.0)
    with pytest.raises(MpcInputError, match="u_min"):
        DiscretePI(1.0, 1.0, 0.1, 0.0, 0.0, u_min=5.0, u_max=1.0)
    with pytest.raises(MpcInputError, match="tt_h"):
        DiscretePI(1.0, 1.0, 0.1, 0.0, 0.0, tt_h=0.01)
    pi = DiscretePI(1.0, 1.0, 0.1, 0.0, 0.0)
    with pytest.raises(MpcInputError, match="y_measured"):
        pi.make_step(float("nan"))


def test_simc_pi_from_linearised_le_roux_holds_p80_through_harder_ore():
    from mpc.plants.leroux import LeRouxCircuit

    plant = LeRouxCircuit(dt_h=0.05)
    xs = plant.steady_state()
    pi, model = pi_from_model(plant.f, plant.outputs, xs, plant.u_nominal, plant.d_nominal,
                              dt_h=0.05, tau_c_h=0.5, u_min=30.0, u_max=90.0, du_max=1.0)
    assert model.gain == pytest.approx(1.64, rel=0.05)  # um per t/h at survey 3
    assert 1.0 < model.tau_h < 2.0 and model.delay_h < 0.1
    y_sp = float(plant.outputs["p80_um"](xs, plant.u_nominal, plant.d_nominal))
    assert pi.setpoint == pytest.approx(y_sp) and pi.u_bias == pytest.approx(plant.u_nominal[0])
    assert (pi.kc, pi.ti_h) == pytest.approx(simc_pi(model, 0.5))
    plant.reset(xs)
    d_hard = plant.d_nominal * np.array([1.05, 1.0, 1.0])  # 5 % harder ore from t = 0
    y = y_sp
    ys, us = [], []
    for _ in range(240):  # 12 h
        u = pi.make_step(y)
        y = plant.make_step([u, plant.u_nominal[1]], d_hard)["p80_um"]
        ys.append(y)
        us.append(u)
    assert max(ys) > y_sp + 1.0  # the disturbance was felt
    assert ys[-1] == pytest.approx(y_sp, abs=0.05)  # and removed, no offset
    assert us[-1] < plant.u_nominal[0] - 1.0  # by cutting the feed
