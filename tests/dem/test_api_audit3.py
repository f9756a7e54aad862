"""A third audit of the DEM's public API: a test that never broke the particle reported a strength, a
packing its bonds did not hold together, and inputs taken as text, bools, mm or dicts that failed far
from where they were given. Each test failed on the code before its fix."""

import math

import numpy as np
import pytest

import dem
from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams
from dem.calibrate import BondCalibrator
from dem.drum import critical_speed_rad_s, drum_test
from dem.errors import DemInputError, UnfracturedWarning
from dem.fragments import find_fragments
from dem.lab import compression_test, drop_weight_test


@pytest.fixture(scope="module")
def small():
    return make_agglomerate(0.022, 60, random_state=2)


def test_a_compression_that_never_breaks_the_particle_says_so(small):
    """Bonds 60x the default: the test ran to the end of travel and reported its 62 kN as the peak force and
    fracture energy, with nothing to say the particle was whole."""
    with pytest.warns(UnfracturedWarning, match=r"the particle did not fracture within max_strain = 0.08 \(1.72 mm "
                                                r"of platen travel\): the peak force 6.\d+e\+04 N"):
        whole = compression_test(small, BondParams().scaled(60.0))
    assert not whole.fractured and whole.summary()["fractured"] is False
    assert whole.fragments.n_fragments == 1
    broken = compression_test(small, BondParams())
    assert broken.fractured and broken.fragments.largest_mass_fraction < 0.9


def test_a_packing_its_bonds_do_not_hold_together_is_refused():
    # a bond distance factor of 1 left loose spheres: the "intact" particle was found in 2-7 pieces
    with pytest.raises(DemInputError, match=r"'bond_distance_factor' parameter of make_agglomerate leaves the "
                                            r"packing in 3 pieces \(2 spheres outside the largest\)"):
        make_agglomerate(0.022, 300, random_state=1, bond_distance_factor=1.0)


@pytest.mark.parametrize("call, match", [
    (lambda a: make_agglomerate(0.022, 50, radius_spread="0.2"),
     "'radius_spread' parameter of make_agglomerate must be a float. Got '0.2'"),
    (lambda a: make_agglomerate("abc"), "'diameter_m' parameter of make_agglomerate must be a float. Got 'abc'"),
    (lambda a: drum_test("0.7", 0.35), "'speed_frac_critical' parameter of drum_test must be a float. Got '0.7'"),
    (lambda a: compression_test(a, BondParams(), platen_speed_m_s="abc"),
     "'platen_speed_m_s' parameter of compression_test must be a float. Got 'abc'"),
    (lambda a: drop_weight_test(a, BondParams(), np.array([100.0])),
     r"'specific_energy_J_kg' parameter of drop_weight_test must be a float. Got array\(\[100.\]\)"),
    (lambda a: compression_test(a, BondParams(), material={"youngs_modulus_Pa": 1e9}),
     "'material' parameter of compression_test must be a dem.Material"),
    (lambda a: find_fragments(a.bond_pairs, np.ones(a.n_bonds, bool), a.radius_m ** 3, "0.022"),
     "'original_size_m' parameter of find_fragments must be a float. Got '0.022'"),
    (lambda a: find_fragments(np.array([[0, 0]]), np.array([True]), np.ones(2), 0.022),
     r"'bond_pairs' parameter of find_fragments must pair two spheres; rows \[0\] bond a sphere to itself"),
    (lambda a: critical_speed_rad_s(500, 25), r"'mill_diameter_m' parameter of critical_speed_rad_s must be a float "
                                              r"in \(0.0, 20.0\]. Got 500"),
    (lambda a: drum_test(0.7, 0.35, mill_diameter_m=0.02),
     r"'ball_diameter_m' parameter must be a float in \(0, mill_diameter_m=0.02\)"),
    (lambda a: BondParams(radius_multiplier=100.0),
     r"'radius_multiplier' parameter of BondParams must be a float in \(0, 1\]"),
    (lambda a: BondCalibrator(n_particles=True).fit(4200.0), r"'n_particles' parameter of BondCalibrator must be an "
                                                             r"int in \(0, 10000\]. Got True"),
])
def test_an_input_of_the_wrong_kind_is_refused_where_it_is_given(small, call, match):
    with pytest.raises(DemInputError, match=match):
        call(small)


def test_the_face_exports_the_warning():
    assert dem.UnfracturedWarning is UnfracturedWarning and math.isfinite(critical_speed_rad_s(0.5, 0.025))


def test_a_bond_fit_to_end_of_travel_forces_is_refused(monkeypatch, small):
    """BondCalibrator.fit took a particle's end-of-travel force as its peak (no fracture), and fitted it."""
    from types import SimpleNamespace

    from dem.errors import DemError

    cal = BondCalibrator(n_particles=2, spheres_per_particle=60, max_iter=1)
    monkeypatch.setattr(BondCalibrator, "particle", lambda self, k: small)
    monkeypatch.setattr(BondCalibrator, "run", lambda self, aggs, params: [
        SimpleNamespace(peak_force_N=4200.0, stiffness_N_m=1e6, fractured=k == 0) for k in range(len(aggs))])
    with pytest.raises(DemError, match=r"particles \[1\] of the best iteration \(1\) did not fracture"):
        cal.fit(4200.0)
