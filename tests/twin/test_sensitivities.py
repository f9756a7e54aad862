"""Exact sensitivities of steady states (implicit function theorem on the Newton system) and the
parametric twins the table fit runs on: against central differences and the full twin."""

import numpy as np
import pytest

from twin import Twin
from twin.calibration import DEM_NAMES, load_calibration
from twin.calibration.parametric import ParametricTwin, calibration_values
from twin.sizes import SizeGrid, pxx_um
from twin.solve import pxx_gradient, steady_sensitivities

EPS = float(np.finfo(float).eps)


def _central(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pxx_gradient_equals_central_differences_of_pxx(seed):
    grid = SizeGrid()
    m = np.random.default_rng(seed).lognormal(size=grid.count)
    g = pxx_gradient(grid, m)
    for j in range(grid.count):
        e = np.zeros(grid.count)
        e[j] = 1.0
        fd = _central(lambda t: pxx_um(grid, m + t * e), 0.0, 1e-7 * m[j])
        assert g[j] == pytest.approx(fd, rel=1e-5, abs=1e-6 * abs(g).max())


def test_pxx_gradient_inside_the_sink_class():
    grid = SizeGrid(count=6)
    m = np.array([0.0, 0.0, 0.0, 0.0, 0.1, 0.9])  # 90 % in the sink: P80 lies inside it
    g = pxx_gradient(grid, m)
    fd = [_central(lambda t, j=j: pxx_um(grid, m + t * np.eye(6)[j]), 0.0, 1e-7) for j in range(6)]
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("at_load", [False, True])
def test_sensitivity_to_hardness_equals_central_differences(twin_b, at_load):
    """d(KPIs)/d(hardness_scale) at a fixed feed and at constant load, against two more solves."""
    def solve(hs):
        return (twin_b.steady_at_constant_load(0.70, hardness_scale=hs) if at_load
                else twin_b.steady(0.031, 0.70, hardness_scale=hs))

    ss = solve(1.0)
    sens = steady_sensitivities(twin_b.model, ss, at_load=at_load)
    h = 1e-5
    up, down = solve(1 + h), solve(1 - h)
    col = twin_b.model.n_components  # hardness_scale comes after the blend
    # a central difference carries round-off ~ eps |y| / h (specific energy at a fixed feed does
    # not depend on hardness: both sides are zero up to that)
    assert sens["p80_um"][col] == pytest.approx((up.p80_um - down.p80_um) / (2 * h), rel=1e-5,
                                                abs=100 * EPS * ss.p80_um / h)
    key = "specific_energy_kwh_t"
    assert sens[key][col] == pytest.approx((up.outputs[key] - down.outputs[key]) / (2 * h), rel=1e-5,
                                           abs=100 * EPS * ss.outputs[key] / h)
    if at_load:
        assert sens["feed_tph"][col] == pytest.approx((up.feed_tph - down.feed_tph) / (2 * h), rel=1e-5)
        assert abs(sens["feed_tph"][col]) > 0  # the test is not trivially zero


@pytest.fixture(scope="module")
def parametric_d():
    cal = load_calibration("dem")
    return cal, ParametricTwin("D", cal, DEM_NAMES)


def test_parametric_twin_is_the_full_twin_at_the_base_values(parametric_d):
    cal, pt = parametric_d
    kpis, _ = pt.kpis(calibration_values(cal), with_gradient=False)
    ss = Twin("D", calibration=cal).steady_at_constant_load(0.70)
    assert kpis["p80_um"] == pytest.approx(ss.p80_um, rel=1e-9)
    assert kpis["specific_energy_kwh_t"] == pytest.approx(ss.outputs["specific_energy_kwh_t"], rel=1e-9)
    assert kpis["throughput_kg_h"] == pytest.approx(1000 * ss.feed_tph, rel=1e-9)


def test_parametric_gradients_equal_central_differences(parametric_d):
    cal, pt = parametric_d
    v = calibration_values(cal)
    _, grad = pt.kpis(v)
    for i, name in enumerate(DEM_NAMES):
        h = 1e-5 * abs(v[name])
        pt.reset()
        up, _ = pt.kpis({**v, name: v[name] + h}, with_gradient=False)
        pt.reset()
        down, _ = pt.kpis({**v, name: v[name] - h}, with_gradient=False)
        for kpi, g in grad.items():
            fd = (up[kpi] - down[kpi]) / (2 * h)
            assert g[i] == pytest.approx(fd, rel=2e-4, abs=1e-9 * max(1.0, abs(up[kpi]) / abs(v[name]))), (name, kpi)
