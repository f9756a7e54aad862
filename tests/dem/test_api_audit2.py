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
from dem.system import DrumGeometry, PlaneWall, System

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


# ---------------------------------------------------------------- restitution
def test_a_restitution_the_damping_cannot_give_is_refused_where_the_material_is_made():
    """Material(restitution=0.01) was made; the refusal came only when a System was built from it."""
    with pytest.raises(DemInputError, match=r"'restitution' parameter of Material.*\[0.05, 1"):
        Material(restitution=0.01)
    with pytest.raises(DemInputError, match=r"'restitution' parameter of damping_coefficient.*\[0.05, 1"):
        damping_coefficient(0.01)
    assert Material(restitution=0.05).restitution == 0.05


# ---------------------------------------------------------------- drum
def test_a_drum_run_of_more_steps_than_its_budget_is_refused_before_a_step(monkeypatch):
    """A speed fraction of 0.007 (0.7 typed 100x too small) started 11 million steps (hours) without
    a word; 1e-300 some 1e304."""
    def no_step(*a, **k):
        raise AssertionError("a step ran before the work was bounded")
    monkeypatch.setattr(drum_module.System, "run", no_step)
    for speed in (0.007, 1e-300):
        with pytest.raises(DemInputError, match=r"run .* steps .*speed_frac_critical .*max_steps = 1e\+07.*least 0.00"):
            drum_test(speed, 0.35)
    with pytest.raises(DemInputError, match=r"max_steps = 1e\+03. Allowed: fewer revolutions"):
        drum_test(0.7, 0.35, max_steps=1000)
    for bad in (0, 2.5, True):
        with pytest.raises(DemInputError, match="'max_steps' parameter of drum_test"):
            drum_test(0.7, 0.35, max_steps=bad)


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


def test_a_sphere_centre_inside_a_lifter_bar_is_refused():
    """A sphere placed 5 mm inside a lifter bar (its centre 1 mm off the bar's axis) was pushed with
    some 400 kN and left at 2 km/s, silently; the drum shell itself was checked."""
    drum = DrumGeometry(0.1, 1.0, n_lifters=4, lifter_height_m=0.02, lifter_width_m=0.01)
    with pytest.raises(DemInputError, match=r"'pos_m'.*inside a lifter bar.*sphere 1 .*lifter 0"):
        System([[0.0, 0.0, 0.0], [0.085, 0.001, 0.0]], [R, R], Material(), drum=drum)
    System([[0.0, 0.0, 0.0], [0.085, 0.01, 0.0]], [R, R], Material(), drum=drum)   # beside it: taken


# ---------------------------------------------------------------- bonds
@pytest.mark.parametrize("kwargs, match", [
    (dict(tensile_strength_Pa=24.5), r"'tensile_strength_Pa'.*>= 1000 Pa.*10e6 for 10 MPa\)\. Got 24.5"),
    (dict(cohesion_Pa=49.0), r"'cohesion_Pa'.*>= 1000 Pa"),
    (dict(tensile_strength_Pa=24.5e6, cohesion_Pa=0.5), "'cohesion_Pa'"),
])
def test_bond_strengths_in_mpa_are_refused(kwargs, match):
    """The calibration file keeps MPa: 24.5 (MPa) given as Pa made bonds a million times too weak."""
    with pytest.raises(DemInputError, match=match):
        BondParams(**kwargs)


def test_a_bond_stiffness_that_means_no_solid_is_refused():
    """k_n 22683 (the calibration file's GPa/m) gave these 1-mm spheres a bond modulus of 45 Pa; 1e18
    (Pa/mm) one of 2e15 Pa, a thousand times diamond's. Both ran."""
    for kn in (22683.0, 1e18):
        with pytest.raises(DemInputError, match=r"'kn_Pa_m'.*bond modulus k_n \(R_i \+ R_j\) in \[10000, 1.2e\+12\]"):
            BondSet([[0, 1]], THREE, np.full(3, R), BondParams(kn_Pa_m=kn, ks_Pa_m=0.4 * kn))
    kn = kn_from_modulus_Pa_m(30e9, R)
    assert BondSet([[0, 1]], THREE, np.full(3, R), BondParams(kn_Pa_m=kn, ks_Pa_m=0.4 * kn)).n_bonds == 1
    with pytest.raises(DemInputError, match=r"'youngs_modulus_Pa'.*30e9 for 30 GPa"):
        BondParams.yade_jcfpm(30.0, 0.4, 10e6, 20e6, 30.0)


# ---------------------------------------------------------------- packings
def test_a_packing_reports_the_overlap_it_returns():
    """max_overlap_rel was the largest overlap seen before the last relaxation pass moved the spheres
    (and a boundary estimate): 0.217 for a packing whose spheres overlap by 0.220 of the mean radius."""
    agg = make_agglomerate(0.022, 30, random_state=2)
    p, r = agg.pos_m, agg.radius_m
    i, j = np.triu_indices(agg.n_spheres, 1)
    measured = np.max(r[i] + r[j] - np.linalg.norm(p[j] - p[i], axis=1)) / np.mean(r)
    assert measured > 0.1                    # few spheres at the target fraction: it does not relax
    assert agg.max_overlap_rel == pytest.approx(measured, rel=1e-12)


def test_a_particle_diameter_in_mm_is_refused():
    """make_agglomerate(22, ...) packed a 22-m particle, and the lab tests broke it, silently."""
    with pytest.raises(DemInputError, match=r"'diameter_m'.*\(0, 1\] m \(0.022 for 22 mm\). Got 22"):
        make_agglomerate(22, 30)
