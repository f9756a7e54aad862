"""Neighbour-list rebuilds during a run: the list is replaced between kernel calls, mid-step,
with the same result as any other split of the run."""

import numpy as np

from dem.materials import Material
from dem.system import PlaneWall, System


def _gas(n_steps, chunk):
    """Frictionless spheres flying between two z platens: the Verlet list is rebuilt every few
    tens of steps, inside one call of System.run."""
    rng = np.random.default_rng(1)
    r = 1e-3
    grid = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3) * 3e-3
    walls = [PlaneWall((0, 0, -2e-3), (0, 0, 1)), PlaneWall((0, 0, 11e-3), (0, 0, -1))]
    s = System(grid, np.full(len(grid), r), Material(friction_coef=0.0), walls=walls,
               wall_material=Material(friction_coef=0.0))
    s.vel[:] = rng.normal(0.0, 5.0, s.vel.shape)
    p0 = (s.mass[:, None] * s.vel).sum(axis=0)
    for _ in range(n_steps // chunk):
        s.run(chunk)
    return s, p0


def test_many_neighbour_list_rebuilds_in_one_run(monkeypatch):
    """The list is rebuilt between kernel calls, mid-step, with the same result as any other
    split of the run; sphere-sphere forces conserve the momentum along the platens. (The list
    replaced inside the parallel step loop corrupted memory: a crash or a hang after some
    rebuilds.)"""
    from dem import kernels as K

    calls = []
    rebuild = K.rebuild_pairs
    monkeypatch.setattr(K, "rebuild_pairs", lambda *a: calls.append(1) or rebuild(*a))
    one, p0 = _gas(3000, 3000)
    assert len(calls) > 20
    chunked, _ = _gas(3000, 250)
    np.testing.assert_array_equal(one.pos, chunked.pos)
    np.testing.assert_array_equal(one.vel, chunked.vel)
    assert np.sum(one.pairs.touch) >= 0 and one.hist_pp.sum() > 0  # spheres did collide
    p = (one.mass[:, None] * one.vel).sum(axis=0)
    scale = float(np.sum(one.mass) * 5.0)
    assert abs(p[0] - p0[0]) < 1e-9 * scale and abs(p[1] - p0[1]) < 1e-9 * scale


def test_a_broken_bond_lets_its_pair_touch_on_the_same_list():
    """Pairs carried by an intact bond are left out of the contact loop; a bond that breaks
    hands its pair to the contacts at once, with no list rebuild in between (without the
    refresh of the active pairs the two spheres would pass through each other)."""
    from dem.bonds import BondParams, BondSet

    r = 1e-3
    pos = np.array([[0.0, 0.0, 0.0], [2 * r, 0.0, 0.0]])
    bp = BondParams(kn_Pa_m=1e13, ks_Pa_m=0.0, tensile_strength_Pa=1e5, moment_factor=0.0)
    s = System(pos, [r, r], Material(friction_coef=0.0, restitution=1.0),
               bonds=BondSet(np.array([[0, 1]]), pos, np.array([r, r]), bp),
               skin_fraction=0.5, time_step_factor=0.2)
    assert s.pairs.n_active[0] == 0                      # the one pair is the bond's
    s.vel[1, 0] = 1.0                                    # pull: the bond breaks in tension
    s.run(50)
    assert s.bonds.state[0] != 0 and s.pairs.n_active[0] == 1
    list_before = s.pairs
    s.vel[:] = 0.0
    s.vel[1, 0] = -0.5                                   # push back: a Hertz contact must stop them
    while s.vel[1, 0] < 0.0 and s.steps < 5000:
        s.run(10)
    assert s.pairs is list_before                        # the same Verlet list all along
    assert s.vel[1, 0] > 0.0                             # bounced: the contact acted
    assert np.linalg.norm(s.pos[1] - s.pos[0]) > 1.9 * r


def test_active_pairs_are_those_no_bond_carries_after_a_crush():
    from dem.agglomerate import make_agglomerate
    from dem.bonds import BondParams, BondSet, kn_from_modulus_Pa_m

    agg = make_agglomerate(0.01, 120, random_state=4)
    kn = kn_from_modulus_Pa_m(30e9, agg.mean_radius_m)
    bp = BondParams(kn_Pa_m=kn, ks_Pa_m=0.4 * kn, tensile_strength_Pa=2e6, cohesion_Pa=4e6)
    pos = agg.pos_m.copy()
    z_lo, z_hi = float(np.min(pos[:, 2] - agg.radius_m)), float(np.max(pos[:, 2] + agg.radius_m))
    walls = [PlaneWall((0, 0, z_lo), (0, 0, 1)), PlaneWall((0, 0, z_hi), (0, 0, -1), (0, 0, -2.0))]
    s = System(pos, agg.radius_m, Material(), bonds=BondSet(agg.bond_pairs, pos, agg.radius_m, bp),
               walls=walls, local_damping=0.3)
    s.run(1500)
    pr = s.pairs
    carried = (pr.bond >= 0) & (s.bonds.state[np.maximum(pr.bond, 0)] == 0)
    assert 0 < np.sum(~carried) < len(carried)           # some bonds broke, some hold
    np.testing.assert_array_equal(pr.active[:pr.n_active[0]], np.nonzero(~carried)[0])
    # each sphere's CSR list holds exactly its active pairs, both ends
    counts = np.bincount(np.r_[pr.i[~carried], pr.j[~carried]], minlength=s.n)
    np.testing.assert_array_equal(np.diff(pr.sphere_start), counts)
