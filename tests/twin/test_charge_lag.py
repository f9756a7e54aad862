"""The charge lag: same steady state, and every speed or hardness -> P80 transfer function is the
bare twin's times a + (1 - a) / (1 + i w tau) at every frequency (exact in the linearisation);
feed -> P80 is untouched (the lag acts on the breakage rates the inputs set, not on the flows)."""

import casadi as ca
import numpy as np
import pytest

from twin import DEFAULT_EFFECTS, ModelError, SizeGrid, Twin

GRID = SizeGrid(top_um=6700.0, ratio=2.0, count=9)
FAST, TAU_H = 0.3, 1.2


def _twin(fast=None, tau_h=TAU_H):
    extra = {} if fast is None else {"charge_lag": {"fast_frac": fast, "time_constant_h": tau_h}}
    return Twin("B", mill="industrial", effects=list(DEFAULT_EFFECTS) + list(extra), effect_options=extra,
                grid=GRID, n_mixers=1)


@pytest.fixture(scope="module")
def pair():
    # off the nominal speed and hardness, so the lag state settles away from zero
    return [(tw, tw.steady(feed_tph=0.9 * tw.mill.feed_nominal_tph, speed_frac_critical=0.74,
                           hardness_scale=0.8)) for tw in (_twin(), _twin(FAST))]


def test_same_steady_state(pair):
    (plain, s0), (lagged, s1) = pair
    assert s1.p80_um == pytest.approx(s0.p80_um, rel=1e-8)
    np.testing.assert_allclose(s1.x[: plain.model.n_mass], s0.x, rtol=1e-7, atol=1e-12)


def _frequency_response(tw, ss, column, w_per_h):
    """P80 over input ``column`` of ``[u; d]`` (0 feed, 1 speed, 3 hardness scale) at ``w``."""
    m = tw.model
    x, u, dist = ca.SX.sym("x", len(ss.x)), ca.SX.sym("u", 2), ca.SX.sym("d", len(ss.d))
    xdot, y = m.f(x, u, dist), m.outputs["p80_um"](x, u, dist)
    ud = ca.vertcat(u, dist)
    jac = ca.Function("p80_jacobians", [x, u, dist], [ca.jacobian(xdot, x), ca.jacobian(xdot, ud),
                                                      ca.jacobian(y, x), ca.jacobian(y, ud)])
    a, b, c, d = (np.asarray(v, float) for v in jac(ss.x, ss.u, ss.d))
    return np.array([(c @ np.linalg.solve(1j * w * np.eye(a.shape[0]) - a, b[:, [column]]) + d[:, [column]]).item()
                     for w in w_per_h])


@pytest.mark.parametrize("column, name", [(1, "speed"), (3, "hardness")])
def test_speed_and_hardness_reach_p80_through_the_lag(pair, column, name):
    (plain, s0), (lagged, s1) = pair
    w = np.array([0.0, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0])
    g0, g1 = _frequency_response(plain, s0, column, w), _frequency_response(lagged, s1, column, w)
    np.testing.assert_allclose(g1, g0 * (FAST + (1.0 - FAST) / (1.0 + 1j * w * TAU_H)), rtol=1e-6, err_msg=name)
    assert abs(g1[-1]) < 0.5 * abs(g0[-1])  # (the test can fail: at 30/h only the fast part is left)


def test_feed_reaches_p80_as_without_the_lag(pair):
    (plain, s0), (lagged, s1) = pair
    w = np.array([0.0, 1.0, 10.0])
    np.testing.assert_allclose(_frequency_response(lagged, s1, 0, w), _frequency_response(plain, s0, 0, w),
                               rtol=1e-6)


@pytest.mark.parametrize("fast, tau_h, option", [(1.5, 1.0, "fast_frac"), (-0.1, 1.0, "fast_frac"),
                                                 (0.3, 0.0, "time_constant_h")])
def test_options_out_of_range_are_refused(fast, tau_h, option):
    with pytest.raises(ModelError, match=option):
        _twin(fast, tau_h)
