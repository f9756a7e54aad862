"""The arrays the numba kernels work on, in five bundles (plain NamedTuples of numpy arrays).

The kernels take these bundles instead of some thirty positional arrays; numba passes a
NamedTuple of arrays without copying, and the arrays stay shared with the Python objects
(:class:`dem.system.System`, :class:`dem.bonds.BondSet`) that hold them.

Parallel kernels and determinism: a bond or contact writes its loads into its own row of a
``load`` table (force on the second sphere, torque on the first, torque on the second); each
sphere then sums the rows that concern it in a fixed order, read from a compressed sparse row
(CSR) list ``sphere_start``/``sphere_entry`` (entry ``2 k + end``, end 0 = first sphere of row k,
1 = second). No two threads write the same number and no sum depends on how the work was split,
so results are bit-identical whatever the number of threads.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

#: columns of a ``load`` row: force on the second sphere (the first gets its opposite), torque
#: on the first sphere, torque on the second
LOAD_F, LOAD_TI, LOAD_TJ = 0, 3, 6
N_LOAD = 9
#: columns of a row of forces through the centres only (central bonds: no torque columns)
N_FORCE = 3


class SphereArrays(NamedTuple):
    """Per-sphere state: positions, velocities, spins (n, 3); radii, masses, moments of inertia
    (n,); the forces and torques of the current step (n, 3)."""

    pos: np.ndarray
    vel: np.ndarray
    omega: np.ndarray
    rad: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    force: np.ndarray
    torque: np.ndarray


class BondArrays(NamedTuple):
    """Bonds (see :mod:`dem.bonds`): sphere pairs ``ij`` (m, 2), property table ``props``
    (m, N_PROPS), stored normal force ``fn``, shear force ``fs`` (m, 3), bending moment ``mb``
    (m, 3), twisting moment ``mt``, current length, state code; ``load`` (m, 9); the per-sphere
    CSR list of bonds; ``partner``/``index`` (n, max bonds a sphere) for pair look-ups; ``scratch``
    one table per thread for :func:`dem.bonds.bond_block` (numba's largest thread count, so that
    every thread id has one)."""

    ij: np.ndarray
    props: np.ndarray
    fn: np.ndarray
    fs: np.ndarray
    mb: np.ndarray
    mt: np.ndarray
    length: np.ndarray
    state: np.ndarray
    load: np.ndarray
    sphere_start: np.ndarray
    sphere_entry: np.ndarray
    partner: np.ndarray
    index: np.ndarray
    scratch: np.ndarray


class PairArrays(NamedTuple):
    """Verlet list of sphere pairs i < j within ``R_i + R_j + skin``, grouped by i (pairs of
    sphere i are ``first[i]:first[i+1]``); ``bond`` the bond index of a bonded pair or -1;
    contact history ``xi`` (p, 3, tangential spring) and ``touch`` (1 while in contact);
    ``load`` (p, 9); ``impact_J`` (normal impact energy of a contact that began this step, else
    -1); the *active* pairs, those not carried by a bond (``active[:n_active[0]]``, increasing),
    and the per-sphere CSR list of the active pairs' rows.

    A pair carried by its bond has no contact: leaving it out of the contact loop and of the
    per-sphere sums (instead of writing and adding a zero row each step) matters in a bonded
    agglomerate, where nearly every listed pair is bonded. Bonds only break, so a pair only
    ever joins the active ones (``dem.kernels.refresh_active``, after a step whose bonds let
    pairs go); its row is then still the zero row it was made with.
    """

    i: np.ndarray
    j: np.ndarray
    bond: np.ndarray
    first: np.ndarray
    xi: np.ndarray
    touch: np.ndarray
    load: np.ndarray
    impact_J: np.ndarray
    active: np.ndarray
    n_active: np.ndarray
    sphere_start: np.ndarray
    sphere_entry: np.ndarray


class WallArrays(NamedTuple):
    """Planar walls: a point, unit normal into the domain, velocity (nw, 3), mass (nw,; > 0 for a
    free drop weight), total force the spheres exert (nw, 3); per sphere and wall: tangential
    spring (n, nw, 3), contact flag (n, nw), the sphere's force on the wall (n, nw, 3) and the
    impact energy of a contact that began this step (n, nw; else -1)."""

    p: np.ndarray
    n: np.ndarray
    v: np.ndarray
    mass: np.ndarray
    f: np.ndarray
    xi: np.ndarray
    touch: np.ndarray
    f_sphere: np.ndarray
    impact_J: np.ndarray


class DrumArrays(NamedTuple):
    """Drum elements (0 the shell, 1.. the lifters at ``lifter_angles`` rad): per sphere and
    element the tangential spring, contact flag and impact energy as for walls; the torque each
    sphere exerts on the drum (n,)."""

    lifter_angles: np.ndarray
    xi: np.ndarray
    touch: np.ndarray
    impact_J: np.ndarray
    torque_sphere: np.ndarray


@nb.njit(cache=True)
def csr_of_rows(first: np.ndarray, second: np.ndarray, n: int):
    """Per-sphere lists of the rows k that name a sphere: entries ``2 k`` (as first sphere) and
    ``2 k + 1`` (as second), each sphere's entries in increasing k (the fixed summation order).
    Returns (sphere_start (n + 1,), sphere_entry (2 m,))."""
    m = first.shape[0]
    start = np.empty(n + 1, dtype=np.int64)
    entry = np.empty(2 * m, dtype=np.int64)
    fill_csr(first, second, np.arange(m), m, start, entry)
    return start, entry


@nb.njit(cache=True)
def fill_csr(first, second, rows, count, start, entry):
    """:func:`csr_of_rows` of the rows ``rows[:count]`` (increasing) only, written in place into
    ``start`` (n + 1,) and ``entry[:2 count]``."""
    n = start.shape[0] - 1
    start[:] = 0
    for q in range(count):
        k = rows[q]
        start[first[k] + 1] += 1
        start[second[k] + 1] += 1
    for s in range(n):
        start[s + 1] += start[s]
    fill = start[:n].copy()
    for q in range(count):
        k = rows[q]
        a = first[k]
        entry[fill[a]] = 2 * k
        fill[a] += 1
        b = second[k]
        entry[fill[b]] = 2 * k + 1
        fill[b] += 1


@nb.njit(cache=True, inline="always")
def write_pair_load(load, k, fx, fy, fz, nx, ny, nz, ai, aj):
    """Row k of a load table: force f on the second sphere (-f on the first) acting at the
    point between them (unit normal n from first to second, lever arms ai, aj from the
    centres: arm of the first +ai n, of the second -aj n) and the torques that follow."""
    tx = ny * fz - nz * fy
    ty = nz * fx - nx * fz
    tz = nx * fy - ny * fx
    load[k, LOAD_F] = fx
    load[k, LOAD_F + 1] = fy
    load[k, LOAD_F + 2] = fz
    load[k, LOAD_TI] = -ai * tx
    load[k, LOAD_TI + 1] = -ai * ty
    load[k, LOAD_TI + 2] = -ai * tz
    load[k, LOAD_TJ] = -aj * tx
    load[k, LOAD_TJ + 1] = -aj * ty
    load[k, LOAD_TJ + 2] = -aj * tz


@nb.njit(cache=True, inline="always")
def unsigned(i):
    """Index ``i`` (>= 0) as an unsigned integer. numba gives an array access with a signed index a
    test that counts a negative index from the end; with an unsigned one the access is a plain load
    or store. The hot loops cast the indices the compiler cannot prove non-negative (read from an
    array, or a parallel loop's): the same arithmetic in fewer instructions (docs/benchmarks.md)."""
    return np.uint64(i)


@nb.njit(cache=True, inline="always")
def add_rows(load, start, entry, s, force, torque, torques=True):
    """Add to sphere s the loads of its rows, in the fixed order of its CSR list. With
    ``torques`` False the rows carry forces through the centres only (central bonds, rows of
    ``N_FORCE`` columns) and no torque column is read."""
    s = unsigned(s)
    fx = fy = fz = tx = ty = tz = 0.0
    for q in range(start[s], start[s + 1]):
        e = entry[unsigned(q)]
        k = unsigned(e >> 1)
        if e & 1:
            fx += load[k, LOAD_F]
            fy += load[k, LOAD_F + 1]
            fz += load[k, LOAD_F + 2]
            if torques:
                tx += load[k, LOAD_TJ]
                ty += load[k, LOAD_TJ + 1]
                tz += load[k, LOAD_TJ + 2]
        else:
            fx -= load[k, LOAD_F]
            fy -= load[k, LOAD_F + 1]
            fz -= load[k, LOAD_F + 2]
            if torques:
                tx += load[k, LOAD_TI]
                ty += load[k, LOAD_TI + 1]
                tz += load[k, LOAD_TI + 2]
    force[s, 0] += fx
    force[s, 1] += fy
    force[s, 2] += fz
    if torques:
        torque[s, 0] += tx
        torque[s, 1] += ty
        torque[s, 2] += tz


@nb.njit(cache=True, inline="always")
def rotated_into_plane(x, y, z, nx, ny, nz):
    """The stored vector (x, y, z) rotated into the plane normal to n, keeping its magnitude (the
    incremental update of a bond's shear force or bending moment as the axis turns; Potyondy &
    Cundall 2004, sec. 2.2; dem.contacts.hertz_mindlin writes the same arithmetic out for a
    contact's tangential spring). Values in, values out, so that the compiler vectorises a loop
    over many bonds (its branch becomes a select)."""
    old2 = x * x + y * y + z * z
    along = x * nx + y * ny + z * nz
    x -= along * nx
    y -= along * ny
    z -= along * nz
    new2 = x * x + y * y + z * z
    if new2 > 0.0:
        sc = math.sqrt(old2 / new2)
        return x * sc, y * sc, z * sc
    return x, y, z
