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
