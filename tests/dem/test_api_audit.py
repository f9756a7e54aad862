"""The DEM's public API refuses what a user plausibly gets wrong, by name and before any step,
and reports a blow-up instead of returning its numbers (an audit of dem's entry points)."""

import math

import numpy as np
import pytest

from dem import calibrate as calibrate_module
from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams, BondSet, find_bond_pairs
from dem.calibrate import BondCalibrator
from dem.drum import drum_system
from dem.errors import DemInputError, DemInstabilityError
from dem.fragments import find_fragments
from dem.lab import compression_test
from dem.materials import Material
from dem.system import DrumGeometry, PlaneWall, System

R = 1e-3
TWO = [[0.0, 0.0, 0.0], [2.1 * R, 0.0, 0.0]]
THREE = np.array([[0.0, 0.0, 0.0], [2 * R, 0.0, 0.0], [4 * R, 0.0, 0.0]])


# ---------------------------------------------------------------- spheres
def test_positions_of_the_wrong_shape_are_refused_not_reshaped():
    """A (3, 2) array of six numbers was read as two spheres' centres."""
    with pytest.raises(DemInputError, match=r"'pos_m'.*\(n, 3\).*\(3, 2\)"):
        System(np.zeros((3, 2)), [R, R], Material())
    with pytest.raises(DemInputError, match=r"'pos_m'.*\(n, 3\)"):
        System(np.arange(6.0) * 3 * R, [R, R], Material())
    with pytest.raises(DemInputError, match="'pos_m'"):
        System(np.zeros((2, 4)), [R, R], Material())


@pytest.mark.parametrize("pos, rad", [
    ([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], [R, R]),            # coincident centres: no contact normal
    ([[0.0, 0.0, 0.0], [2.1e-3, 0.0, 0.0]], [1.0, 1.0]),      # centres in m, radii in mm
])
def test_a_centre_inside_another_sphere_is_refused_at_construction(pos, rad):
    """Coincident centres were run and reported as an instability at step 0 ('reduce
    time_step_factor'), a unit mix-up as an explosion or silently."""
    with pytest.raises(DemInputError, match=r"spheres 0 and 1 .*same unit"):
        System(pos, rad, Material())


def test_a_force_gone_non_finite_in_the_last_step_is_reported():
    """Spheres 1 and 3 (not among the three numbers the kernel samples after a step's forces)
    meet at the same point in the call's only step: their force, then their velocity, is NaN.
    The run returned normally with that state."""
    dt = 2.0 ** -24
    a = 2.0 ** -8
    pos = [[0.0, 0.1, 0.0], [-a, 0.0, 0.0], [0.0, 0.2, 0.0], [a, 0.0, 0.0], [0.0, 0.3, 0.0]]
    s = System(pos, [R] * 5, Material(), dt_s=dt)
    s.vel[1, 0] = a / dt
    s.vel[3, 0] = -a / dt
    with pytest.raises(DemInstabilityError, match="Non-finite state at step 1"):
        s.run(1)


@pytest.mark.parametrize("n_steps", [2.7, -5, float("nan"), "10", True])
def test_a_step_count_that_is_not_a_whole_number_is_refused(n_steps):
    """2.7 ran 2 steps and -5 none, silently."""
    s = System(TWO, [R, R], Material())
    with pytest.raises(DemInputError, match="'n_steps'"):
        s.run(n_steps)


def test_a_whole_float_step_count_runs():
    s = System(TWO, [R, R], Material())
    s.run(1e1)
    assert s.steps == 10


# ---------------------------------------------------------------- materials and options
@pytest.mark.parametrize("kwargs, match", [
    (dict(youngs_modulus_Pa=30.0), r"'youngs_modulus_Pa'.*30e9 for 30 GPa"),
    (dict(density_kg_m3=2.7), r"'density_kg_m3'.*2700 for 2.7 g/cm3"),
    (dict(youngs_modulus_Pa="30e9"), r"'youngs_modulus_Pa'.*must be a float"),
])
def test_material_units_and_types_are_checked(kwargs, match):
    with pytest.raises(DemInputError, match=match):
        Material(**kwargs)


@pytest.mark.parametrize("kwargs, match", [
    (dict(periodic_z_m=-0.01), "'periodic_z_m'"),
    (dict(periodic_z_m=float("nan")), "'periodic_z_m'"),
    (dict(periodic_z_m=1e-3), r"'periodic_z_m'.*two largest sphere diameters"),
    (dict(skin_fraction=float("nan")), "'skin_fraction'"),
    (dict(skin_fraction=-1.0), "'skin_fraction'"),
    (dict(gravity_m_s2=(0.0, -9.81)), "'gravity_m_s2'"),
    (dict(gravity_m_s2=(0.0, float("nan"), 0.0)), "'gravity_m_s2'"),
    (dict(density_kg_m3=2.7), r"'density_kg_m3' parameter of System"),
    (dict(wall_material="steel"), "'wall_material'"),
    (dict(walls=[PlaneWall((0, 0, -R), (0, 0, 0))]), r"'walls\[0\].normal'"),
    (dict(walls=[PlaneWall((0, 0, math.nan), (0, 0, 1))]), r"'walls\[0\].point_m'"),
    (dict(walls=[PlaneWall((0, 0, -R), (0, 0, 1), mass_kg=-1.0)]), r"'walls\[0\].mass_kg'"),
    (dict(drum=DrumGeometry(0.1, math.nan)), "'drum.omega_rad_s'"),
    (dict(drum=DrumGeometry(0.1, 1.0, n_lifters=-1)), "'drum.n_lifters'"),
    (dict(drum=DrumGeometry(0.1, 1.0, n_lifters=2.5)), "'drum.n_lifters'"),
    (dict(drum=DrumGeometry(1e-3, 1.0)), r"'pos_m'.*inside the drum.*sphere 1"),
])
def test_system_options_are_checked_before_any_step(kwargs, match):
    """Each was run silently (a negative or NaN period as no period, a NaN skin, a negative wall
    mass as a fixed wall, a NaN drum speed, spheres outside the shell), failed with a raw
    numpy/Python error, or as an instability at step 0."""
    with pytest.raises(DemInputError, match=match):
        System(TWO, [R, R], Material(), **kwargs)


# ---------------------------------------------------------------- bonds
def test_a_bond_set_for_other_spheres_is_refused():
    """A BondSet of 3 spheres in a System of 4 read its tables out of bounds (a segmentation
    fault); one of 3 in a System of 2 failed with an IndexError."""
    bs = BondSet([[0, 1], [1, 2]], THREE, np.full(3, R), BondParams())
    four = np.vstack([THREE, [[6 * R, 0, 0]]])
    with pytest.raises(DemInputError, match=r"'bonds'.*its 4 spheres.*made for 3"):
        System(four, np.full(4, R), Material(), bonds=bs)
    with pytest.raises(DemInputError, match=r"'bonds'.*its 2 spheres.*made for 3"):
        System(THREE[:2], [R, R], Material(), bonds=bs)


def test_a_bond_set_made_at_other_positions_is_refused():
    """Its bonds would start stretched: pre-stressed, broken at once, silently."""
    bs = BondSet([[0, 1], [1, 2]], THREE, np.full(3, R), BondParams())
    moved = THREE * np.array([1.2, 1.0, 1.0])
    with pytest.raises(DemInputError, match=r"'bonds'.*bond 0 .*made 0.002 m long.*0.0024 m apart"):
        System(moved, np.full(3, R), Material(), bonds=bs)
    System(THREE + 1.0, np.full(3, R), Material(), bonds=bs)  # moved as a whole: the same bonds


@pytest.mark.parametrize("pairs, match", [
    ([[1, 1]], "two different spheres"),           # a bond of zero length
    ([[0, 5]], r"two different spheres of \[0, 3\)"),
    ([[0, -1]], "two different spheres"),
    ([[0, 1], [1, 0]], "each pair once"),          # a double bond, twice as stiff
    ([[0.7, 1.2]], "whole sphere indices"),        # read as [0, 1]
    ([0, 1, 2], "whole sphere indices"),
])
def test_bond_pairs_are_checked(pairs, match):
    with pytest.raises(DemInputError, match=match):
        BondSet(pairs, THREE, np.full(3, R), BondParams())


def test_bond_set_arguments_are_checked():
    with pytest.raises(DemInputError, match="'params'"):
        BondSet([[0, 1]], THREE, np.full(3, R), None)
    with pytest.raises(DemInputError, match="'radius_m'"):
        BondSet([[0, 1]], THREE, np.full(2, R), BondParams())
    with pytest.raises(DemInputError, match="'kn_Pa_m'.*must be a float"):
        BondParams(kn_Pa_m="1e13")
    BondSet([[0, 1]], THREE.tolist(), [R, R, R], BondParams())  # lists are taken


@pytest.mark.parametrize("pos, rad, match", [
    (THREE, np.full(2, R), "'radius_m'"),
    (np.array([[math.nan, 0, 0], [0, 0, 0]]), np.full(2, R), "'pos_m'"),
    (np.zeros((0, 3)), np.zeros(0), "'pos_m'"),
])
def test_find_bond_pairs_checks_its_spheres(pos, rad, match):
    with pytest.raises(DemInputError, match=match):
        find_bond_pairs(pos, rad)


# ---------------------------------------------------------------- fragments
def test_bond_state_codes_are_not_taken_for_intact_flags():
    """``BondSet.state`` (0 = intact) passed as ``intact`` counted the intact bonds as broken and
    the broken ones as intact."""
    state = np.array([0, 1], dtype=np.int8)   # bond 0 intact, bond 1 broken in tension
    with pytest.raises(DemInputError, match=r"'intact'.*booleans.*state codes"):
        find_fragments([[0, 1], [1, 2]], state, [1.0, 1.0, 1.0], 1.0)
    assert find_fragments([[0, 1], [1, 2]], state == 0, [1.0, 1.0, 1.0], 1.0).n_fragments == 2


@pytest.mark.parametrize("kwargs, match", [
    (dict(sphere_volume_m3=[-1.0, 1.0, 1.0]), "'sphere_volume_m3'"),
    (dict(sphere_volume_m3=[math.nan, 1.0, 1.0]), "'sphere_volume_m3'"),
    (dict(sphere_volume_m3=[0.0, 0.0, 0.0]), "'sphere_volume_m3'"),
    (dict(bond_pairs=[[0, 5]]), "'bond_pairs'"),
    (dict(bond_pairs=[[0.5, 1.5]]), "'bond_pairs'"),
    (dict(original_size_m=math.inf), "'original_size_m'"),
    (dict(n_sieves=0), "'n_sieves'"),
])
def test_find_fragments_checks_its_inputs(kwargs, match):
    """Negative, NaN or zero volumes gave NaN or negative mass fractions; an infinite size gave
    t10 = 0; out-of-range pairs an IndexError; n_sieves 0 an empty distribution."""
    args = dict(bond_pairs=[[0, 1]], intact=[False], sphere_volume_m3=[1.0, 1.0, 1.0], original_size_m=1.0)
    args.update(kwargs)
    with pytest.raises(DemInputError, match=match):
        find_fragments(args.pop("bond_pairs"), args.pop("intact"), args.pop("sphere_volume_m3"),
                       args.pop("original_size_m"), **args)


# ---------------------------------------------------------------- packings, tests, calibration
@pytest.mark.parametrize("kwargs, match", [
    (dict(max_passes=20), r"'max_passes'.*\[410,"),   # returned unrelaxed, overlap at 62 % radii
    (dict(max_passes=0), "'max_passes'"),             # max_overlap_rel = inf
    (dict(random_state=-1), "'random_state'"),
    (dict(random_state=0.5), "'random_state'"),
])
def test_make_agglomerate_checks_its_schedule_and_seed(kwargs, match):
    with pytest.raises(DemInputError, match=match):
        make_agglomerate(0.022, 30, **kwargs)


def test_lab_tests_check_particle_bonds_and_chunks():
    """chunk_steps 0 failed with an IndexError after the System was built; a tuple for the
    agglomerate or None for the bonds with AttributeError."""
    agg = make_agglomerate(0.006, 30, random_state=3)
    with pytest.raises(DemInputError, match="'chunk_steps' parameter of compression_test"):
        compression_test(agg, BondParams(), chunk_steps=0)
    with pytest.raises(DemInputError, match="'agglomerate' parameter of compression_test"):
        compression_test((agg.pos_m, agg.radius_m), BondParams())
    with pytest.raises(DemInputError, match="'bonds' parameter of compression_test"):
        compression_test(agg, None)


@pytest.mark.parametrize("kwargs, match", [
    (dict(local_damping=1.5), "'local_damping' parameter of BondCalibrator"),
    (dict(platen_speed_m_s=50.0), "'platen_speed_m_s' parameter of BondCalibrator"),
    (dict(time_step_factor=2.0), "'time_step_factor' parameter of BondCalibrator"),
    (dict(moment_factor=2.0), "'moment_factor'"),
    (dict(material="rock"), "'material' parameter of BondCalibrator"),
    (dict(bond_modulus_Pa=30.0), "'bond_modulus_Pa'"),   # 30 GPa given in GPa
])
def test_calibrator_refuses_bad_options_before_making_packings(kwargs, match, monkeypatch):
    def no_packing(*a, **k):
        raise AssertionError("a packing was made before the options were checked")
    monkeypatch.setattr(calibrate_module, "make_agglomerate", no_packing)
    with pytest.raises(DemInputError, match=match):
        BondCalibrator(n_particles=2, spheres_per_particle=30, **kwargs).fit(100.0)


def test_drum_system_checks_its_seed():
    with pytest.raises(DemInputError, match="'random_state' parameter of drum_system"):
        drum_system(0.7, 0.3, random_state=0.5)
