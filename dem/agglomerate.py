"""Agglomerates: dense random packings of polydisperse spheres filling a sphere or an ellipsoid.

Packing: ``n`` radii ``r_mean (1 + s U(-1, 1))`` (s = 0.25 gives r(1 ± 0.25)) are placed at
random in the container and then *grown and relaxed*: their radii are scaled up from 60 % to
100 % while a geometric overlap-removal iteration (each overlapping pair is pushed apart by
half its overlap, spheres poking out of the container are pulled back in) removes the
overlaps. This is a simple relative of the Lubachevsky–Stillinger growth algorithm and of the
"radius expansion" packing of PFC (Potyondy & Cundall 2004 §3.1). ``r_mean`` is set so the
spheres fill ``target_solid_fraction`` of the container; the achieved solid fraction and
the largest remaining overlap are reported. Bonds join neighbours whose centre distance is
at most ``bond_distance_factor (R1 + R2)`` (default 1.3, Yade's interaction factor).
Spheres are numbered along a Z-order curve (:func:`morton_order`). Everything is seeded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from dem.bonds import find_bond_pairs
from dem.errors import DemInputError
from dem.materials import as_real
from dem.kernels import build_neighbour_list


@dataclass(frozen=True)
class Agglomerate:
    """A packed particle: spheres centred on the origin and their bond pairs.

    Fields
    ------
    pos_m : (n, 3) centres; radius_m : (n,) radii; bond_pairs : (m, 2) sphere indices i < j;
    diameter_m : the particle's (largest) diameter; semi_axes_m : container semi-axes;
    volume_m3 : container volume; solid_fraction : sum of sphere volumes / container volume;
    max_overlap_rel : largest overlap ``R_i + R_j - d`` of two spheres of the packing returned, /
    mean radius (measured on ``pos_m``, ``radius_m``); seed : the random seed.

    Overlaps: the relaxation stops when the largest overlap is below 1e-3 of the mean radius or
    after ``max_passes``; packings of few spheres at the target solid fraction stop there with
    overlaps of several to tens of per cent of the mean radius (a container a few spheres across
    holds less without overlap). The bonds are made at these positions, stress-free, and a bond
    that breaks counts contact overlap only beyond its own (:mod:`dem.bonds`); the spheres'
    volumes (``solid_fraction``) count the overlapped lenses twice.
    """

    pos_m: np.ndarray
    radius_m: np.ndarray
    bond_pairs: np.ndarray
    diameter_m: float
    semi_axes_m: tuple[float, float, float]
    volume_m3: float
    solid_fraction: float
    max_overlap_rel: float
    seed: int

    @property
    def n_spheres(self) -> int:
        return int(self.radius_m.shape[0])

    @property
    def n_bonds(self) -> int:
        return int(self.bond_pairs.shape[0])

    @property
    def mean_radius_m(self) -> float:
        return float(np.mean(self.radius_m))

    @property
    def coordination_number(self) -> float:
        return 2.0 * self.n_bonds / max(self.n_spheres, 1)


@nb.njit(cache=True)
def _relax(pos, rad, scale, axes, pi, pj, n_pass):
    """``n_pass`` Jacobi overlap-removal passes at radii ``scale * rad``; returns max overlap."""
    n = pos.shape[0]
    disp = np.zeros((n, 3))
    worst = 0.0
    for _ in range(n_pass):
        disp[:, :] = 0.0
        worst = 0.0
        for k in range(pi.shape[0]):
            i = pi[k]
            j = pj[k]
            dx = pos[j, 0] - pos[i, 0]
            dy = pos[j, 1] - pos[i, 1]
            dz = pos[j, 2] - pos[i, 2]
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
            ov = scale * (rad[i] + rad[j]) - d
            if ov > 0.0 and d > 0.0:
                if ov > worst:
                    worst = ov
                f = 0.5 * ov / d
                wi = rad[j] ** 3 / (rad[i] ** 3 + rad[j] ** 3)
                wj = 1.0 - wi
                disp[i, 0] -= 2.0 * wi * f * dx
                disp[i, 1] -= 2.0 * wi * f * dy
                disp[i, 2] -= 2.0 * wi * f * dz
                disp[j, 0] += 2.0 * wj * f * dx
                disp[j, 1] += 2.0 * wj * f * dy
                disp[j, 2] += 2.0 * wj * f * dz
        for i in range(n):
            for d in range(3):
                pos[i, d] += 0.5 * disp[i, d]
            r = scale * rad[i]
            q = 0.0
            for d in range(3):
                q += (pos[i, d] / (axes[d] - r)) ** 2
            q = math.sqrt(q)
            if q > 1.0:
                ov = 0.0
                for d in range(3):
                    pos[i, d] /= q
                # record boundary overlap as roughly (q - 1) * smallest free semi-axis
                ov = (q - 1.0) * (min(axes[0], min(axes[1], axes[2])) - r)
                if ov > worst:
                    worst = ov
    return worst


def morton_order(pos_m: np.ndarray, cell_m: float) -> np.ndarray:
    """Sphere order along a Z-order (Morton) curve through cells of edge ``cell_m``: spheres near
    in space get near indices, so the bonds and contacts of neighbours touch nearby memory (the
    kernels' locality; the packing itself is unchanged, only numbered anew)."""
    q = np.floor((pos_m - pos_m.min(axis=0)) / cell_m).astype(np.int64)
    key = np.zeros(pos_m.shape[0], dtype=np.int64)
    for bit in range(20):
        for d in range(3):
            key |= ((q[:, d] >> bit) & 1) << (3 * bit + d)
    return np.argsort(key, kind="stable")


#: Largest particle diameter (m): breakage tests take tens of mm (the JK drop-weight test
#: 13-63 mm, Napier-Munn et al. 1996, "Mineral Comminution Circuits", ch. 4) and mill feeds a
#: few hundred mm; a diameter in mm (22 for 22 mm) lies above it.
MAX_DIAMETER_M = 1.0
#: Radii of the packing grow from START_SCALE to full size by SCALE_STEP every RELAX_PASSES
#: passes (see :func:`make_agglomerate`)
START_SCALE = 0.6
SCALE_STEP = 0.01
RELAX_PASSES = 10
#: Fewest ``max_passes``: those that grow the radii to full size and relax once at it (with
#: fewer the packing is returned at shrunken radii and its overlap measured at them)
MIN_PASSES = RELAX_PASSES * (round((1.0 - START_SCALE) / SCALE_STEP) + 1)


def _validate(diameter_m, n_spheres, radius_spread, target_solid_fraction, aspect,
              bond_distance_factor, random_state=0, max_passes=4000):
    if not (isinstance(max_passes, (int, np.integer)) and MIN_PASSES <= max_passes <= 10**8):
        raise DemInputError(
            f"The 'max_passes' parameter of make_agglomerate must be an int in [{MIN_PASSES}, 100000000] (the "
            f"radii reach full size after {MIN_PASSES - RELAX_PASSES} passes). Got {max_passes!r}.")
    if not (isinstance(random_state, (int, np.integer)) and not isinstance(random_state, bool)
            and random_state >= 0):
        raise DemInputError(
            f"The 'random_state' parameter of make_agglomerate must be an int >= 0. Got {random_state!r}.")
    if not (math.isfinite(diameter_m) and 0 < diameter_m <= MAX_DIAMETER_M):
        raise DemInputError(
            f"The 'diameter_m' parameter of make_agglomerate must be a float in (0, {MAX_DIAMETER_M:g}] m "
            f"(0.022 for 22 mm). Got {diameter_m!r}.")
    if not (isinstance(n_spheres, (int, np.integer)) and 2 <= n_spheres <= 200_000):
        raise DemInputError(
            f"The 'n_spheres' parameter of make_agglomerate must be an int in [2, 200000]. Got {n_spheres!r}.")
    if not (0.0 <= radius_spread < 1.0):
        raise DemInputError(
            f"The 'radius_spread' parameter of make_agglomerate must be a float in [0, 1). Got {radius_spread!r}.")
    if not (0.2 <= target_solid_fraction <= 0.64):
        raise DemInputError(
            f"The 'target_solid_fraction' parameter of make_agglomerate must be a float in [0.2, 0.64]. "
            f"Got {target_solid_fraction!r}.")
    if len(aspect) != 3 or not all(0.2 <= float(a) <= 1.0 for a in aspect) or max(aspect) != 1.0:
        raise DemInputError(
            f"The 'aspect' parameter of make_agglomerate must be 3 semi-axis ratios in [0.2, 1] "
            f"with the largest equal to 1. Got {aspect!r}.")
    if not (1.0 <= bond_distance_factor <= 2.0):
        raise DemInputError(
            f"The 'bond_distance_factor' parameter of make_agglomerate must be a float in [1, 2]. "
            f"Got {bond_distance_factor!r}.")


def _refuse_pieces(pairs: np.ndarray, rad: np.ndarray, bond_distance_factor: float) -> None:
    """A packing its bonds do not hold together: at a bond distance factor of 1 loose spheres were left
    (2-7 pieces of 300 spheres), and a test of the 'intact' particle found it in pieces."""
    n = rad.shape[0]
    graph = scipy.sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    n_pieces, labels = scipy.sparse.csgraph.connected_components(graph, directed=False)
    if n_pieces > 1:
        outside = n - int(np.bincount(labels).max())
        raise DemInputError(f"The 'bond_distance_factor' parameter of make_agglomerate leaves the packing in "
                            f"{n_pieces} pieces ({outside} spheres outside the largest): its bonds do not hold the "
                            f"particle together; raise it (default 1.3). Got {bond_distance_factor!r}.")


def make_agglomerate(diameter_m: float = 0.022, n_spheres: int = 250, *, radius_spread: float = 0.25,
                     target_solid_fraction: float = 0.58, aspect=(1.0, 1.0, 1.0),
                     bond_distance_factor: float = 1.3, random_state: int = 0,
                     max_passes: int = 4000) -> Agglomerate:
    """Seeded dense random packing of ``n_spheres`` polydisperse spheres filling a sphere/ellipsoid.

    ``aspect`` gives the semi-axes as fractions of ``diameter_m / 2`` (``(1, 1, 1)`` = sphere,
    e.g. ``(1, 0.8, 0.6)`` = ellipsoid). Returns an :class:`Agglomerate`.
    """
    o = "make_agglomerate"
    diameter_m, radius_spread, target_solid_fraction, bond_distance_factor = (
        as_real(o, name, value) for name, value in (
            ("diameter_m", diameter_m), ("radius_spread", radius_spread),
            ("target_solid_fraction", target_solid_fraction), ("bond_distance_factor", bond_distance_factor)))
    _validate(diameter_m, n_spheres, radius_spread, target_solid_fraction,
              tuple(aspect), bond_distance_factor, random_state, max_passes)
    rng = np.random.default_rng(random_state)
    axes = 0.5 * float(diameter_m) * np.asarray(aspect, dtype=float)
    volume = 4.0 / 3.0 * math.pi * float(np.prod(axes))
    rel = 1.0 + radius_spread * rng.uniform(-1.0, 1.0, n_spheres)
    r_mean = (target_solid_fraction * volume / (4.0 / 3.0 * math.pi * np.sum(rel**3))) ** (1 / 3)
    rad = r_mean * rel
    if 2.0 * rad.max() >= 2.0 * axes.min():
        raise DemInputError(
            f"The 'n_spheres' parameter of make_agglomerate is too small for the shape: spheres "
            f"would not fit (largest radius {rad.max():.3g} m, smallest semi-axis {axes.min():.3g} m). "
            f"Got {n_spheres!r}.")
    # random start inside the container (uniform in the unit ball, then stretched)
    u = rng.normal(size=(n_spheres, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    u *= rng.uniform(0.0, 1.0, n_spheres)[:, None] ** (1 / 3)
    pos = u * (axes[None, :] - rad[:, None])
    dummy_p = np.full((n_spheres, 1), -1, dtype=np.int64)
    skin = 0.6 * r_mean
    worst = math.inf
    scale = START_SCALE
    passes = 0
    while passes < max_passes:
        pi, pj, _, _ = build_neighbour_list(pos, rad, skin, 0.0, dummy_p, dummy_p)
        worst = _relax(pos, rad, scale, axes, pi, pj, RELAX_PASSES)
        passes += RELAX_PASSES
        if scale < 1.0:
            scale = min(1.0, scale + SCALE_STEP)
        elif worst < 1e-3 * r_mean:
            break
    solid = float(np.sum(4.0 / 3.0 * math.pi * rad**3) / volume)
    order = morton_order(pos, 2.0 * r_mean)
    pos, rad = pos[order], rad[order]
    pairs = find_bond_pairs(pos, rad, bond_distance_factor)
    _refuse_pieces(pairs, rad, bond_distance_factor)
    # every overlapping pair is within bond distance (factor >= 1): measured on what is returned
    gap = np.linalg.norm(pos[pairs[:, 1]] - pos[pairs[:, 0]], axis=1) - rad[pairs[:, 0]] - rad[pairs[:, 1]]
    overlap = max(0.0, -float(gap.min())) if gap.size else 0.0
    return Agglomerate(pos_m=pos, radius_m=rad, bond_pairs=pairs, diameter_m=float(diameter_m),
                       semi_axes_m=tuple(float(a) for a in axes), volume_m3=volume,
                       solid_fraction=solid, max_overlap_rel=overlap / float(np.mean(rad)),
                       seed=int(random_state))
