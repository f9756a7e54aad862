"""Bonded-particle model: parallel bonds between spheres (SI units).

Model (MISSION.md eqs. 3–4; Potyondy & Cundall, IJRMMS 41 (2004) 1329, §2.2.2):

- a bond is a disc of radius ``R_b = lambda * min(R_i, R_j)`` between the two sphere centres,
  area ``A = pi R_b^2``, second moments ``I = pi R_b^4 / 4`` and ``J = pi R_b^4 / 2``;
- force increments ``dF_n = k_n A du_n`` (tension positive, ``du_n`` the change of the centre
  distance) and ``dF_s = -k_s A du_s`` (``du_s`` the tangential displacement increment of j
  relative to i at the bond centre); moment increments ``dM_t = -k_s J dtheta_t`` (twist) and
  ``dM_b = -k_n I dtheta_b`` (bending) when the moment factor ``beta > 0``; stiffnesses
  ``k_n, k_s`` in Pa/m; stored shear force and bending moment are rotated with the bond axis;
- the bond starts stress-free in the position it is created (neighbours within a factor of
  ``R_i + R_j``, so it may span a gap);
- maximum stresses at the bond periphery ``sigma = F_n/A + beta |M_b| R_b / I`` and
  ``tau = |F_s|/A + beta |M_t| R_b / J``; the bond breaks in *tension* if ``sigma >
  tensile strength``, else in *shear* if ``tau > cohesion + max(-F_n/A, 0) tan(phi_b)``
  (Mohr–Coulomb when ``phi_b > 0``; Potyondy & Cundall use ``phi_b = 0``);
- a broken bond carries nothing; the two spheres then interact through the frictional
  Hertz–Mindlin contact of :mod:`dem.contacts` (skipped while the bond is intact). Its
  overlap is counted from the overlap the pair had when the bond was made (packings leave
  small overlaps; without this offset a breaking bond would release a spurious Hertz force
  and trigger a cascade of failures).
"""

from __future__ import annotations

import math
import mmap
import numbers
from dataclasses import dataclass

import numba as nb
import numpy as np

from dem.errors import DemInputError
from dem.materials import MAX_YOUNGS_MODULUS_PA, MIN_YOUNGS_MODULUS_PA
from dem.state import (LOAD_F, LOAD_TI, LOAD_TJ, N_FORCE, N_LOAD, BondArrays, csr_of_rows, rotated_into_plane,
                       unsigned, write_pair_load)

#: bond state codes
INTACT = 0
BROKEN_TENSION = 1
BROKEN_SHEAR = 2
#: "yade_jcfpm" only: broken in shear while in compression, still a frictional spring about
#: the bond's stress-free length (JCFpm keeps the interaction with its ``initD``) until the
#: pair moves apart beyond that length; then BROKEN_SHEAR
BROKEN_SHEAR_SLIDING = 3

# columns of the bond property table (one row per bond, stored column by column, see BondSet):
# k_n A, k_s A (N/m), 1/A, tensile strength, cohesion,
# tan(phi_b), 1 for JCFpm's signed Mohr-Coulomb, overlap at bonding (m); k_n I, k_s J (N m/rad),
# R_b/I, R_b/J; A, R_b, k_n, k_s (Pa/m), length at bonding
(P_KN_A, P_KS_A, P_INV_AREA, P_SIGT, P_COH, P_TANPHI, P_SIGNED_MC, P_OVERLAP0, P_KN_I, P_KS_J,
 P_RB_I, P_RB_J, P_AREA, P_RBAR, P_KN, P_KS, P_LENGTH0) = range(17)
N_PROPS = 17
#: rows the property table has at least (see BondSet): with fewer it is not only F-contiguous
MIN_TABLE_ROWS = 2

#: bond conventions of :class:`BondParams`
CONVENTIONS = ("parallel", "yade_jcfpm")
#: The widest parallel bond, as a multiple of its smaller sphere's radius: Potyondy & Cundall (2004) take
#: lambda = 1; a wider bond (100) shrinks the bond's critical time step ~1/lambda and ran for ever.
RADIUS_MULTIPLIER_MAX = 1.0

#: Smallest bond tensile strength and cohesion (Pa), some ten times below the tensile strength of
#: the weakest rock: ISRM (1981) grade R0 "extremely weak", UCS from 0.25 MPa, tensile strength
#: sigma_ci / m_i with m_i up to ~33 (Hoek & Brown, IJRMMS 34 (1997) 1165); calibrated parallel-bond
#: strengths lie above the rock's own (Potyondy & Cundall 2004, §3). 10 meant as 10 MPa is refused.
MIN_BOND_STRENGTH_PA = 1e3


@dataclass(frozen=True)
class BondParams:
    """Parameters of the parallel bonds of an agglomerate.

    Fields
    ------
    kn_Pa_m : normal stiffness per unit area k_n (Pa/m).
    ks_Pa_m : shear stiffness per unit area k_s (Pa/m). 0 with ``moment_factor`` 0 makes a
        *central* bond: a normal spring ``k_n A`` along the line of centres only, breaking in
        tension (the spring bonds of LAMMPS' BPM package, Clemmer & Robbins 2022, in tension),
        on a faster kernel path with no shear spring and no torques.
    tensile_strength_Pa : bond tensile strength (Pa), at least :data:`MIN_BOND_STRENGTH_PA`.
    cohesion_Pa : bond shear strength at zero normal stress (Pa), at least
        :data:`MIN_BOND_STRENGTH_PA`.
    friction_angle_deg : Mohr–Coulomb friction angle of the bond shear strength (0 = constant).
    radius_multiplier : lambda, bond radius / smaller sphere radius.
    moment_factor : beta in [0, 1], weight of bending/twist moments (0 = forces only).
    convention : ``"parallel"`` (default; the model of the module docstring) or
        ``"yade_jcfpm"``: the bond of Yade's JCFpm model (Scholtès & Donzé, IJRMMS 52 (2012) 18;
        Yade ``Ip2_JCFpmMat_JCFpmMat_JCFpmPhys`` and
        ``Law2_ScGeom_JCFpmPhys_JointedCohesiveFrictionalPM``), used to run the same model
        as Yade: spring stiffness per bond ``k_n A = 2 E R1 R2/(R1+R2)`` (N/m) with
        ``E = youngs_modulus_Pa``, ``k_s A = (ks_Pa_m/kn_Pa_m) k_n A`` (Yade's ``poisson``),
        strengths times ``A = pi min(R1,R2)^2`` (so ``radius_multiplier`` must be 1), shear
        strength ``c A + F_n tan(phi_b)`` with the *signed* normal force (compression positive:
        tension lowers it, as in Yade); ``moment_factor`` must be 0 (JCFpm has no bond moments).
        Build it with :meth:`BondParams.yade_jcfpm`.
    youngs_modulus_Pa : E of the ``"yade_jcfpm"`` convention (unused by ``"parallel"``), in
        [:data:`dem.materials.MIN_YOUNGS_MODULUS_PA`, :data:`dem.materials.MAX_YOUNGS_MODULUS_PA`].

    A ``"parallel"`` ``kn_Pa_m`` is checked where the radii are known (:class:`BondSet`): the bond
    modulus it means, ``k_n (R_i + R_j)`` (Potyondy & Cundall 2004, eq. 9), must lie in that band.
    """

    kn_Pa_m: float = 30e9 / 2.2e-3
    ks_Pa_m: float = 0.4 * 30e9 / 2.2e-3
    tensile_strength_Pa: float = 10e6
    cohesion_Pa: float = 20e6
    friction_angle_deg: float = 0.0
    radius_multiplier: float = 1.0
    moment_factor: float = 1.0
    convention: str = "parallel"
    youngs_modulus_Pa: float = 0.0

    def __post_init__(self) -> None:
        for name in ("kn_Pa_m", "ks_Pa_m", "tensile_strength_Pa", "cohesion_Pa", "friction_angle_deg",
                     "radius_multiplier", "moment_factor", "youngs_modulus_Pa"):
            v = getattr(self, name)
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
                raise DemInputError(f"The '{name}' parameter of BondParams must be a float. Got {v!r}.")
        if self.convention not in CONVENTIONS:
            raise DemInputError(
                f"The 'convention' parameter of BondParams must be one of {CONVENTIONS}. Got {self.convention!r}.")
        if self.convention == "yade_jcfpm":
            e = float(self.youngs_modulus_Pa)
            if not MIN_YOUNGS_MODULUS_PA <= e <= MAX_YOUNGS_MODULUS_PA:
                raise DemInputError(
                    f"The 'youngs_modulus_Pa' parameter of BondParams must be a float in [{MIN_YOUNGS_MODULUS_PA:g}, "
                    f"{MAX_YOUNGS_MODULUS_PA:g}] Pa with convention 'yade_jcfpm' (30e9 for 30 GPa). Got {e!r}.")
            if float(self.moment_factor) != 0.0 or float(self.radius_multiplier) != 1.0:
                raise DemInputError(
                    "BondParams with convention 'yade_jcfpm' needs moment_factor 0 and "
                    f"radius_multiplier 1 (JCFpm bonds). Got {self.moment_factor!r}, {self.radius_multiplier!r}.")
        if float(self.radius_multiplier) > RADIUS_MULTIPLIER_MAX:
            raise DemInputError(f"The 'radius_multiplier' parameter of BondParams must be a float in (0, "
                                f"{RADIUS_MULTIPLIER_MAX:g}] (a bond no wider than its smaller sphere). "
                                f"Got {self.radius_multiplier!r}.")
        for name in ("kn_Pa_m", "ks_Pa_m", "tensile_strength_Pa", "cohesion_Pa",
                     "radius_multiplier"):
            v = float(getattr(self, name))
            if name == "ks_Pa_m" and v == 0.0 and self.convention == "parallel":
                continue  # a central bond: a normal spring only
            if not math.isfinite(v) or v <= 0.0:
                raise DemInputError(
                    f"The '{name}' parameter of BondParams must be a finite float > 0"
                    + (" (or 0 for a central bond, convention 'parallel')" if name == "ks_Pa_m" else "")
                    + f". Got {v!r}.")
        for name in ("tensile_strength_Pa", "cohesion_Pa"):
            v = float(getattr(self, name))
            if v < MIN_BOND_STRENGTH_PA:
                raise DemInputError(
                    f"The '{name}' parameter of BondParams must be a float >= {MIN_BOND_STRENGTH_PA:g} Pa "
                    f"(below any rock's; 10e6 for 10 MPa). Got {v!r}.")
        phi = float(self.friction_angle_deg)
        if not (0.0 <= phi < 90.0):
            raise DemInputError(
                f"The 'friction_angle_deg' parameter of BondParams must be a float in [0, 90). Got {phi!r}.")
        beta = float(self.moment_factor)
        if not (0.0 <= beta <= 1.0):
            raise DemInputError(
                f"The 'moment_factor' parameter of BondParams must be a float in [0, 1]. Got {beta!r}.")

    def scaled(self, strength_factor: float = 1.0, stiffness_factor: float = 1.0) -> "BondParams":
        """Copy with strengths and/or stiffnesses multiplied by a factor."""
        return BondParams(self.kn_Pa_m * stiffness_factor, self.ks_Pa_m * stiffness_factor,
                          self.tensile_strength_Pa * strength_factor,
                          self.cohesion_Pa * strength_factor, self.friction_angle_deg,
                          self.radius_multiplier, self.moment_factor, self.convention,
                          self.youngs_modulus_Pa * stiffness_factor)

    @classmethod
    def yade_jcfpm(cls, youngs_modulus_Pa: float, poisson: float, tensile_strength_Pa: float,
                   cohesion_Pa: float, friction_angle_deg: float) -> "BondParams":
        """Bonds of Yade's ``JCFpmMat(young, poisson, tensileStrength, cohesion, frictionAngle)``
        (``poisson`` is Yade's k_s/k_n ratio); see the ``convention`` field. ``kn_Pa_m`` holds
        E and ``ks_Pa_m`` poisson * E only to carry the ratio."""
        e = float(youngs_modulus_Pa)
        return cls(kn_Pa_m=e, ks_Pa_m=float(poisson) * e, tensile_strength_Pa=tensile_strength_Pa,
                   cohesion_Pa=cohesion_Pa, friction_angle_deg=friction_angle_deg,
                   radius_multiplier=1.0, moment_factor=0.0, convention="yade_jcfpm",
                   youngs_modulus_Pa=e)


def kn_from_modulus_Pa_m(modulus_Pa: float, mean_radius_m: float) -> float:
    """Bond normal stiffness from a bond modulus: ``k_n = E_b / (R_i + R_j)`` (Potyondy & Cundall 2004, eq. 9)."""
    return float(modulus_Pa) / (2.0 * float(mean_radius_m))


def find_bond_pairs(pos_m: np.ndarray, radius_m: np.ndarray, factor: float = 1.3) -> np.ndarray:
    """Pairs (i < j) whose centre distance is at most ``factor (R_i + R_j)`` (Yade's interaction factor)."""
    from scipy.spatial import cKDTree

    if not (1.0 <= factor <= 2.0):
        raise DemInputError(
            f"The 'bond_distance_factor' parameter must be a float in [1, 2]. Got {factor!r}.")
    pos_m, radius_m = _spheres("find_bond_pairs", pos_m, radius_m)
    tree = cKDTree(pos_m)
    cand = tree.query_pairs(r=factor * 2.0 * float(np.max(radius_m)), output_type="ndarray")
    if cand.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    d = np.linalg.norm(pos_m[cand[:, 1]] - pos_m[cand[:, 0]], axis=1)
    keep = d <= factor * (radius_m[cand[:, 0]] + radius_m[cand[:, 1]])
    pairs = np.sort(cand[keep], axis=1).astype(np.int64)
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return pairs[order]


def _spheres(owner: str, pos_m, radius_m) -> tuple[np.ndarray, np.ndarray]:
    """Float64 centres (n, 3), n >= 1, and radii (n,), finite (radii > 0), or a DemInputError."""
    try:
        pos = np.asarray(pos_m, dtype=np.float64)
        rad = np.asarray(radius_m, dtype=np.float64)
    except (TypeError, ValueError):
        raise DemInputError(
            f"The 'pos_m' and 'radius_m' parameters of {owner} must be arrays of numbers (m).") from None
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] < 1 or not np.all(np.isfinite(pos)):
        raise DemInputError(
            f"The 'pos_m' parameter of {owner} must be a finite (n, 3) array of sphere centres (m), n >= 1. "
            f"Got shape {pos.shape}{'' if np.all(np.isfinite(pos)) else ' with non-finite entries'}.")
    if rad.shape != (pos.shape[0],) or not np.all(np.isfinite(rad) & (rad > 0)):
        raise DemInputError(
            f"The 'radius_m' parameter of {owner} must be {pos.shape[0]} finite radii > 0 (m), one per "
            f"sphere. Got shape {rad.shape}.")
    return pos, rad


def _bond_pairs(pairs, n: int) -> np.ndarray:
    """Pairs as an (m, 2) int64 array of distinct sphere indices in [0, n), each pair once, or a
    DemInputError (a float index is not truncated; a repeated pair would double the bond)."""
    try:
        raw = np.asarray(pairs)
        ok = raw.dtype.kind in "iu" or (raw.dtype.kind == "f" and bool(np.all(raw == np.round(raw))))
    except (TypeError, ValueError):
        raw, ok = None, False
    flat_ok = raw is not None and raw.ndim == 1 and raw.size in (0, 2)
    if not ok or not (flat_ok or (raw.ndim == 2 and raw.shape[1] == 2)):
        raise DemInputError(
            "The 'pairs' parameter of BondSet must be an (m, 2) array of whole sphere indices. Got "
            + (f"{pairs!r}." if raw is None else f"shape {raw.shape}, dtype {raw.dtype}."))
    ij = raw.astype(np.int64).reshape(-1, 2)
    if ij.size == 0:
        return ij
    bad = np.nonzero((ij.min(axis=1) < 0) | (ij.max(axis=1) >= n) | (ij[:, 0] == ij[:, 1]))[0]
    if bad.size:
        raise DemInputError(
            f"The 'pairs' parameter of BondSet must join two different spheres of [0, {n}). "
            f"Got {ij[bad[0]].tolist()} (row {int(bad[0])}).")
    key = np.sort(ij, axis=1)
    uniq, count = np.unique(key, axis=0, return_counts=True)
    if np.any(count > 1):
        raise DemInputError(
            f"The 'pairs' parameter of BondSet must list each pair once. Got {uniq[count > 1][0].tolist()} "
            f"{int(count.max())} times.")
    return ij


class BondSet:
    """Arrays of the bonds of one system (intact and broken), created stress-free.

    ``pairs`` (m, 2) whole sphere indices, each pair once (either order); ``pos_m`` (n, 3) and
    ``radius_m`` (n,) the spheres (m) at which the bonds are made; ``n_spheres`` = n (a
    :class:`dem.system.System` takes the set only for as many spheres, at these positions).

    ``arrays`` is the :class:`dem.state.BondArrays` bundle the kernels take; ``ij``, ``props``,
    ``fn``, ``fs``, ``mb``, ``mt``, ``length`` and ``state`` are the same arrays.
    """

    def __init__(self, pairs: np.ndarray, pos_m: np.ndarray, radius_m: np.ndarray,
                 params: BondParams) -> None:
        if not isinstance(params, BondParams):
            raise DemInputError(f"The 'params' parameter of BondSet must be a BondParams. Got {params!r}.")
        pos_m, radius_m = _spheres("BondSet", pos_m, radius_m)
        n = pos_m.shape[0]
        pairs = _bond_pairs(pairs, n)
        _check_bond_modulus(pairs, radius_m, params)
        nbnd = pairs.shape[0]
        self.n_spheres = n
        self.params = params
        self.beta = float(params.moment_factor)
        self.ij = pairs
        # column-major: a central bond reads three columns, and a bond's row of 17 would cost a
        # cache line of traffic each; the full bond reads its dozen columns as as many streams.
        # At least two rows: a table of 0 or 1 rows is C-contiguous too, numba types it so, and
        # every kernel taking the bundle is compiled a second time (minutes on a cold cache).
        # The kernels get the whole table (they index real bonds only); ``props`` is its view
        # of the real rows, sharing its memory.
        table = np.zeros((max(nbnd, MIN_TABLE_ROWS), N_PROPS), order="F")
        table[:nbnd] = _property_table(pairs, pos_m, radius_m, params)
        self.props = table[:nbnd]
        self.length = self.props[:, P_LENGTH0].copy()
        self.fn = np.zeros(nbnd)
        self.fs = np.zeros((nbnd, 3))
        self.mb = np.zeros((nbnd, 3))
        self.mt = np.zeros(nbnd)
        self.state = np.zeros(nbnd, dtype=np.int8)
        self.partner, self.index = _bond_partners(pairs, n)
        start, entry = csr_of_rows(pairs[:, 0].copy(), pairs[:, 1].copy(), n)
        # central bonds load their spheres through the centres: rows of the force columns only
        load = np.zeros((nbnd, N_FORCE if self.central else N_LOAD))
        self.arrays = BondArrays(self.ij, table, self.fn, self.fs, self.mb, self.mt,
                                 self.length, self.state, load, start, entry,
                                 self.partner, self.index, _block_scratch())

    def __getstate__(self) -> dict:
        # the scratch tables are this process's working memory, one per numba thread: a process
        # with more threads (its numba.config.NUMBA_NUM_THREADS) needs more, and the kernels do
        # not check bounds. ``props`` is a view of the table, which pickle would copy apart.
        state = self.__dict__.copy()
        state["arrays"] = self.arrays._replace(scratch=None)
        del state["props"]
        return state

    def __setstate__(self, state: dict) -> None:
        arrays = state["arrays"]
        state["arrays"] = arrays._replace(scratch=_block_scratch())
        state["props"] = arrays.props[:state["ij"].shape[0]]
        self.__dict__.update(state)

    @property
    def n_bonds(self) -> int:
        return int(self.ij.shape[0])

    @property
    def central(self) -> bool:
        """Every bond central (k_s = 0, no moments): their loads are forces through the centres."""
        return self.beta == 0.0 and self.n_bonds > 0 and bool(np.all(self.props[:, P_KS_A] == 0.0))

    @property
    def intact(self) -> np.ndarray:
        return self.state == INTACT

    def counts(self) -> dict[str, int]:
        """Numbers of intact bonds and of bonds broken in tension and in shear."""
        return {"intact": int(np.sum(self.state == INTACT)),
                "broken_tension": int(np.sum(self.state == BROKEN_TENSION)),
                "broken_shear": int(np.sum((self.state == BROKEN_SHEAR)
                                           | (self.state == BROKEN_SHEAR_SLIDING)))}

    def stiffness_sums(self, n: int, radius_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-sphere sums of translational (N/m) and rotational (N m/rad) bond stiffness.

        A sphere's rotation about an axis across the bond turns its shear spring through the
        lever arm ``a`` (from its centre to the bond centre; Yade's JCFpm: its radius), which
        stiffens it by ``k_s A a^2``, besides the bending spring ``beta k_n I``; about the bond
        axis only the twisting spring ``beta k_s J`` acts. The larger of the two counts."""
        pr = self.props
        kt = np.maximum(pr[:, P_KN_A], pr[:, P_KS_A])
        k_sum = np.zeros(n)
        r_sum = np.zeros(n)
        half_gap = 0.5 * (pr[:, P_LENGTH0] - radius_m[self.ij[:, 0]] - radius_m[self.ij[:, 1]])
        jcfpm = pr[:, P_SIGNED_MC] != 0.0
        for col in (0, 1):
            r = radius_m[self.ij[:, col]]
            arm = np.where(jcfpm, r, r + half_gap)
            kr = np.maximum(pr[:, P_KS_A] * arm**2 + self.beta * pr[:, P_KN_I], self.beta * pr[:, P_KS_J])
            np.add.at(k_sum, self.ij[:, col], kt)
            np.add.at(r_sum, self.ij[:, col], kr)
        return k_sum, r_sum

    def elastic_energy_J(self) -> float:
        """Strain energy stored in the intact bonds."""
        ok = self.state == INTACT
        pr = self.props[ok]
        e = self.fn[ok] ** 2 / (2 * pr[:, P_KN_A]) + np.sum(self.fs[ok] ** 2, axis=1) / (2 * pr[:, P_KS_A])
        if self.beta > 0:
            e = e + (np.sum(self.mb[ok] ** 2, axis=1) / (2 * pr[:, P_KN_I])
                     + self.mt[ok] ** 2 / (2 * pr[:, P_KS_J]))
        return float(np.sum(e))

    def damage(self) -> np.ndarray:
        """Current ``max(sigma / tensile strength, tau / shear strength)`` of each bond (0 if broken)."""
        out = np.zeros(self.n_bonds)
        for b in range(self.n_bonds):
            if self.state[b] == INTACT:
                s, t, smax, tmax = bond_stresses(b, self.props, self.fn, shear_magnitude(self.fs, b), self.mb,
                                                 self.mt, self.beta)
                out[b] = max(s / smax, t / tmax)
        return out


def _check_bond_modulus(pairs, radius_m, params: BondParams) -> None:
    """A "parallel" ``kn_Pa_m`` means the bond modulus ``k_n (R_i + R_j)`` (Potyondy & Cundall 2004,
    eq. 9): it must be a solid's (the band of :mod:`dem.materials`); a k_n in GPa/m or per mm is not."""
    if params.convention != "parallel" or pairs.shape[0] == 0:
        return
    r_sum = radius_m[pairs[:, 0]] + radius_m[pairs[:, 1]]
    lo, hi = params.kn_Pa_m * float(r_sum.min()), params.kn_Pa_m * float(r_sum.max())
    if lo < MIN_YOUNGS_MODULUS_PA or hi > MAX_YOUNGS_MODULUS_PA:
        raise DemInputError(
            f"The 'kn_Pa_m' parameter of BondSet's params must give these spheres a bond modulus k_n (R_i + R_j) in "
            f"[{MIN_YOUNGS_MODULUS_PA:g}, {MAX_YOUNGS_MODULUS_PA:g}] Pa (kn_from_modulus_Pa_m makes it from one). "
            f"Got {params.kn_Pa_m!r} Pa/m: moduli {lo:.3g} to {hi:.3g} Pa.")


def _block_scratch() -> np.ndarray:
    """One scratch table of :func:`bond_block` per thread numba can run in this process, each
    starting a memory page of its own and padded to whole pages (its rows beyond ``N_ROWS`` are
    never used). numpy aligns an array to 16 bytes only; with the tables packed end to end, the
    thread whose table followed another's ran its bond blocks slower than the other, and the step
    on two threads was slower (measured: docs/benchmarks.md)."""
    row = BOND_BLOCK * 8
    rows = -(-N_ROWS * row // mmap.PAGESIZE) * mmap.PAGESIZE // row
    shape = (nb.config.NUMBA_NUM_THREADS, rows, BOND_BLOCK)
    size = shape[0] * rows * BOND_BLOCK
    buf = np.empty(size + mmap.PAGESIZE // 8)
    skip = (-buf.ctypes.data % mmap.PAGESIZE) // 8
    return buf[skip:skip + size].reshape(shape)


def _property_table(pairs, pos_m, radius_m, params: BondParams) -> np.ndarray:
    """One row of constants per bond (columns ``P_*``), the products the kernel needs precomputed."""
    nbnd = pairs.shape[0]
    r1 = radius_m[pairs[:, 0]]
    r2 = radius_m[pairs[:, 1]]
    rbar = params.radius_multiplier * np.minimum(r1, r2)
    area = math.pi * rbar**2
    inertia = math.pi * rbar**4 / 4.0        # second moment of the bond disc, I
    polar = 2.0 * inertia                      # polar moment, J
    props = np.zeros((nbnd, N_PROPS))
    if params.convention == "yade_jcfpm":
        kn_area = params.youngs_modulus_Pa * 2.0 * r1 * r2 / (r1 + r2)  # N/m, Yade's kn
        kn = kn_area / area
        ks = kn * (params.ks_Pa_m / params.kn_Pa_m)
        props[:, P_SIGNED_MC] = 1.0
    else:
        kn = np.full(nbnd, params.kn_Pa_m)
        ks = np.full(nbnd, params.ks_Pa_m)
    props[:, P_AREA] = area
    props[:, P_INV_AREA] = 1.0 / area
    props[:, P_RBAR] = rbar
    props[:, P_KN] = kn
    props[:, P_KS] = ks
    props[:, P_KN_A] = kn * area
    props[:, P_KS_A] = ks * area
    props[:, P_KN_I] = kn * inertia
    props[:, P_KS_J] = ks * polar
    props[:, P_RB_I] = rbar / inertia
    props[:, P_RB_J] = rbar / polar
    props[:, P_SIGT] = params.tensile_strength_Pa
    props[:, P_COH] = params.cohesion_Pa
    props[:, P_TANPHI] = math.tan(math.radians(params.friction_angle_deg))
    length = np.linalg.norm(pos_m[pairs[:, 1]] - pos_m[pairs[:, 0]], axis=1)
    props[:, P_LENGTH0] = length
    # overlap at bonding (packings leave small overlaps): after the bond breaks, the Hertz
    # contact counts only overlap beyond it, so breaking releases no stored contact force.
    # "yade_jcfpm": it becomes Yade's initD of the frictional contact that follows the bond; it
    # is set at breakage and lowered as the pair separates (bond kernel and dem.contacts)
    props[:, P_OVERLAP0] = np.maximum(0.0, r1 + r2 - length)
    return props


def _bond_partners(pairs, n):
    """(partner, index) tables (n, max bonds of a sphere): the bonded neighbours of each sphere and
    the bond indices, -1 padded (the neighbour search marks bonded pairs with them)."""
    counts = np.bincount(pairs.ravel(), minlength=n) if pairs.shape[0] else np.zeros(n, dtype=np.int64)
    maxb = max(1, int(counts.max()) if n else 1)
    partner = np.full((n, maxb), -1, dtype=np.int64)
    index = np.full((n, maxb), -1, dtype=np.int64)
    fill = np.zeros(n, dtype=np.int64)
    for b, (i, j) in enumerate(pairs):
        partner[i, fill[i]] = j
        index[i, fill[i]] = b
        fill[i] += 1
        partner[j, fill[j]] = i
        index[j, fill[j]] = b
        fill[j] += 1
    return partner, index


# ---------------------------------------------------------------------------------- kernels
# Element functions take plain arrays: a NamedTuple bundle passed into a function called once
# per bond costs reference counting of every array in it (measured: ~10x the bond's own work).

@nb.njit(cache=True, inline="always")
def shear_magnitude(fs, b):
    """|F_s| of bond b."""
    return math.sqrt(fs[b, 0] * fs[b, 0] + fs[b, 1] * fs[b, 1] + fs[b, 2] * fs[b, 2])


@nb.njit(cache=True, inline="always")
def bond_stresses(b, props, fn, fsm, mb, mt, beta):
    """(sigma, tau, tensile strength, shear strength) of bond b, tension positive; ``fsm`` its
    shear force's magnitude."""
    inv_a = props[b, P_INV_AREA]
    sigma = fn[b] * inv_a
    tau = fsm * inv_a
    if beta > 0.0:
        mbm = math.sqrt(mb[b, 0] ** 2 + mb[b, 1] ** 2 + mb[b, 2] ** 2)
        sigma += beta * mbm * props[b, P_RB_I]
        tau += beta * abs(mt[b]) * props[b, P_RB_J]
    comp = -fn[b] * inv_a
    if comp < 0.0 and props[b, P_SIGNED_MC] == 0.0:
        comp = 0.0
    return sigma, tau, props[b, P_SIGT], props[b, P_COH] + comp * props[b, P_TANPHI]


#: bonds per block of :func:`bond_block`: the block's scratch table (N_ROWS x BOND_BLOCK doubles,
#: 18 kB) stays in a core's 32 kB L1 data cache
BOND_BLOCK = 64
# rows of the scratch table, one column per bond of the block: centre-to-centre vector (then the
# unit axis n), radii, velocity of j minus that of i, spins of i and j, shear force, normal force,
# k_n A, length, k_s A dt, 1 for the JCFpm convention; centre distance d, lever arms, the
# relative-velocity factors of the convention; bending moment, twisting moment, k_s J, k_n I; |F_s|
(G_NX, G_NY, G_NZ, G_RI, G_RJ, G_DVX, G_DVY, G_DVZ, G_OIX, G_OIY, G_OIZ, G_OJX, G_OJY, G_OJZ,
 G_FSX, G_FSY, G_FSZ, G_FN, G_KNA, G_LEN, G_KSDT, G_YADE, G_D, G_AI, G_AJ, G_ALPHA, G_QI, G_QJ,
 G_MBX, G_MBY, G_MBZ, G_MT, G_KSJ, G_KNI, G_FSM) = range(35)
N_ROWS = 35


@nb.njit(cache=True, inline="always")
def _centre_vector(i, j, pos, lz):
    """Vector from the centre of sphere i to that of j (the nearest image along a periodic z)."""
    dz = pos[j, 2] - pos[i, 2]
    if lz > 0.0:
        dz -= lz * math.floor(dz / lz + 0.5)
    return pos[j, 0] - pos[i, 0], pos[j, 1] - pos[i, 1], dz


@nb.njit(cache=True, inline="always")
def _unit_axis(dx, dy, dz):
    """Length d of (dx, dy, dz) and its unit vector."""
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    inv_d = 1.0 / d
    return d, dx * inv_d, dy * inv_d, dz * inv_d


@nb.njit(cache=True, inline="always")
def _gather(b0, b1, ij, props, fn, fs, mb, mt, length, pos, vel, om, rad, lz, dt, moments, g):
    """Copy what bonds b0..b1-1 read into columns of the scratch table ``g`` (broken bonds too:
    their columns are computed and not used)."""
    for t in range(b1 - b0):
        b = unsigned(b0 + t)
        i = unsigned(ij[b, 0])
        j = unsigned(ij[b, 1])
        g[G_NX, t], g[G_NY, t], g[G_NZ, t] = _centre_vector(i, j, pos, lz)
        g[G_RI, t] = rad[i]
        g[G_RJ, t] = rad[j]
        g[G_FN, t] = fn[b]
        g[G_KNA, t] = props[b, P_KN_A]
        g[G_LEN, t] = length[b]
        for c in range(3):
            g[G_DVX + c, t] = vel[j, c] - vel[i, c]
            g[G_OIX + c, t] = om[i, c]
            g[G_OJX + c, t] = om[j, c]
            g[G_FSX + c, t] = fs[b, c]
        g[G_KSDT, t] = props[b, P_KS_A] * dt
        g[G_YADE, t] = props[b, P_SIGNED_MC]
        if moments:
            for c in range(3):
                g[G_MBX + c, t] = mb[b, c]
            g[G_MT, t] = mt[b]
            g[G_KSJ, t] = props[b, P_KS_J]
            g[G_KNI, t] = props[b, P_KN_I]


@nb.njit(cache=True, inline="always")
def _axes(m, g):
    """Centre distance d, unit axis n from i to j, lever arms ai, aj to the bond centre (midway
    across the gap between the surfaces) of the block's m bonds, and the factors of the relative
    velocity: centre velocities times alpha, spins times the arms qi, qj; Yade's
    ScGeom::getIncidentVel (avoidGranularRatcheting) for JCFpm bonds: alpha = (R1+R2)/d, the
    sphere radii as arms."""
    for t in range(m):
        d, nx, ny, nz = _unit_axis(g[G_NX, t], g[G_NY, t], g[G_NZ, t])
        ri = g[G_RI, t]
        rj = g[G_RJ, t]
        half_gap = 0.5 * (d - ri - rj)
        ai = ri + half_gap
        aj = rj + half_gap
        yade = g[G_YADE, t] != 0.0
        g[G_D, t] = d
        g[G_NX, t] = nx
        g[G_NY, t] = ny
        g[G_NZ, t] = nz
        g[G_AI, t] = ai
        g[G_AJ, t] = aj
        g[G_ALPHA, t] = (ri + rj) / d if yade else 1.0
        g[G_QI, t] = ri if yade else ai
        g[G_QJ, t] = rj if yade else aj


@nb.njit(cache=True, inline="always")
def _springs(m, g):
    """Incremental update of the block's m bonds (Potyondy & Cundall 2004, eqs. 5-8): dF_n = k_n A
    du_n with du_n the exact change of the centre distance; the stored shear force rotated into
    the new tangent plane, then dF_s = -k_s A du_s with du_s the tangential part of the velocity
    of j relative to i at the bond centre times dt (mid-step velocities)."""
    for t in range(m):
        nx = g[G_NX, t]
        ny = g[G_NY, t]
        nz = g[G_NZ, t]
        alpha = g[G_ALPHA, t]
        qi = g[G_QI, t]
        qj = g[G_QJ, t]
        vrx = (alpha * g[G_DVX, t] - qj * (g[G_OJY, t] * nz - g[G_OJZ, t] * ny)
               - qi * (g[G_OIY, t] * nz - g[G_OIZ, t] * ny))
        vry = (alpha * g[G_DVY, t] - qj * (g[G_OJZ, t] * nx - g[G_OJX, t] * nz)
               - qi * (g[G_OIZ, t] * nx - g[G_OIX, t] * nz))
        vrz = (alpha * g[G_DVZ, t] - qj * (g[G_OJX, t] * ny - g[G_OJY, t] * nx)
               - qi * (g[G_OIX, t] * ny - g[G_OIY, t] * nx))
        vn = vrx * nx + vry * ny + vrz * nz
        x, y, z = rotated_into_plane(g[G_FSX, t], g[G_FSY, t], g[G_FSZ, t], nx, ny, nz)
        ksa_dt = g[G_KSDT, t]
        x -= ksa_dt * (vrx - vn * nx)
        y -= ksa_dt * (vry - vn * ny)
        z -= ksa_dt * (vrz - vn * nz)
        g[G_FSX, t] = x
        g[G_FSY, t] = y
        g[G_FSZ, t] = z
        g[G_FSM, t] = math.sqrt(x * x + y * y + z * z)


@nb.njit(cache=True, inline="always")
def _moments(m, g, dt):
    """The block's bond moments (beta > 0): dM_t = -k_s J dtheta_t, the stored bending moment
    rotated into the new tangent plane, then dM_b = -k_n I dtheta_b, dtheta the relative rotation
    of j over dt (Potyondy & Cundall 2004, eqs. 7-8)."""
    for t in range(m):
        nx = g[G_NX, t]
        ny = g[G_NY, t]
        nz = g[G_NZ, t]
        wx = (g[G_OJX, t] - g[G_OIX, t]) * dt
        wy = (g[G_OJY, t] - g[G_OIY, t]) * dt
        wz = (g[G_OJZ, t] - g[G_OIZ, t]) * dt
        wt = wx * nx + wy * ny + wz * nz
        g[G_MT, t] -= g[G_KSJ, t] * wt
        x, y, z = rotated_into_plane(g[G_MBX, t], g[G_MBY, t], g[G_MBZ, t], nx, ny, nz)
        kni = g[G_KNI, t]
        g[G_MBX, t] = x - kni * (wx - wt * nx)
        g[G_MBY, t] = y - kni * (wy - wt * ny)
        g[G_MBZ, t] = z - kni * (wz - wt * nz)


@nb.njit(cache=True, inline="always")
def _scale_shear(fs, b, limit_N):
    """Cut the stored shear force to ``limit_N`` (Coulomb or strength limit) if above it."""
    fsm = shear_magnitude(fs, b)
    if fsm > limit_N:
        sc = limit_N / fsm
        fs[b, 0] *= sc
        fs[b, 1] *= sc
        fs[b, 2] *= sc


@nb.njit(cache=True, inline="always")
def _failure(b, props, fn, fs, fsm, mb, mt, state, beta, pen):
    """Test an intact bond (sigma > tensile strength: tension, else tau > shear strength: shear)
    and set its state. Returns True if it broke. JCFpm erases the interaction of a broken bond;
    a new stress-free contact forms at the current overlap ``pen`` if the spheres still
    overlap (its initD)."""
    sigma, tau, smax, tmax = bond_stresses(b, props, fn, fsm, mb, mt, beta)
    jcfpm = props[b, P_SIGNED_MC] != 0.0
    if sigma > smax:
        state[b] = BROKEN_TENSION
    elif tau > tmax:
        if jcfpm and fn[b] <= 0.0:
            # JCFpm: the pair stays in frictional contact about its bonding distance; this
            # step the shear force is cut to the strength it exceeded
            state[b] = BROKEN_SHEAR_SLIDING
            _scale_shear(fs, b, tmax * props[b, P_AREA])
            return True
        state[b] = BROKEN_SHEAR
    else:
        return False
    if jcfpm:
        props[b, P_OVERLAP0] = pen if pen > 0.0 else 0.0
    return True


@nb.njit(cache=True, inline="always")
def _clear(b, fn, fs, mb, mt, load):
    """A broken bond carries nothing from now on."""
    fn[b] = 0.0
    for c in range(3):
        fs[b, c] = 0.0
        mb[b, c] = 0.0
    mt[b] = 0.0
    for c in range(N_LOAD):
        load[b, c] = 0.0


@nb.njit(cache=True, inline="always")
def _write_load(b, fn, fs, mb, mt, load, nx, ny, nz, ai, aj, beta):
    """Loads of bond b into its row: on j the force -F_n n (tension pulls j back) + F_s at the
    bond centre and the moment M = M_b + M_t n; on i their opposites."""
    fx = -fn[b] * nx + fs[b, 0]
    fy = -fn[b] * ny + fs[b, 1]
    fz = -fn[b] * nz + fs[b, 2]
    write_pair_load(load, b, fx, fy, fz, nx, ny, nz, ai, aj)
    if beta > 0.0:
        mx = mb[b, 0] + mt[b] * nx
        my = mb[b, 1] + mt[b] * ny
        mz = mb[b, 2] + mt[b] * nz
        load[b, LOAD_TI] -= mx
        load[b, LOAD_TI + 1] -= my
        load[b, LOAD_TI + 2] -= mz
        load[b, LOAD_TJ] += mx
        load[b, LOAD_TJ + 1] += my
        load[b, LOAD_TJ + 2] += mz


@nb.njit(cache=True, inline="always")
def _central_spring(b, d, nx, ny, nz, props, fn, length, state, load):
    """A central bond (k_s = 0, no moments) of centre distance d and axis n: the normal spring
    along the line of centres, broken when F_n/A exceeds the tensile strength; its force acts
    through both centres, so it exerts no torque (only a row's force columns are written).
    Returns 1 if it broke, else 0."""
    fn[b] += props[b, P_KN_A] * (d - length[b])
    length[b] = d
    broke = fn[b] * props[b, P_INV_AREA] > props[b, P_SIGT]
    if broke:
        state[b] = BROKEN_TENSION
        fn[b] = 0.0
    load[b, LOAD_F] = -fn[b] * nx
    load[b, LOAD_F + 1] = -fn[b] * ny
    load[b, LOAD_F + 2] = -fn[b] * nz
    return 1 if broke else 0


@nb.njit(cache=True, inline="always")
def _finish(b, t, g, props, fn, fs, mb, mt, length, state, load, beta):
    """Store bond b's updated springs (block column t), test it for failure, write its loads.
    Returns 1 if it broke (a JCFpm bond that starts to slide counts), else 0."""
    st = state[b]
    if beta == 0.0 and props[b, P_KS_A] == 0.0:
        return _central_spring(b, g[G_D, t], g[G_NX, t], g[G_NY, t], g[G_NZ, t], props, fn, length, state, load)
    fn[b] = g[G_FN, t]
    length[b] = g[G_D, t]
    for c in range(3):
        fs[b, c] = g[G_FSX + c, t]
    if beta > 0.0:
        for c in range(3):
            mb[b, c] = g[G_MBX + c, t]
        mt[b] = g[G_MT, t]
    pen = g[G_RI, t] + g[G_RJ, t] - g[G_D, t]
    broke = 0
    if st == BROKEN_SHEAR_SLIDING:
        # JCFpm after a shear break: no tension (the interaction is erased when the pair is
        # farther apart than at bonding), Coulomb friction |F_s| <= -F_n tan(phi)
        if fn[b] > 0.0:
            state[b] = BROKEN_SHEAR
            props[b, P_OVERLAP0] = pen if pen > 0.0 else 0.0
            _clear(b, fn, fs, mb, mt, load)
            return 0
        _scale_shear(fs, b, -fn[b] * props[b, P_TANPHI])
    elif _failure(b, props, fn, fs, g[G_FSM, t], mb, mt, state, beta, pen):
        broke = 1
        if state[b] != BROKEN_SHEAR_SLIDING:
            _clear(b, fn, fs, mb, mt, load)
            return 1
    _write_load(b, fn, fs, mb, mt, load, g[G_NX, t], g[G_NY, t], g[G_NZ, t], g[G_AI, t], g[G_AJ, t], beta)
    return broke


@nb.njit(cache=True, inline="always")
def _any_active(b0, b1, state):
    """Is any of bonds b0..b1-1 intact or sliding? (Stops at the first: an intact block costs
    one look.)"""
    for b in range(b0, b1):
        if state[b] == INTACT or state[b] == BROKEN_SHEAR_SLIDING:
            return True
    return False


@nb.njit(cache=True, inline="always")
def bond_block(b0, b1, ij, props, fn, fs, mb, mt, length, state, load, pos, vel, om, rad, lz, dt, beta,
               central, g):
    """Step bonds b0..b1-1 (at most BOND_BLOCK) that are active (intact, or JCFpm's sliding):
    update them incrementally, test them for failure, write their loads, each into its own row.
    Velocities must be mid-step values (those that moved the spheres over the last ``dt``).
    ``central``: every bond of the set is central (no velocities read, no block); ``g`` a scratch
    table (N_ROWS or more rows, BOND_BLOCK columns). Returns (bonds that broke, bonds that stopped carrying their pair:
    their contacts start next step). The loads are summed per sphere by
    :func:`dem.kernels.compute_forces`, which runs the blocks in parallel.

    The geometry and spring updates run as loops over the block's columns, which the compiler
    vectorises; each bond's arithmetic is the same IEEE operations in the same order as one bond
    at a time, so the results are too. Central bonds, one square root and one division each, are
    stepped one at a time: through the block they ran slower, the gather costing more than the
    vector loop saved (measured: docs/benchmarks.md, the LAMMPS comparison)."""
    broke = released = 0
    if central:
        for q in range(b0, b1):
            b = unsigned(q)
            if state[b] != INTACT:
                continue
            dx, dy, dz = _centre_vector(unsigned(ij[b, 0]), unsigned(ij[b, 1]), pos, lz)
            d, nx, ny, nz = _unit_axis(dx, dy, dz)
            broke += _central_spring(b, d, nx, ny, nz, props, fn, length, state, load)
        return broke, broke
    if not _any_active(b0, b1, state):  # a block of broken bonds: nothing to gather
        return 0, 0
    m = b1 - b0
    moments = beta > 0.0
    _gather(b0, b1, ij, props, fn, fs, mb, mt, length, pos, vel, om, rad, lz, dt, moments, g)
    _axes(m, g)
    for t in range(m):
        g[G_FN, t] = g[G_FN, t] + g[G_KNA, t] * (g[G_D, t] - g[G_LEN, t])
    _springs(m, g)
    if moments:
        _moments(m, g, dt)
    for t in range(m):
        b = unsigned(b0 + t)
        st = state[b]
        if st != INTACT and st != BROKEN_SHEAR_SLIDING:
            continue
        broke += _finish(b, t, g, props, fn, fs, mb, mt, length, state, load, beta)
        after = state[b]
        released += 1 if after != INTACT and after != BROKEN_SHEAR_SLIDING else 0
    return broke, released


@nb.njit(cache=True, error_model="numpy")
def bond_step(b, ij, props, fn, fs, mb, mt, length, state, load, pos, vel, om, rad, lz, dt, beta):
    """:func:`bond_block` of bond b alone. Returns 1 if it broke, else 0."""
    g = np.empty((N_ROWS, BOND_BLOCK))
    return bond_block(b, b + 1, ij, props, fn, fs, mb, mt, length, state, load, pos, vel, om, rad, lz, dt,
                      beta, False, g)[0]
