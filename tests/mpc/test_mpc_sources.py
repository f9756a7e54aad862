"""The control side against its published sources, each formula checked by an independent computation
written out here: SIMC tuning (Skogestad 2003), the discrete PI with back-calculation (Astrom & Murray 2008),
one EKF step against the linear Kalman filter by hand (Simon 2006), the RK4 tableau and its order
(Hairer, Norsett & Wanner), the analyser's dead time and hold, and the KPIs (trapezoid rule)."""

from __future__ import annotations

import math
import types

import casadi as ca
import numpy as np
import pandas as pd
import pytest

from mpc import Sensors, SensorState
from mpc.discretize import rk4_map, rk4_sensitivity_map
from mpc.errors import MpcInputError
from mpc.estimator import Ekf
from mpc.kpis import loop_kpis
from mpc.linear import Fopdt, fit_fopdt
from mpc.pi import DiscretePI, simc_pi


# --------------------------------------------------------------------------- SIMC and the PI
@pytest.mark.parametrize("k,tau,theta,tau_c", [(1.6, 1.3, 0.25, None), (-0.8, 5.0, 0.1, 0.3), (2.0, 0.4, 0.3, 0.2)])
def test_simc_gains_are_skogestads_rule(k, tau, theta, tau_c):
    """Skogestad (2003), J. Process Control 13, 291-309, the SIMC PI for k exp(-theta s)/(tau s + 1):
    Kc = tau / (k (tau_c + theta)), Ti = min(tau, 4 (tau_c + theta)), tau_c = theta by default. The cases take
    both branches of the min (5.0 > 4 x 0.4; 0.4 < 4 x 0.5) and a negative process gain (Kc takes its sign)."""
    tc = theta if tau_c is None else tau_c
    kc, ti = simc_pi(Fopdt(k, tau, theta), tau_c)
    assert kc == pytest.approx(tau / k / (tc + theta), rel=1e-14)
    assert ti == pytest.approx(tau if tau < 4 * (tc + theta) else 4 * (tc + theta), rel=1e-14)
    assert np.sign(kc) == np.sign(k)


def test_the_integral_repeats_the_proportional_action_in_one_integral_time():
    """The integral time's definition (Astrom & Murray 2008, ch. 10): with a constant error the integral
    action grows by Kc e every Ti; forward Euler reaches it exactly after Ti / dt samples."""
    kc, ti, dt, e = 2.5, 0.6, 0.05, 4.0
    pi = DiscretePI(kc, ti, dt, setpoint=100.0, u_bias=50.0)
    us = [pi.make_step(100.0 - e) for _ in range(round(ti / dt) + 1)]
    assert us[0] == pytest.approx(50.0 + kc * e, rel=1e-14)  # proportional action alone on the first sample
    assert us[-1] == pytest.approx(50.0 + 2.0 * kc * e, rel=1e-12)  # doubled after Ti


def test_back_calculation_drives_the_integral_by_the_saturation_over_tt():
    """Astrom & Murray (2008) sec. 10.4: dI/dt = Kc/Ti e + (u - v)/Tt, here by forward Euler; one saturated
    sample and the next by hand."""
    kc, ti, dt, tt = 2.0, 1.0, 0.1, 0.5
    pi = DiscretePI(kc, ti, dt, setpoint=10.0, u_bias=5.0, u_min=0.0, u_max=8.0, tt_h=tt)
    u = pi.make_step(7.0)  # e = 3: v = 5 + 6 = 11, clipped to 8
    assert u == 8.0 and pi.last_result.status == "saturated"
    i1 = kc * dt / ti * 3.0 + dt / tt * (8.0 - 11.0)
    assert pi.integral == pytest.approx(i1, rel=1e-14)
    u = pi.make_step(9.0)  # e = 1: v = 5 + 2 + I1, inside the bounds
    assert u == pytest.approx(5.0 + kc * 1.0 + i1, rel=1e-14)
    assert pi.integral == pytest.approx(i1 + kc * dt / ti * 1.0, rel=1e-14)


def test_the_fopdt_fit_recovers_a_first_order_plus_dead_time_response():
    """The SIMC input: fit_fopdt on the exact step response k (1 - exp(-(t - theta)/tau)) for t > theta
    (written out here) gives back k, tau and theta; a step of du scales the response, not the gain."""
    k, tau, theta, du = -1.7, 0.8, 0.15, 2.5
    t = np.linspace(0.0, 6.0, 601)
    y = k * du * (1.0 - np.exp(-np.clip(t - theta, 0.0, None) / tau))
    fit = fit_fopdt(t, y, du=du)
    assert (fit.gain, fit.tau_h, fit.delay_h) == pytest.approx((k, tau, theta), rel=1e-6)
    assert fit.rms_error < 1e-8


@pytest.mark.parametrize("kwargs,name", [({"kc": "fast"}, "kc"), ({"ti_h": "1"}, "ti_h"), ({"u_max": None}, "u_max"),
                                         ({"setpoint": True}, "setpoint"), ({"du_max": "inf"}, "du_max")])
def test_a_pi_parameter_that_is_not_a_number_is_named(kwargs, name):
    """A string failed inside float() with no parameter named ("could not convert string to float"), and
    True was read as 1."""
    args = {"kc": 1.0, "ti_h": 1.0, "dt_h": 0.1, "setpoint": 0.0, "u_bias": 0.0, **kwargs}
    with pytest.raises(MpcInputError, match=f"'{name}'"):
        DiscretePI(**args)


def test_a_tau_c_that_is_not_a_number_is_named():
    with pytest.raises(MpcInputError, match="'tau_c_h'"):
        simc_pi(Fopdt(1.0, 1.0, 0.1), "0.2")


# --------------------------------------------------------------------------- EKF
def scalar_model(lam: float, c: float, kappa: float = 0.0):
    """x' = -lam x + feed + kappa (hardness - 1) [t, h], linear in the state and the hardness (the last entry
    of d); the analyser reads c x, the load x, the power x; no algebraic aggregates. What Ekf reads of a
    twin's model."""
    x, u, d = ca.SX.sym("x", 1), ca.SX.sym("u", 2), ca.SX.sym("d", 2)
    ode = -lam * x + u[0] + kappa * (d[1] - 1.0)
    out = {"p80_um": c * x, "power_kw": x, "load_frac": x}
    return types.SimpleNamespace(
        x=x, u=u, d=d, z=ca.SX(0, 1), z_expr=ca.SX(0, 1), dae={"x": x, "ode": ode},
        f=ca.Function("f", [x, u, d], [ode]), spec=types.SimpleNamespace(holdup_nominal_t=10.0),
        outputs={k: ca.Function(k, [x, u, d], [v]) for k, v in out.items()})


def rk4_gain(z: complex) -> complex:
    """R(z) of classical RK4: one step of y' = lam y multiplies y by R(h lam)."""
    return 1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24


def test_one_ekf_step_is_the_kalman_filter_by_hand():
    """On a linear model the EKF is the Kalman filter (Simon 2006, eqs. 5.17-5.19): z = [x; h; b], the
    hardness h and a P80 bias b walking with intensities q_h, q_b (variance q^2 dt per sample), P80 and load
    measured, power absent. RK4 on the affine x' = -lam (x - c/lam), c = u + kappa (h - 1), is exact:
    x+ = c/lam + R^n (x - c/lam) over n substeps, so F = [[R^n, kappa (1 - R^n)/lam, 0], [0, 1, 0], [0, 0, 1]]
    (not symmetric: F P F^T is told from F P F). The short form (I - K H) P- of the optimal gain stands in
    for the Joseph form."""
    lam, c, kappa, dt, n = 2.0, 3.0, -6.0, 0.1, 2
    q_h, q_b, p80_sd, load_sd, rel, p0_rel, h_p0, b_p0 = 0.05, 4.0, 2.0, 0.5, 0.01, 0.2, 0.3, 6.0
    x0, u = 5.0, np.array([4.0, 0.7])
    ekf = Ekf(scalar_model(lam, c, kappa), dt, [x0], disturbance_model="hardness+p80_bias", p80_noise_um=p80_sd,
              load_noise_frac=load_sd, state_noise_rel=rel, p0_rel=p0_rel, hardness_p0=h_p0, p80_bias_p0_um=b_p0,
              hardness_noise_per_sqrt_h=q_h, p80_bias_noise_um_per_sqrt_h=q_b, rk4_substeps=n, codegen="off")
    a = rk4_gain(-lam * dt / n).real ** n
    F = np.array([[a, kappa * (1 - a) / lam, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    Q = np.diag([(rel * x0) ** 2, q_h ** 2 * dt, q_b ** 2 * dt])
    P = np.diag([(p0_rel * x0) ** 2, h_p0 ** 2, b_p0 ** 2])
    zp = np.array([u[0] / lam + a * (x0 - u[0] / lam), 1.0, 0.0])  # h = 1: no hardness term yet
    Pp = F @ P @ F.T + Q
    H = np.array([[c, 0.0, 1.0], [1.0, 0.0, 0.0]])
    R, y = np.diag([p80_sd ** 2, load_sd ** 2]), np.array([16.0, 4.2])
    K = Pp @ H.T @ np.linalg.inv(H @ Pp @ H.T + R)
    z_want, P_want = zp + K @ (y - H @ zp), (np.eye(3) - K @ H) @ Pp
    assert abs(z_want[1] - 1.0) > 0.005  # the hardness moved, inside its bounds (no clipping)
    ekf.make_step([y[0], np.nan, y[1]], u, [1.0])
    np.testing.assert_allclose(ekf.z, z_want, rtol=1e-12)
    np.testing.assert_allclose(ekf.P, P_want, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(ekf.innovation, [y[0] - c * zp[0], np.nan, y[1] - zp[0]], rtol=1e-12)


def test_a_hardness_walk_adds_its_intensity_squared_times_dt_per_sample():
    """A random walk of intensity q [1/sqrt(h)] over dt: variance q^2 dt. With nothing measured and a state
    the hardness does not move, the hardness variance grows by exactly that each sample."""
    q, dt, p0 = 0.03, 0.05, 0.1
    ekf = Ekf(scalar_model(2.0, 3.0), dt, [5.0], hardness_noise_per_sqrt_h=q, hardness_p0=p0, codegen="off")
    for k in range(1, 4):
        ekf.make_step([np.nan] * 3, [4.0, 0.7], [1.0])
        assert ekf.P[1, 1] == pytest.approx(p0 ** 2 + k * q ** 2 * dt, rel=1e-12)


@pytest.mark.parametrize("kwargs,name", [({"dt_h": "0.05"}, "dt_h"), ({"p80_noise_um": True}, "p80_noise_um"),
                                         ({"hardness_noise_per_sqrt_h": None}, "hardness_noise_per_sqrt_h")])
def test_an_ekf_setting_that_is_not_a_number_is_named(kwargs, name):
    """A string or None failed inside np.isfinite with no parameter named; True ran as a 1 um analyser noise."""
    args = {"dt_h": 0.05, **kwargs}
    with pytest.raises(MpcInputError, match=f"'{name}'"):
        Ekf(scalar_model(2.0, 3.0), args.pop("dt_h"), [5.0], codegen="off", **args)


# --------------------------------------------------------------------------- RK4
def test_rk4_is_the_classical_tableau_and_fourth_order_on_exponential_decay():
    """One RK4 step of x' = -x is the Taylor series of exp(-h) to h^4 (the classical tableau; a wrong
    weight or node changes a coefficient); over [0, 1] the error against exp(-1) falls 16-fold per halving
    of h (observed order 4), and the sensitivity map carries the same tableau (dx+/dx = R(-h)^n)."""
    x, u, d = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("d")
    f = ca.Function("f", [x, u, d], [-x])
    h = 0.3
    assert float(rk4_map(f, h)(1.0, 0, 0)) == pytest.approx(1 - h + h ** 2 / 2 - h ** 3 / 6 + h ** 4 / 24, rel=1e-15)
    errors = [abs(float(rk4_map(f, 1.0, n)(1.0, 0, 0)) - math.exp(-1.0)) for n in (8, 16, 32)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(orders - 4.0) < 0.1), orders
    _, a, b = rk4_sensitivity_map(scalar_model(1.0, 1.0), 1.0, 4)(0.5, [0.0, 0.7], [1.0, 1.0])
    assert float(a) == pytest.approx(rk4_gain(-0.25) ** 4, rel=1e-14)
    assert float(b[0]) == pytest.approx(1.0 - rk4_gain(-0.25) ** 4, rel=1e-14)  # d/du of u (1 - R^n)


# --------------------------------------------------------------------------- the analyser
@pytest.mark.parametrize("dead_h,dt_h,delay_samples", [(0.1, 0.05, 2), (0.1, 1 / 60, 6), (0.12, 0.05, 3)])
def test_the_analyser_delays_a_step_by_its_dead_time_rounded_up_to_a_sample(dead_h, dt_h, delay_samples):
    """A P80 step taken at sample 10 (the analyser sampling every 0.05 h, read every dt_h): a 0.1 h dead time
    is exactly 2 samples of 0.05 h and 6 of 1 min; 0.12 h is reported at 0.17 h after the step, read at the
    next sample after it (3 samples): a reading never comes before its dead time."""
    state = SensorState(Sensors(p80_noise_um=0.0, p80_dead_time_h=dead_h, p80_sample_period_h=0.05),
                        np.random.default_rng(0))
    step = 10 if dt_h == 0.05 else 30  # 0.5 h, an analyser sample
    held = [state.make_step(k * dt_h, 200.0 if k < step else 230.0, 0.0, 0.0)[1] for k in range(step + 12)]
    first = next(k for k, v in enumerate(held) if v == 230.0)
    assert first - step == delay_samples
    assert all(v == 230.0 for v in held[first:])  # held between reports


@pytest.mark.parametrize("kwargs,name", [({"p80_noise_um": "3"}, "p80_noise_um"),
                                         ({"p80_dead_time_h": True}, "p80_dead_time_h"),
                                         ({"p80_sample_period_h": None}, "p80_sample_period_h")])
def test_a_sensor_setting_that_is_not_a_number_is_named(kwargs, name):
    """A string or None failed inside np.isfinite with no field named; True was a 1 h dead time."""
    with pytest.raises(MpcInputError, match=f"'{name}'"):
        Sensors(**kwargs)


def test_a_nan_first_time_is_named():
    """It failed inside math.floor ("cannot convert float NaN to integer")."""
    with pytest.raises(MpcInputError, match="'t_h'"):
        SensorState(Sensors(), np.random.default_rng(0)).make_step(math.nan, 200.0, 100.0, 1.0)


# --------------------------------------------------------------------------- KPIs
def test_loop_kpis_by_hand():
    """IAE (trapezoid of |P80 - target|, exact for a piecewise-linear error of one sign), P80 and load standard
    deviations over the samples (population form, ddof 0), largest error, throughput (trapezoid of the product
    rate) and specific energy = energy / fed tonnes with the feed held, on four samples 0.5 h apart."""
    frame = pd.DataFrame({
        "time_h": [0.0, 0.5, 1.0, 1.5], "p80_um": [214.0, 218.0, 212.0, 211.0], "p80_target_um": 210.0,
        "load_frac": [1.0, 1.1, 0.7, 1.0], "throughput_tph": [30.0, 32.0, 34.0, 36.0],
        "power_kw": [1500.0, 1600.0, 1500.0, 1400.0], "feed_tph": [30.0, 36.0, 30.0, 90.0],
        "solve_time_s": [0.01, 0.02, 0.03, 0.04], "fallback": [None, None, "hold_input", None]})
    k = loop_kpis(frame)
    assert k["p80_iae_um_h"] == pytest.approx(0.5 * ((4 + 8) / 2 + (8 + 2) / 2 + (2 + 1) / 2), rel=1e-14)
    p80 = np.array([214.0, 218.0, 212.0, 211.0])
    assert k["p80_std_um"] == pytest.approx(math.sqrt(np.sum((p80 - 213.75) ** 2) / 4), rel=1e-14)
    assert k["p80_max_abs_err_um"] == 8.0 and k["p80_within_10um_frac"] == 1.0
    assert k["load_outside_band_frac"] == 0.25
    assert k["throughput_t"] == pytest.approx(0.5 * (31 + 33 + 35), rel=1e-14)
    energy_kwh, fed_t = 0.5 * (1550 + 1550 + 1450), 0.5 * (30 + 36 + 30)  # the last feed is never applied
    assert k["specific_energy_kwh_t"] == pytest.approx(energy_kwh / fed_t, rel=1e-14)
    assert k["fallback_steps"] == 1
