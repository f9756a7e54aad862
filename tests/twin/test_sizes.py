import math

import casadi as ca
import numpy as np
import pytest

from twin.errors import TwinInputError
from twin.sizes import (GatesGaudinSchuhmann, RosinRammler, SizeGrid, TabulatedPSD, discretise,
                        pxx_um, smooth_pxx)


def test_grid_is_geometric_coarsest_first_with_sink():
    g = SizeGrid(top_um=1000.0, ratio=2.0, count=5)
    assert np.allclose(g.upper_um, [1000, 500, 250, 125, 62.5])
    assert g.lower_um[-1] == 0.0 and np.allclose(g.lower_um[:-1], g.upper_um[1:])


@pytest.mark.parametrize("psd", [RosinRammler.from_p80(210.0, 1.2), GatesGaudinSchuhmann.from_p80(3200.0, 0.8)])
def test_discretised_distribution_sums_to_one_and_recovers_p80(psd):
    g = SizeGrid()
    f = discretise(g, psd)
    assert f.sum() == pytest.approx(1.0, abs=1e-14) and np.all(f >= 0)
    p80_true = {RosinRammler: 210.0, GatesGaudinSchuhmann: 3200.0}[type(psd)]
    # linear-in-log interpolation of a curved distribution: within a few % on a sqrt(2) grid
    assert pxx_um(g, f) == pytest.approx(p80_true, rel=0.02)


def test_pxx_exact_at_class_bounds():
    g = SizeGrid(top_um=1000.0, ratio=2.0, count=6)
    m = np.array([0.1, 0.1, 0.3, 0.2, 0.2, 0.1])
    # passing at upper sizes: 1, .9, .8, .5, .3, .1 -> P80 exactly at 250 um, P50 at 125 um
    assert pxx_um(g, m, 80) == pytest.approx(250.0, rel=1e-12)
    assert pxx_um(g, m, 50) == pytest.approx(125.0, rel=1e-12)
    # halfway in passing between bounds -> geometric mean in size
    assert pxx_um(g, m, 65) == pytest.approx(math.sqrt(250 * 125), rel=1e-12)


def test_smooth_p80_error_against_exact_is_within_stated_bound():
    g = SizeGrid()
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(200):
        p80 = float(np.exp(rng.uniform(np.log(30), np.log(2000))))
        f = discretise(g, RosinRammler.from_p80(p80, rng.uniform(0.6, 2.0)))
        worst = max(worst, abs(smooth_pxx(g, f) / pxx_um(g, f) - 1))
    assert worst < 0.013  # the bound stated in smooth_pxx's docstring


def test_smooth_p80_is_differentiable_in_casadi():
    g = SizeGrid()
    m = ca.SX.sym("m", g.count)
    p80 = smooth_pxx(g, m)
    grad = ca.Function("g", [m], [ca.gradient(p80, m)])
    f = discretise(g, RosinRammler.from_p80(200.0, 1.0))
    v = np.asarray(grad(f)).ravel()
    assert np.all(np.isfinite(v))
    # adding coarse mass raises P80, adding fines lowers it
    assert v[0] > 0 and v[-1] < 0


def test_passing_weights_match_interpolation():
    g = SizeGrid()
    f = discretise(g, RosinRammler.from_p80(210.0, 1.1))
    p80 = pxx_um(g, f)
    assert g.passing_weights(p80) @ f == pytest.approx(0.80, abs=1e-12)


def test_tabulated_psd_rejects_decreasing_passing():
    with pytest.raises(TwinInputError, match="non-decreasing"):
        TabulatedPSD((100.0, 200.0, 400.0), (0.5, 0.4, 1.0))


def test_grid_rejects_bad_ratio():
    with pytest.raises(TwinInputError, match="'ratio' parameter of SizeGrid"):
        SizeGrid(ratio=0.5)


def test_symbolic_pxx_is_remade_for_each_grid_and_percent():
    """The symbolic Pxx is built once per (grid, percent, sharpness) and reused: each grid's and
    percent's expression must still be its own (the numeric formula's value to round-off)."""
    rng = np.random.default_rng(3)
    for g in (SizeGrid(), SizeGrid(top_um=3350.0), SizeGrid(count=30, ratio=2 ** 0.25)):
        m = ca.SX.sym("m", g.count)
        for percent in (80.0, 50.0, 80.0):
            fn = ca.Function("p", [m], [smooth_pxx(g, m, percent)])
            for _ in range(5):
                f = discretise(g, RosinRammler.from_p80(float(rng.uniform(60.0, 900.0)), 1.0))
                assert float(fn(f)) == pytest.approx(smooth_pxx(g, f, percent), rel=1e-12)
