"""Tests of mpc.discretize: observed order of RK4, agreement with CVODES, RK4 stability count."""

import numpy as np
import pytest

from mpc.discretize import (RK4_RATE_SAFETY, cvodes_map, min_rk4_substeps, rk4_amplification, rk4_map,
                            stable_rk4_substeps)
from mpc.errors import MpcInputError
from mpc.plants.leroux import LeRouxCircuit
from mpc.linear import linearize


@pytest.fixture(scope="module")
def plant():
    c = LeRouxCircuit()
    return c, c.steady_state()


def test_rk4_observed_order_is_four_on_le_roux(plant):
    c, xs = plant
    u = c.u_nominal + np.array([8.0, -0.03])  # a real transient from the steady state
    dt = 0.1
    ref = np.array(cvodes_map(c.f, dt, 1e-12, 1e-12)(xs, u, c.d_nominal)).ravel()
    errs = []
    for n in (4, 8, 16, 32):
        xn = np.array(rk4_map(c.f, dt, n)(xs, u, c.d_nominal)).ravel()
        errs.append(np.max(np.abs(xn - ref)))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 3.7), orders  # classical RK4: 4
    assert errs[-1] < 1e-8


def test_cvodes_tighter_tolerance_is_more_accurate(plant):
    c, xs = plant
    u = c.u_nominal + np.array([8.0, -0.03])
    ref = np.array(cvodes_map(c.f, 0.5, 1e-13, 1e-13)(xs, u, c.d_nominal)).ravel()
    e_loose = np.max(np.abs(np.array(cvodes_map(c.f, 0.5, 1e-4, 1e-4)(xs, u, c.d_nominal)).ravel() - ref))
    e_tight = np.max(np.abs(np.array(cvodes_map(c.f, 0.5, 1e-8, 1e-8)(xs, u, c.d_nominal)).ravel() - ref))
    assert e_tight < e_loose
    assert e_tight < 1e-5


def test_min_rk4_substeps_is_the_stability_boundary(plant):
    c, xs = plant
    sys, _ = linearize(c.f, c.outputs, xs, c.u_nominal, c.d_nominal, ["p80_um"])
    lam = np.linalg.eigvals(sys.A)
    dt = 0.25
    n = min_rk4_substeps(sys.A, dt)
    # fastest mode ~ -76.5 1/h; RK4 real-axis limit 2.785: n >= 76.5 * 0.25 / 2.785 = 6.9
    assert n == 7
    assert np.all(rk4_amplification(lam * dt / n) <= 1.0)
    assert np.any(rk4_amplification(lam * dt / (n - 1)) > 1.0)
    # the unstable count blows up a simulation of the nonlinear model; the stable one does not
    u = c.u_nominal
    for steps, bounded in ((n - 2, False), (n, True)):
        f = rk4_map(c.f, dt, steps)
        x = xs + 1e-3
        with np.errstate(all="ignore"):
            for _ in range(200):
                x = np.array(f(x, u, c.d_nominal)).ravel()
        assert bool(np.all(np.isfinite(x)) and np.max(np.abs(x - xs)) < 1.0) is bounded


def test_stable_rk4_substeps_is_the_count_at_the_scaled_jacobian(plant):
    c, xs = plant
    sys, _ = linearize(c.f, c.outputs, xs, c.u_nominal, c.d_nominal, ["p80_um"])
    for dt in (0.05, 0.25):
        assert stable_rk4_substeps(c.f, xs, c.u_nominal, c.d_nominal, dt) == \
            min_rk4_substeps(RK4_RATE_SAFETY * sys.A, dt)
    # ~76.5 1/h x 1.4 x 0.25 h / 2.785 = 9.6: ten steps, where the bare rates need seven
    assert stable_rk4_substeps(c.f, xs, c.u_nominal, c.d_nominal, 0.25) == 10
    assert stable_rk4_substeps(c.f, xs, c.u_nominal, c.d_nominal, 0.25, safety=1.0) == 7


def test_discretize_validation(plant):
    c, _ = plant
    with pytest.raises(MpcInputError, match="n_steps"):
        rk4_map(c.f, 0.1, 0)
    with pytest.raises(MpcInputError, match="dt_h"):
        rk4_map(c.f, -0.1)
    with pytest.raises(MpcInputError, match="'f'"):
        rk4_map(c.outputs, 0.1)
    with pytest.raises(MpcInputError, match="Re > 0"):
        min_rk4_substeps(np.array([[0.1]]), 0.1)
