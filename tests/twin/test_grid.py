"""The size discretisation: observed order of convergence on grids that halve the class width,
mass conservation on every grid, and the controller's coarse grid predicting the plant's mill."""

import math

import numpy as np
import pytest

from twin import BreakageParams, GatesGaudinSchuhmann, SizeGrid, Twin, discretise, ore_breakage
from twin.breakage import GAUSS_NODES, cell_average_breakage
from twin.sizes import pxx_um

TOP_UM, BOTTOM_UM = 6700.0, 6700.0 / 4096.0
PARAMS = BreakageParams(se_1mm_t_kwh=1.0, alpha=1.0, mu_um=3000.0, Lambda=2.5, gamma=1.0, beta=4.0, phi=0.5)
COUNTS = (13, 25, 49, 97)  # class widths halve; 385 classes is the reference


def mixer_product(count: int, scheme: str, params=PARAMS, tau_h: float = 1.0):
    """Exact steady product of one perfect mixer, (I/tau + (I - b) S) m = f/tau, on a grid spanning
    the same sizes: linear algebra, no integrator, so only the discretisation is measured."""
    grid = SizeGrid.spanning(TOP_UM, BOTTOM_UM, count, scheme)
    ob = ore_breakage(grid, params, 1.0, 1.0)
    feed = discretise(grid, GatesGaudinSchuhmann.from_p80(3200.0, 0.8))
    a = np.eye(count) / tau_h + (np.eye(count) - ob.b) @ np.diag(ob.selection_per_h)
    return grid, np.linalg.solve(a, feed / tau_h), feed


def passing_on_coarse_bounds(grid, mass, coarse) -> np.ndarray:
    """Cumulative passing at the coarsest grid's class bounds (bounds of every finer grid)."""
    passing = grid.cumulative_passing(mass)
    return np.array([passing[np.argmin(np.abs(grid.upper_um - x))] for x in coarse])


def observed_orders(scheme: str, measure) -> list[float]:
    ref = mixer_product(385, scheme)
    errors = [measure(mixer_product(n, scheme), ref) for n in COUNTS]
    return [math.log2(errors[k] / errors[k + 1]) for k in range(len(errors) - 1)]


def _psd_error(run, ref):
    coarse = SizeGrid.spanning(TOP_UM, BOTTOM_UM, COUNTS[0]).upper_um
    return np.max(np.abs(passing_on_coarse_bounds(*run[:2], coarse) - passing_on_coarse_bounds(*ref[:2], coarse)))


def _p80_error(run, ref):
    return abs(pxx_um(*run[:2]) / pxx_um(*ref[:2]) - 1.0)


@pytest.mark.parametrize("measure", [_psd_error, _p80_error], ids=["passing", "p80"])
def test_cell_average_scheme_converges_at_second_order(measure):
    """Cumulative passing on the coarsest grid's bounds, and P80 (interpolated in ln size)."""
    orders = observed_orders("cell_average", measure)
    assert min(orders) >= 1.8, orders


def test_austin_scheme_is_first_order_so_the_order_test_can_fail():
    orders = observed_orders("austin", _psd_error)
    assert max(orders) < 1.3, orders


@pytest.mark.parametrize("scheme", ["cell_average", "austin"])
@pytest.mark.parametrize("count", [7, 13, 25, 49, 97])
def test_mass_is_conserved_to_round_off_on_every_grid(scheme, count):
    grid, product, feed = mixer_product(count, scheme, tau_h=0.3)
    b = ore_breakage(grid, PARAMS, 1.0, 1.0).b
    assert np.max(np.abs(b[:, :-1].sum(axis=0) - 1.0)) < 1e-13
    assert product.sum() == pytest.approx(feed.sum(), abs=1e-13)
    assert np.all(product >= 0)


def test_gauss_nodes_integrate_the_interval_to_round_off(monkeypatch):
    grid = SizeGrid(count=25)
    s12, b12 = cell_average_breakage(grid, 1.0, PARAMS)
    monkeypatch.setattr("twin.breakage.GAUSS_NODES", 4 * GAUSS_NODES)
    s48, b48 = cell_average_breakage(grid, 1.0, PARAMS)
    assert np.allclose(s12, s48, rtol=1e-10) and np.allclose(b12, b48, atol=1e-12)


def test_controller_grid_predicts_the_plant_mill():
    """The reference scene's controller model (7 classes of ratio 2.5) and plant (25 of sqrt 2),
    same calibration: the same product on the controller's class bounds within 1 point of
    passing, and the same load within a tenth of the half-width of the mill's stable load band
    (what the controller keeps the load in). The coarse classes' hold-up error grows toward
    overload; this case runs 5 % over nominal. (Its P80, interpolated inside one class of ratio
    2.5, is coarser, and both errors are tabled in benchmarks/results/twin_grid.md.)"""
    kw = dict(mill="industrial", n_mixers=3)
    coarse = SizeGrid(6700.0, 2.5, 7)
    plant_twin = Twin(["B", "D"], grid=SizeGrid(6700.0, math.sqrt(2.0), 25), **kw)
    plant = plant_twin.steady(feed_tph=30.0, blend=[1, 0])
    ctl = Twin(["B", "D"], grid=coarse, **kw).steady(feed_tph=30.0, blend=[1, 0])
    fine = plant_twin.grid
    plant_on_coarse = np.interp(np.log(coarse.upper_um), np.log(fine.upper_um[::-1]),
                                fine.cumulative_passing(plant.psd)[::-1])
    assert np.max(np.abs(coarse.cumulative_passing(ctl.psd) - plant_on_coarse)) < 0.01
    lo, hi = plant_twin.mill.stable_band
    assert ctl.outputs["load_frac"] == pytest.approx(plant.outputs["load_frac"], abs=0.1 * (hi - lo) / 2.0)
