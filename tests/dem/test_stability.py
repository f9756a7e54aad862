"""Hard cases: fast impacts stay stable, periodic boundaries, no imports from upper floors."""

import ast
import pathlib

import numpy as np
import pytest

from dem.errors import DemInstabilityError
from dem.materials import Material
from dem.system import System


def test_fast_head_on_impact_is_stable_and_does_not_create_energy():
    r = 1e-3
    s = System([[0, 0, 0], [2.0001 * r, 0, 0]], [r, r], Material(restitution=0.9))
    s.vel[0, 0] = 25.0
    s.vel[1, 0] = -25.0
    e0 = s.kinetic_energy_J()
    s.run(2000)
    assert np.all(np.isfinite(s.pos))
    assert s.kinetic_energy_J() < e0
    assert s.vel[1, 0] > 0 > s.vel[0, 0]


def test_contact_across_the_periodic_boundary():
    lz = 0.02
    r = 1e-3
    pos = [[0, 0, 0.5 * r], [0, 0, lz - 1.4 * r], [0.01, 0, 0.01]]
    s = System(pos, [r, r, r], Material(), periodic_z_m=lz)
    # spheres 0 and 1 overlap through z = 0 / z = lz: pushed apart across the boundary
    assert s.force[0, 2] > 0 and s.force[1, 2] < 0
    assert s.force[2, 2] == 0.0
    s.run(50)
    assert np.all((s.pos[:, 2] >= 0) & (s.pos[:, 2] < lz))


def test_dem_imports_nothing_from_upper_floors():
    root = pathlib.Path(__file__).resolve().parents[2] / "dem"
    for f in root.glob("*.py"):
        tree = ast.parse(f.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for n in names:
                assert n.split(".")[0] not in {"twin", "mpc", "scenarios"}, (f.name, n)


def test_a_sphere_that_blows_up_alone_is_reported_not_carried_along():
    """A non-finite position of any one sphere (here one away from the others, so it cannot
    spread through contacts, and not one of the spheres the step's sample looks at) stops the
    run with DemInstabilityError."""
    r = 1e-3
    pos = [[4 * r * k, 0, 0] for k in range(7)]
    for bad in (np.nan, np.inf):
        s = System(pos, [r] * 7, Material())
        s.run(5)
        s.pos[2, 1] = bad
        with pytest.raises(DemInstabilityError, match="Non-finite state"):
            s.run(5)
