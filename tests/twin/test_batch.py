"""Batch mill (MISSION.md eq. 5): CasADi integration against the exact solution; observed
order of a fixed-step scheme."""

import numpy as np
import pytest

from twin.solve.simulate import batch_exact, integrate_constant, rk4_simulate


def _exact(batch, t_h, x0):
    ore = batch.spec.breakage[0]
    return batch_exact(ore.selection_per_h, ore.b, x0, t_h)


def test_cvodes_matches_exact_solution_at_tight_tolerance(batch_b):
    m = batch_b.model
    x0 = m.initial_state()
    u, d = m.u_vector(0.0), m.d_vector()
    for t_h in (0.05, 0.5, 2.0):
        x = integrate_constant(m, x0, t_h, u, d, rtol=1e-13, atol_rel=1e-15)
        exact = _exact(batch_b, t_h, x0)
        assert np.abs(x - exact).max() / exact.sum() <= 1e-8


def test_rk4_observed_order_of_convergence(batch_b):
    m = batch_b.model
    x0 = m.initial_state()
    u, d = m.u_vector(0.0), m.d_vector()
    exact = _exact(batch_b, 0.5, x0)
    errors = [np.abs(rk4_simulate(m, x0, 0.5, n, u, d) - exact).max() for n in (40, 80, 160)]
    orders = [np.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert min(orders) >= 3.8, (errors, orders)


def test_batch_model_has_no_flows_and_conserves_mass(batch_b):
    m = batch_b.model
    assert "throughput_tph" not in m.outputs and "transport" not in m.effect_names
    x0 = m.initial_state()
    x = integrate_constant(m, x0, 3.0, m.u_vector(0.0), m.d_vector())
    assert x.sum() == pytest.approx(x0.sum(), rel=1e-9)
    assert x.min() >= 0.0
