"""A second audit of the DEM's public API: inputs it took and then ran wrongly (or for ever) without
a word. Each test failed on the code before its fix."""

import math

import numpy as np
import pytest

from dem import drum as drum_module
from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams, BondSet, kn_from_modulus_Pa_m
from dem.drum import drum_test
from dem.errors import DemInputError
from dem.materials import Material, damping_coefficient
from dem.system import PlaneWall, System

R = 1e-3
TWO = [[0.0, 0.0, 0.0], [2.1 * R, 0.0, 0.0]]
THREE = np.array([[0.0, 0.0, 0.0], [2 * R, 0.0, 0.0], [4 * R, 0.0, 0.0]])


# ---------------------------------------------------------------- time step
def test_a_time_step_assigned_past_the_critical_one_is_refused():
    """The constructor refused dt_s above critical_dt_s; assigning it afterwards was taken (past it
    bonds break spuriously and forces are off by tens of per cent before any blow-up is reported,
    benchmarks/results/dem_time_step.md)."""
    s = System(TWO, [R, R], Material())
    with pytest.raises(DemInputError, match=r"'dt_s' parameter of System.*critical time step.*set_dt_beyond"):
        s.dt_s = 10.0 * s.critical_dt_s
    for bad in (0.0, -1e-9, math.nan, "1e-7"):
        with pytest.raises(DemInputError, match="'dt_s'"):
            s.dt_s = bad
    s.dt_s = 0.5 * s.critical_dt_s          # within the bound: taken, and used by run
    s.run(4)
    assert s.time_s == pytest.approx(4 * 0.5 * s.critical_dt_s, rel=1e-12)


def test_a_stability_study_sets_a_step_past_critical_on_purpose():
    s = System(TWO, [R, R], Material())
    s.set_dt_beyond_critical(1.6 * s.critical_dt_s)
    assert s.dt_s == 1.6 * s.critical_dt_s
    with pytest.raises(DemInputError, match="'dt_s' parameter of System.set_dt_beyond_critical"):
        s.set_dt_beyond_critical(math.inf)


# ---------------------------------------------------------------- walls
@pytest.mark.parametrize("normal", [(0.0, 0.0, 2.0), (1.0, 1.0, 0.0), (0.0, 0.1, 1.0)])
def test_a_wall_normal_that_is_not_unit_is_refused_not_scaled(normal):
    """(0, 0.1, 1) (a typo) was scaled into a tilted wall, (1, 1, 0) into a diagonal one, silently."""
    with pytest.raises(DemInputError, match=r"'walls\[0\].normal'.*unit vector.*divide it by its length"):
        System(TWO, [R, R], Material(), walls=[PlaneWall((0, 0, -R), normal)])


def test_a_wall_normal_typed_to_six_digits_is_taken():
    c = 0.707107    # 1/sqrt(2) to six digits
    s = System(TWO, [R, R], Material(), walls=[PlaneWall((0, -2 * R, 0), (0, c, c))])
    assert np.linalg.norm(s.w_n[0]) == pytest.approx(1.0, abs=1e-15)


def test_a_sphere_centre_behind_a_wall_is_refused():
    """A bottom platen given the normal (0, 0, -1) put both spheres 'inside' it, with an overlap of
    twice their radius: a force of some 100 kN on each 1-mm sphere, which left at 3 km/s, silently."""
    with pytest.raises(DemInputError, match=r"'walls\[0\]'.*sphere 0 .*behind the plane.*normal's sign"):
        System(TWO, [R, R], Material(), walls=[PlaneWall((0, 0, -R), (0, 0, -1))])


