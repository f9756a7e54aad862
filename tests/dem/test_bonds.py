"""Parallel bonds: k A du, failure exactly at strength, reference match, energy conservation."""

import math

import numpy as np
import pytest

from dem.bonds import (BOND_BLOCK, BROKEN_SHEAR, BROKEN_SHEAR_SLIDING, BROKEN_TENSION, INTACT, N_ROWS, P_AREA,
                       P_LENGTH0, BondParams, BondSet, bond_block, bond_step, find_bond_pairs)
from dem.errors import DemInputError, DemInstabilityError
from dem.materials import Material
from dem.reference import reference_bond
from dem.state import LOAD_F, LOAD_TI, LOAD_TJ, N_FORCE
from dem.system import System

R = 1e-3
KN = 1e13
KS = 4e12


def _pair(params, gap=0.0):
    pos = np.array([[0.0, 0.0, 0.0], [2 * R + gap, 0.0, 0.0]])
    rad = np.array([R, R])
    return pos, rad, BondSet(np.array([[0, 1]]), pos, rad, params)


def _apply(pos, rad, bs, vel, omega=None, dt=1e-7):
    """Move by vel*dt and update the bond (what the integrator does), return forces, torques
    (from the bond's load row: force on j, torque on i, torque on j; see dem.state)."""
    omega = np.zeros((2, 3)) if omega is None else omega
    pos += vel * dt
    nbr = bond_step(0, bs.ij, bs.props, bs.fn, bs.fs, bs.mb, bs.mt, bs.length, bs.state,
                    bs.arrays.load, pos, vel, omega, rad, 0.0, dt, bs.beta)
    row = bs.arrays.load[0]
    f = np.array([-row[LOAD_F:LOAD_F + 3], row[LOAD_F:LOAD_F + 3]])
    if row.shape[0] == N_FORCE:  # central bonds: rows of forces through the centres, no torque
        return f, np.zeros((2, 3)), nbr
    t = np.array([row[LOAD_TI:LOAD_TI + 3], row[LOAD_TJ:LOAD_TJ + 3]])
    return f, t, nbr


def test_axial_displacement_gives_kn_A_du():
    p = BondParams(kn_Pa_m=KN, ks_Pa_m=KS, tensile_strength_Pa=1e12, cohesion_Pa=1e12)
    pos, rad, bs = _pair(p, gap=1e-4)
    area = math.pi * R**2
    du = 1e-7
    f, _, _ = _apply(pos, rad, bs, np.array([[0, 0, 0], [du / 1e-7, 0, 0]]))
    assert bs.fn[0] == pytest.approx(KN * area * du, rel=1e-9)
    # tension pulls j back (-x) and i forward (+x)
    assert f[1, 0] == pytest.approx(-KN * area * du, rel=1e-9)
    assert f[0, 0] == pytest.approx(KN * area * du, rel=1e-9)
    # compression is carried too
    _apply(pos, rad, bs, np.array([[0, 0, 0], [-3 * du / 1e-7, 0, 0]]))
    assert bs.fn[0] == pytest.approx(-2 * KN * area * du, rel=1e-9)


def test_shear_displacement_gives_minus_ks_A_du():
    p = BondParams(kn_Pa_m=KN, ks_Pa_m=KS, tensile_strength_Pa=1e12, cohesion_Pa=1e12,
                   moment_factor=0.0)
    pos, rad, bs = _pair(p)
    area = math.pi * R**2
    du = 1e-8
    f, t, _ = _apply(pos, rad, bs, np.array([[0, 0, 0], [0, du / 1e-7, 0]]))
    assert bs.fs[0, 1] == pytest.approx(-KS * area * du, rel=1e-6)
    assert f[1, 1] == pytest.approx(-KS * area * du, rel=1e-6)
    # the shear force acts at the bond centre: torques on both spheres about z
    assert t[1, 2] == pytest.approx(R * KS * area * du, rel=1e-5)
    assert t[0, 2] == pytest.approx(R * KS * area * du, rel=1e-5)


@pytest.mark.parametrize("ks, beta", [(KS, 1.0), (0.0, 0.0)], ids=["parallel", "central"])
def test_bond_breaks_exactly_at_tensile_strength(ks, beta):
    sig_t = 5e6
    p = BondParams(kn_Pa_m=KN, ks_Pa_m=ks, tensile_strength_Pa=sig_t, cohesion_Pa=1e12,
                   moment_factor=beta)
    pos, rad, bs = _pair(p)
    area = math.pi * R**2
    du = 1e-10
    vel = np.array([[0, 0, 0], [du / 1e-7, 0, 0]])
    last = 0.0
    for step in range(100000):
        _, _, nbr = _apply(pos, rad, bs, vel)
        if nbr:
            break
        last = bs.fn[0]
    assert bs.state[0] == BROKEN_TENSION
    # the last intact force is within one increment below the strength
    inc = KN * area * du
    assert sig_t * area - inc <= last <= sig_t * area
    assert bs.fn[0] == 0.0


def test_bond_breaks_exactly_at_cohesion_in_shear():
    coh = 4e6
    p = BondParams(kn_Pa_m=KN, ks_Pa_m=KS, tensile_strength_Pa=1e12, cohesion_Pa=coh,
                   moment_factor=0.0)
    pos, rad, bs = _pair(p)
    area = math.pi * R**2
    du = 1e-10
    vel = np.array([[0, 0, 0], [0, 0, du / 1e-7]])
    last = 0.0
    for _ in range(100000):
        _, _, nbr = _apply(pos, rad, bs, vel)
        if nbr:
            break
        last = np.linalg.norm(bs.fs[0])
    assert bs.state[0] == BROKEN_SHEAR
    assert coh * area - 1.01 * KS * area * du <= last <= coh * area


def test_mohr_coulomb_compression_raises_shear_strength():
    p0 = BondParams(kn_Pa_m=KN, ks_Pa_m=KS, tensile_strength_Pa=1e12, cohesion_Pa=4e6,
                    moment_factor=0.0)
    p30 = BondParams(kn_Pa_m=KN, ks_Pa_m=KS, tensile_strength_Pa=1e12, cohesion_Pa=4e6,
                     friction_angle_deg=30.0, moment_factor=0.0)
    out = []
    for p in (p0, p30):
        pos, rad, bs = _pair(p)
        _apply(pos, rad, bs, np.array([[0, 0, 0], [-2e-9 / 1e-7, 0, 0]]))  # compress first
        for n in range(1, 100000):
            _, _, nbr = _apply(pos, rad, bs, np.array([[0, 0, 0], [0, 1e-3, 0]]))
            if nbr:
                out.append(n)
                break
    assert out[1] > out[0]


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_bond_kernel_matches_reference(seed):
    rng = np.random.default_rng(seed)
    p = BondParams(kn_Pa_m=KN, ks_Pa_m=KS, tensile_strength_Pa=3e6, cohesion_Pa=4e6,
                   friction_angle_deg=20.0)
    pos, rad, bs = _pair(p, gap=2e-5)
    pos[1] += rng.normal(0, 1e-4, 3)
    bs = BondSet(np.array([[0, 1]]), pos, rad, p)
    area = bs.props[0, P_AREA]
    state = {"fn": 0.0, "fs": np.zeros(3), "mb": np.zeros(3), "mt": 0.0, "length": bs.length[0]}
    for _ in range(40):
        vel = rng.normal(0, 2e-3, (2, 3))
        om = rng.normal(0, 2.0, (2, 3))
        p_old = pos.copy()
        f, t, _ = _apply(pos, rad, bs, vel, om)
        state, f_j, t_i, t_j, mode = reference_bond(
            pos[0], pos[1], vel[0], vel[1], om[0], om[1], R, R, state, area=area, rbar=R, kn=KN,
            ks=KS, tensile=3e6, cohesion=4e6, tan_phi=math.tan(math.radians(20.0)), beta=1.0,
            dt=1e-7)
        assert mode == bs.state[0]
        if mode:
            break
        np.testing.assert_allclose(f[1], f_j, rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(t[0], t_i, rtol=1e-8, atol=1e-15)
        np.testing.assert_allclose(t[1], t_j, rtol=1e-8, atol=1e-15)
        assert p_old is not pos


@pytest.mark.parametrize("params", [BondParams(kn_Pa_m=KN, ks_Pa_m=KS, tensile_strength_Pa=2e7, cohesion_Pa=3e7,
                                               friction_angle_deg=20.0),
                                    BondParams.yade_jcfpm(30e9, 0.4, 1e7, 2e7, 30.0)], ids=["parallel", "jcfpm"])
def test_a_block_of_bonds_gives_each_bond_what_stepping_it_alone_gives(params):
    """The kernel steps bonds in blocks whose columns the compiler computes two at a time
    (dem.bonds.bond_block): every bond of every block, whatever its column, its state and its
    neighbours', must get exactly what stepping it alone gives (a column read from its neighbour,
    a block offset off by one or a broken bond's column written back would not)."""
    from dem.agglomerate import make_agglomerate

    agg = make_agglomerate(0.008, 60, random_state=1)
    n, m = agg.n_spheres, agg.bond_pairs.shape[0]
    assert m > 3 * BOND_BLOCK  # several blocks, the last one partly filled
    rng = np.random.default_rng(4)
    vel = rng.normal(0.0, 1.0, (n, 3))
    om = rng.normal(0.0, 3e3, (n, 3))
    sets = [BondSet(agg.bond_pairs, agg.pos_m, agg.radius_m, params) for _ in range(2)]
    for bs in sets:
        bs.state[::7] = BROKEN_TENSION
        bs.state[3::11] = BROKEN_SHEAR_SLIDING if params.convention == "yade_jcfpm" else BROKEN_SHEAR
        bs.state[BOND_BLOCK:2 * BOND_BLOCK] = BROKEN_TENSION  # a block of broken bonds, skipped
        bs.state[2 * BOND_BLOCK:3 * BOND_BLOCK - 1] = BROKEN_TENSION  # one whose last bond holds
    pos = [agg.pos_m.copy(), agg.pos_m.copy()]
    g = np.empty((N_ROWS, BOND_BLOCK))
    dt = 2e-7
    for _ in range(6):
        for p in pos:
            p += vel * dt
        a, b = sets
        for b0 in range(0, m, BOND_BLOCK):
            bond_block(b0, min(b0 + BOND_BLOCK, m), a.ij, a.props, a.fn, a.fs, a.mb, a.mt, a.length, a.state,
                       a.arrays.load, pos[0], vel, om, agg.radius_m, 0.0, dt, a.beta, False, g)
        for k in range(m):
            bond_step(k, b.ij, b.props, b.fn, b.fs, b.mb, b.mt, b.length, b.state, b.arrays.load, pos[1], vel,
                      om, agg.radius_m, 0.0, dt, b.beta)
    a, b = sets
    assert len(set(a.state.tolist())) >= 3  # intact, broken this run or before, (sliding)
    lone = 3 * BOND_BLOCK - 1  # stepped (its length stored), so its block was not skipped
    assert a.length[lone] != a.props[lone, P_LENGTH0]
    for name in ("fn", "fs", "mb", "mt", "length", "state", "props"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    np.testing.assert_array_equal(a.arrays.load, b.arrays.load)


def test_a_pickled_bond_set_gets_this_processs_scratch_tables_and_keeps_its_table_shared():
    """The block kernel's scratch tables are indexed by numba's thread id without a bounds check:
    a BondSet carried into another process (pickled) must get one table per thread of that
    process, not keep the tables of the one it came from; and its ``props`` must stay a view of
    the kernels' table (pickle would copy the view apart)."""
    import pickle

    import numba as nb
    from dem.agglomerate import make_agglomerate

    agg = make_agglomerate(0.008, 30, random_state=2)
    bs = BondSet(agg.bond_pairs, agg.pos_m, agg.radius_m, BondParams(kn_Pa_m=KN, ks_Pa_m=KS))
    bs.arrays = bs.arrays._replace(scratch=np.empty((0, N_ROWS, BOND_BLOCK)))  # as if from elsewhere
    c = pickle.loads(pickle.dumps(bs))
    threads, rows, block = c.arrays.scratch.shape
    assert threads == nb.config.NUMBA_NUM_THREADS and rows >= N_ROWS and block == BOND_BLOCK
    assert c.arrays.fn is c.fn and c.arrays.state is c.state
    c.arrays.props[0, P_AREA] = 123.0
    assert c.props[0, P_AREA] == 123.0 and c.props.shape == bs.props.shape
    np.testing.assert_array_equal(c.props[1:], bs.props[1:])


def test_each_threads_scratch_table_starts_a_page_and_fills_whole_pages():
    """Packed end to end at numpy's 16-byte alignment, the thread whose table followed another's
    ran its bond blocks slower: every table starts a page of its own, C-contiguous (the type the
    kernels are compiled for)."""
    import mmap

    from dem.bonds import _block_scratch

    s = _block_scratch()
    assert s.flags.c_contiguous and s.dtype == np.float64 and s.shape[1] >= N_ROWS
    assert s.strides[0] % mmap.PAGESIZE == 0
    assert all(s[t].ctypes.data % mmap.PAGESIZE == 0 for t in range(s.shape[0]))


def test_energy_drift_without_damping_or_breakage():
    """Velocity Verlet: |E(t) - E(0)| / E(0) < 1e-4 over 1e4 steps and no secular drift."""
    from dem.agglomerate import make_agglomerate

    agg = make_agglomerate(0.006, 40, random_state=3)
    p = BondParams(kn_Pa_m=KN, ks_Pa_m=KS, tensile_strength_Pa=1e15, cohesion_Pa=1e15)
    bs = BondSet(agg.bond_pairs, agg.pos_m, agg.radius_m, p)
    mat = Material(restitution=1.0, friction_coef=0.0)
    s = System(agg.pos_m.copy(), agg.radius_m, mat, bonds=bs, time_step_factor=0.03)
    rng = np.random.default_rng(0)
    s.vel[:] = rng.normal(0, 0.05, s.vel.shape)
    s.omega[:] = rng.normal(0, 20.0, s.omega.shape)
    s._forces(0.0)
    e0 = s.total_energy_J()
    rel = []
    for _ in range(100):
        s.run(100)
        rel.append((s.total_energy_J() - e0) / e0)
    rel = np.array(rel)
    assert np.all(bs.state == INTACT)
    assert np.max(np.abs(rel)) < 1e-4
    # no secular drift: late and early means agree far better than the bound
    assert abs(np.mean(rel[-20:]) - np.mean(rel[:20])) < 1e-5
    # and the energy did flow into the bonds (the test is not trivial)
    assert bs.elastic_energy_J() > 0.05 * e0


def test_find_bond_pairs_uses_distance_factor():
    pos = np.array([[0, 0, 0], [2.5e-3, 0, 0], [2.7e-3, 0, 0]], dtype=float)
    rad = np.array([1e-3, 1e-3, 1e-3])
    pairs = find_bond_pairs(pos, rad, 1.3)
    assert [tuple(x) for x in pairs] == [(0, 1), (1, 2)]
    with pytest.raises(DemInputError, match="bond_distance_factor"):
        find_bond_pairs(pos, rad, 3.0)


def test_bond_params_validation():
    with pytest.raises(DemInputError, match="tensile_strength_Pa"):
        BondParams(tensile_strength_Pa=0.0)
    with pytest.raises(DemInputError, match="moment_factor"):
        BondParams(moment_factor=2.0)
    with pytest.raises(DemInputError, match=r"ks_Pa_m.*or 0 for a central bond.*-1"):
        BondParams(ks_Pa_m=-1.0)
    with pytest.raises(DemInputError, match="ks_Pa_m"):
        BondParams.yade_jcfpm(30e9, 0.0, 1e6, 1e6, 30.0)


# ---------------------------------------------------------------- central bonds (k_s = 0)
CENTRAL = dict(kn_Pa_m=KN, ks_Pa_m=0.0, cohesion_Pa=1e12, moment_factor=0.0)


def test_central_bond_is_a_normal_spring_with_no_shear_and_no_torque():
    pos, rad, bs = _pair(BondParams(tensile_strength_Pa=1e12, **CENTRAL), gap=1e-4)
    assert bs.central and bs.arrays.load.shape == (1, N_FORCE)  # no torque columns at all
    area = math.pi * R**2
    du = 1e-7
    f, t, _ = _apply(pos, rad, bs, np.array([[0, 0, 0], [du / 1e-7, 0, 0]]))
    assert bs.fn[0] == pytest.approx(KN * area * du, rel=1e-9)
    assert f[1, 0] == pytest.approx(-KN * area * du, rel=1e-9)
    # sideways motion: the spring turns with the line of centres, no shear force, no torque
    omega = np.array([[0, 0, 0], [0, 0, 3.0]])
    f, t, _ = _apply(pos, rad, bs, np.array([[0, 0, 0], [0, 0.05, 0]]), omega)
    axis = (pos[1] - pos[0]) / np.linalg.norm(pos[1] - pos[0])
    np.testing.assert_allclose(np.cross(f[1], axis), 0.0, atol=1e-12 * np.linalg.norm(f[1]))
    assert np.all(t == 0.0) and np.all(bs.fs == 0.0)


def test_central_bond_path_matches_the_full_bond_with_a_vanishing_shear_spring():
    """The fast path and the general bond kernel with k_s -> 0 load a packing alike."""
    from dem.agglomerate import make_agglomerate
    from dem.bonds import kn_from_modulus_Pa_m
    from dem.system import PlaneWall

    agg = make_agglomerate(0.01, 120, random_state=4)
    kn = kn_from_modulus_Pa_m(30e9, agg.mean_radius_m)
    forces = []
    for ks in (0.0, 1e-12 * kn):
        bp = BondParams(kn_Pa_m=kn, ks_Pa_m=ks, tensile_strength_Pa=1e9, cohesion_Pa=1e9,
                        moment_factor=0.0)
        pos = agg.pos_m.copy()
        z_lo = float(np.min(pos[:, 2] - agg.radius_m))
        z_hi = float(np.max(pos[:, 2] + agg.radius_m))
        walls = [PlaneWall((0, 0, z_lo), (0, 0, 1)), PlaneWall((0, 0, z_hi), (0, 0, -1), (0, 0, -0.5))]
        s = System(pos, agg.radius_m, Material(), bonds=BondSet(agg.bond_pairs, pos, agg.radius_m, bp),
                   walls=walls, local_damping=0.3, time_step_factor=0.5)
        s.run(1500)
        assert not np.any(s.bonds.state)
        forces.append(s.record_arrays()["wall_force_N"][:, 1])
    assert forces[0].max() > 0
    np.testing.assert_allclose(forces[0], forces[1], rtol=1e-6, atol=1e-9 * forces[0].max())


# ---------------------------------------------------------------- Yade JCFpm mirror convention
E_YADE = 30e9


def _yade_pair(r1, r2, tensile=1e12, cohesion=1e12, phi=30.0):
    p = BondParams.yade_jcfpm(E_YADE, 0.4, tensile, cohesion, phi)
    pos = np.array([[0.0, 0.0, 0.0], [r1 + r2, 0.0, 0.0]])
    rad = np.array([r1, r2])
    return pos, rad, BondSet(np.array([[0, 1]]), pos, rad, p)


def test_yade_bond_stiffness_is_2E_R1R2_over_R1_plus_R2_per_bond():
    """Yade's Ip2_JCFpmMat_JCFpmMat_JCFpmPhys: k_n = 2 E R1 R2 / (R1 + R2) [N/m], k_s = 0.4 k_n."""
    r1, r2 = 1e-3, 1.5e-3
    pos, rad, bs = _yade_pair(r1, r2)
    kn = 2 * E_YADE * r1 * r2 / (r1 + r2)
    du = 1e-9
    _apply(pos, rad, bs, np.array([[0, 0, 0], [du / 1e-7, 0, 0]]))
    assert bs.fn[0] == pytest.approx(kn * du, rel=1e-6)
    _apply(pos, rad, bs, np.array([[0, 0, 0], [-du / 1e-7, 0, du / 1e-7]]))  # back, then shear
    assert np.linalg.norm(bs.fs[0]) == pytest.approx(0.4 * kn * du, rel=1e-3)


def test_yade_bond_breaks_at_tensile_strength_times_min_radius_area():
    r1, r2 = 1e-3, 1.5e-3
    sig_t = 5e6
    pos, rad, bs = _yade_pair(r1, r2, tensile=sig_t)
    area = math.pi * min(r1, r2) ** 2
    kn = 2 * E_YADE * r1 * r2 / (r1 + r2)
    du = 1e-11
    last = 0.0
    for _ in range(200000):
        _, _, nbr = _apply(pos, rad, bs, np.array([[0, 0, 0], [du / 1e-7, 0, 0]]))
        if nbr:
            break
        last = bs.fn[0]
    assert bs.state[0] == BROKEN_TENSION
    assert sig_t * area - kn * du <= last <= sig_t * area


def test_yade_shear_strength_grows_with_compression_and_leaves_a_frictional_contact():
    """JCFpm: shear strength c A + F_n tan(phi) with compression positive; a bond broken in shear
    under compression stays a Coulomb contact |F_s| = F_n tan(phi)."""
    from dem.bonds import BROKEN_SHEAR_SLIDING

    r = 1e-3
    coh, phi = 4e6, 30.0
    area = math.pi * r**2
    kn = E_YADE * r
    pos, rad, bs = _yade_pair(r, r, cohesion=coh, phi=phi)
    comp = 1e-6  # F_n = 30 N: its friction term (17 N) above the cohesion c A (12.6 N)
    _apply(pos, rad, bs, np.array([[0, 0, 0], [-comp / 1e-7, 0, 0]]))
    fn_c = -bs.fn[0]
    assert fn_c == pytest.approx(kn * comp, rel=1e-6)
    du = 5e-11
    last = last_fn = 0.0
    for _ in range(400000):
        _, _, nbr = _apply(pos, rad, bs, np.array([[0, 0, 0], [0, 0, du / 1e-7]]))
        if nbr:
            break
        last, last_fn = np.linalg.norm(bs.fs[0]), -bs.fn[0]
    assert bs.state[0] == BROKEN_SHEAR_SLIDING
    # the shear motion lengthens the pair slightly, so take the normal force it had then
    assert last_fn == pytest.approx(fn_c, rel=0.03)
    strength = coh * area + last_fn * math.tan(math.radians(phi))
    assert strength > 1.5 * coh * area  # compression raised it
    inc = 0.4 * kn * du
    assert strength - 1.01 * inc <= last <= strength * (1 + 1e-6)
    # after the break: sliding at the Coulomb limit of the normal force it still carries
    _apply(pos, rad, bs, np.array([[0, 0, 0], [0, 0, du / 1e-7]]))
    assert np.linalg.norm(bs.fs[0]) == pytest.approx(-bs.fn[0] * math.tan(math.radians(phi)), rel=1e-6)


# ---------------------------------------------------------------- critical time step
def _spinning_pair(ks_over_kn):
    pos = np.array([[0.0, 0.0, 0.0], [2 * R, 0.0, 0.0]])
    bp = BondParams(kn_Pa_m=KN, ks_Pa_m=ks_over_kn * KN, tensile_strength_Pa=1e15, cohesion_Pa=1e15)
    return pos, BondSet(np.array([[0, 1]]), pos, np.array([R, R]), bp)


def test_rotational_stiffness_counts_the_shear_spring_through_its_lever_arm():
    _, bs = _spinning_pair(1.0)
    area, inertia = math.pi * R**2, math.pi * R**4 / 4
    k_sum, r_sum = bs.stiffness_sums(2, np.array([R, R]))
    np.testing.assert_allclose(k_sum, KN * area, rtol=1e-12)
    # about an axis across the bond: shear spring at the lever arm R, plus bending (beta = 1)
    np.testing.assert_allclose(r_sum, KN * area * R**2 + KN * inertia, rtol=1e-12)


@pytest.mark.parametrize("ks_over_kn", [0.4, 1.0])
def test_largest_allowed_time_step_is_stable_for_a_spinning_bonded_pair(ks_over_kn):
    """At time_step_factor 1 (System's largest) a pair with spinning spheres keeps its energy
    bounded (velocity Verlet's shadow-energy swing, ~dt^2); a step that leaves out the shear
    spring's torque stiffness (the critical step before it was counted: 1.58x this one at
    k_s = k_n) blows up."""
    for factor, bounded in ((1.0, True), (1.6, False)):
        pos, bs = _spinning_pair(ks_over_kn)
        s = System(pos, [R, R], Material(), bonds=bs, dt_s=1e-12)
        s.set_dt_beyond_critical(factor * s.critical_dt_s)
        rng = np.random.default_rng(0)
        s.vel[:] = rng.normal(0, 1e-3, (2, 3))
        s.omega[:] = rng.normal(0, 1.0, (2, 3))
        e0, e_max = s.total_energy_J(), 0.0
        try:
            for _ in range(30):
                s.run(100)
                e_max = max(e_max, s.total_energy_J())
        except DemInstabilityError:
            e_max = math.inf
        assert (e_max < 1.25 * e0) == bounded, (factor, e_max / e0)
