"""Parallel kernels: one and two threads give bit-identical results (bonds breaking, contacts
forming, platens, the drum with lifters), and the Verlet list carries contact histories over."""

import numba
import numpy as np
import pytest

from dem.agglomerate import make_agglomerate, morton_order
from dem.bonds import BondParams, BondSet, kn_from_modulus_Pa_m
from dem.drum import drum_system
from dem.materials import Material
from dem.system import PlaneWall, System

from . import in_fresh_interpreter

if numba.config.NUMBA_NUM_THREADS < 2:  # a machine configuration, not our code
    pytest.fail("these tests need NUMBA_NUM_THREADS >= 2 (numba found "
                f"{numba.config.NUMBA_NUM_THREADS}); set it, numba then runs two threads on any core count")


@pytest.fixture(autouse=True)
def _parallel_at_any_size(monkeypatch):
    """These systems are small: run them on the threads asked for, not serially by size."""
    import dem.system

    monkeypatch.setattr(dem.system, "PARALLEL_MIN_SPHERES", 0)


def _crushed(threads):
    """A weak agglomerate crushed fast: bonds break, broken pairs come into frictional contact."""
    agg = make_agglomerate(0.01, 120, random_state=4)
    kn = kn_from_modulus_Pa_m(30e9, agg.mean_radius_m)
    bp = BondParams(kn_Pa_m=kn, ks_Pa_m=0.4 * kn, tensile_strength_Pa=2e6, cohesion_Pa=4e6)
    pos = agg.pos_m.copy()
    bs = BondSet(agg.bond_pairs, pos, agg.radius_m, bp)
    z_lo = float(np.min(pos[:, 2] - agg.radius_m))
    z_hi = float(np.max(pos[:, 2] + agg.radius_m))
    walls = [PlaneWall((0, 0, z_lo), (0, 0, 1)), PlaneWall((0, 0, z_hi), (0, 0, -1), (0, 0, -2.0))]
    numba.set_num_threads(threads)
    try:
        s = System(pos, agg.radius_m, Material(), bonds=bs, walls=walls, local_damping=0.3,
                   time_step_factor=0.5)
        s.run(2500)
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return s


def test_one_and_two_threads_are_bit_identical_while_bonds_break():
    a, b = _crushed(1), _crushed(2)
    # the run exercised every path: bonds broke, a broken pair touches, the platen carries load
    assert np.sum(a.bonds.state != 0) > 20
    assert np.sum(a.pairs.touch[a.pairs.bond >= 0]) > 0
    assert a.record_arrays()["wall_force_N"][:, 1].max() > 0
    for name in ("pos", "vel", "omega", "force", "torque"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    np.testing.assert_array_equal(a.bonds.state, b.bonds.state)
    np.testing.assert_array_equal(a.bonds.fs, b.bonds.fs)
    np.testing.assert_array_equal(a.pairs.xi, b.pairs.xi)
    np.testing.assert_array_equal(a.record_arrays()["wall_force_N"], b.record_arrays()["wall_force_N"])


def test_drum_is_bit_identical_on_one_and_two_threads():
    out = []
    for threads in (1, 2):
        numba.set_num_threads(threads)
        try:
            s = drum_system(0.7, 0.3, ball_diameter_m=0.04, section_length_m=0.1, random_state=2).system
            s.run(3000)
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        out.append(s)
    a, b = out
    assert a.hist_pp.sum() > 0 and a.hist_pw.sum() > 0  # collisions were counted
    assert np.any(a.record_arrays()["torque_Nm"] != 0)  # the shell's torque reached the record
    np.testing.assert_array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(a.hist_pp, b.hist_pp)
    np.testing.assert_array_equal(a.hist_pw, b.hist_pw)
    np.testing.assert_array_equal(a.record_arrays()["torque_Nm"], b.record_arrays()["torque_Nm"])


def test_contact_history_survives_a_neighbour_list_rebuild():
    """A rebuilt Verlet list carries each listed pair's tangential spring and contact flag over
    (a reset would zero the spring of a sliding contact at every rebuild)."""
    from dem import kernels as K

    r = 1e-3
    mat = Material(friction_coef=10.0, restitution=1.0)
    # three spheres in a row: pairs (0, 1) in contact, (1, 2) listed but apart
    s = System([[0, 0, 0], [2 * r * (1 - 1e-4), 0, 0], [4.02 * r, 0, 0]], [r, r, r], mat,
               skin_fraction=0.1, time_step_factor=0.1)
    s.vel[1, 1] = 1.0
    s.run(3)
    old = s.pairs
    k_old = int(np.nonzero((old.i == 0) & (old.j == 1))[0][0])
    assert old.touch[k_old] == 1 and np.linalg.norm(old.xi[k_old]) > 0
    s.pos[2, 2] += 1e-4            # change the list: the new one has other rows
    new = K.rebuild_pairs(s.spheres, s.bonds.arrays, old, s.cp[K.CP_SKIN], 0.0)
    k_new = int(np.nonzero((new.i == 0) & (new.j == 1))[0][0])
    assert new.touch[k_new] == 1
    np.testing.assert_array_equal(new.xi[k_new], old.xi[k_old])
    others = [k for k in range(new.i.shape[0]) if k != k_new]
    assert all(new.touch[k] == 0 and not np.any(new.xi[k]) for k in others)


def test_morton_order_keeps_neighbours_near_in_index():
    rng = np.random.default_rng(0)
    pos = rng.uniform(0, 1, (4000, 3))
    order = morton_order(pos, 0.05)
    assert sorted(order.tolist()) == list(range(4000))
    step = np.linalg.norm(np.diff(pos[order], axis=0), axis=1)
    step_random = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    assert np.median(step) < 0.25 * np.median(step_random)


def _layer_in_subprocess(**env):
    """The threading layer numba used for a small System run in a fresh interpreter."""
    code = ("import numba; from dem.system import System; from dem.materials import Material; "
            "s = System([[0, 0, 0], [3e-3, 0, 0]], [1e-3, 1e-3], Material()); s.run(2); "
            "print(numba.threading_layer())")
    return in_fresh_interpreter(code, ("NUMBA_THREADING_LAYER",), **env)


def test_openmp_is_the_threading_layer_unless_the_user_chooses():
    assert _layer_in_subprocess() == "omp"
    assert _layer_in_subprocess(NUMBA_THREADING_LAYER="workqueue") == "workqueue"
