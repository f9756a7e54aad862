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
from dataclasses import dataclass

import numba as nb
import numpy as np

from dem.contacts import add_pair_load, rotate_into_plane
from dem.errors import DemInputError

#: bond state codes
INTACT = 0
BROKEN_TENSION = 1
BROKEN_SHEAR = 2
#: "yade_jcfpm" only: broken in shear while in compression, still a frictional spring about
#: the bond's stress-free length (JCFpm keeps the interaction with its ``initD``) until the
#: pair moves apart beyond that length; then BROKEN_SHEAR
BROKEN_SHEAR_SLIDING = 3

# columns of the bond property table
P_AREA, P_RBAR, P_KN, P_KS, P_SIGT, P_COH, P_TANPHI, P_OVERLAP0, P_SIGNED_MC = range(9)
N_PROPS = 9

#: bond conventions of :class:`BondParams`
CONVENTIONS = ("parallel", "yade_jcfpm")


@dataclass(frozen=True)
class BondParams:
    """Parameters of the parallel bonds of an agglomerate.

    Fields
    ------
    kn_Pa_m : normal stiffness per unit area k_n (Pa/m).
    ks_Pa_m : shear stiffness per unit area k_s (Pa/m).
    tensile_strength_Pa : bond tensile strength.
    cohesion_Pa : bond shear strength at zero normal stress.
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
    youngs_modulus_Pa : E of the ``"yade_jcfpm"`` convention (unused by ``"parallel"``).
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
        if self.convention not in CONVENTIONS:
            raise DemInputError(
                f"The 'convention' parameter of BondParams must be one of {CONVENTIONS}. Got {self.convention!r}.")
        if self.convention == "yade_jcfpm":
            e = float(self.youngs_modulus_Pa)
            if not math.isfinite(e) or e <= 0.0:
                raise DemInputError(
                    "The 'youngs_modulus_Pa' parameter of BondParams must be a finite float > 0 "
                    f"with convention 'yade_jcfpm'. Got {e!r}.")
            if float(self.moment_factor) != 0.0 or float(self.radius_multiplier) != 1.0:
                raise DemInputError(
                    "BondParams with convention 'yade_jcfpm' needs moment_factor 0 and "
                    f"radius_multiplier 1 (JCFpm bonds). Got {self.moment_factor!r}, {self.radius_multiplier!r}.")
        for name in ("kn_Pa_m", "ks_Pa_m", "tensile_strength_Pa", "cohesion_Pa",
                     "radius_multiplier"):
            v = float(getattr(self, name))
            if not math.isfinite(v) or v <= 0.0:
                raise DemInputError(
                    f"The '{name}' parameter of BondParams must be a finite float > 0. Got {v!r}.")
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
    tree = cKDTree(pos_m)
    cand = tree.query_pairs(r=factor * 2.0 * float(np.max(radius_m)), output_type="ndarray")
    if cand.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    d = np.linalg.norm(pos_m[cand[:, 1]] - pos_m[cand[:, 0]], axis=1)
    keep = d <= factor * (radius_m[cand[:, 0]] + radius_m[cand[:, 1]])
    pairs = np.sort(cand[keep], axis=1).astype(np.int64)
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return pairs[order]


class BondSet:
    """Arrays of the bonds of one system (intact and broken), created stress-free."""

    def __init__(self, pairs: np.ndarray, pos_m: np.ndarray, radius_m: np.ndarray,
                 params: BondParams) -> None:
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        nbnd = pairs.shape[0]
        self.params = params
        self.ij = pairs
        rbar = params.radius_multiplier * np.minimum(radius_m[pairs[:, 0]], radius_m[pairs[:, 1]])
        self.props = np.zeros((nbnd, N_PROPS))
        self.props[:, P_AREA] = math.pi * rbar**2
        self.props[:, P_RBAR] = rbar
        if params.convention == "yade_jcfpm":
            r1 = radius_m[pairs[:, 0]]
            r2 = radius_m[pairs[:, 1]]
            kn_area = params.youngs_modulus_Pa * 2.0 * r1 * r2 / (r1 + r2)  # N/m, Yade's kn
            self.props[:, P_KN] = kn_area / (math.pi * rbar**2) if nbnd else 0.0
            self.props[:, P_KS] = self.props[:, P_KN] * (params.ks_Pa_m / params.kn_Pa_m)
            self.props[:, P_SIGNED_MC] = 1.0
        else:
            self.props[:, P_KN] = params.kn_Pa_m
            self.props[:, P_KS] = params.ks_Pa_m
        self.props[:, P_SIGT] = params.tensile_strength_Pa
        self.props[:, P_COH] = params.cohesion_Pa
        self.props[:, P_TANPHI] = math.tan(math.radians(params.friction_angle_deg))
        self.fn = np.zeros(nbnd)
        self.fs = np.zeros((nbnd, 3))
        self.mb = np.zeros((nbnd, 3))
        self.mt = np.zeros(nbnd)
        self.state = np.zeros(nbnd, dtype=np.int8)
        self.length = (np.linalg.norm(pos_m[pairs[:, 1]] - pos_m[pairs[:, 0]], axis=1)
                       if nbnd else np.zeros(0))
        # overlap at bonding (packings leave small overlaps): after the bond breaks, the Hertz
        # contact counts only overlap beyond it, so breaking releases no stored contact force
        self.props[:, P_OVERLAP0] = np.maximum(
            0.0, radius_m[pairs[:, 0]] + radius_m[pairs[:, 1]] - self.length) if nbnd else 0.0
        # "yade_jcfpm": P_OVERLAP0 becomes Yade's initD of the frictional contact that follows
        # the bond; it is set at breakage and lowered as the pair separates (bond_forces and
        # kernels.compute_forces)
        self.beta = float(params.moment_factor)
        n = pos_m.shape[0]
        counts = np.bincount(pairs.ravel(), minlength=n) if nbnd else np.zeros(n, dtype=np.int64)
        maxb = max(1, int(counts.max()) if n else 1)
        self.partner = np.full((n, maxb), -1, dtype=np.int64)
        self.index = np.full((n, maxb), -1, dtype=np.int64)
        fill = np.zeros(n, dtype=np.int64)
        for b, (i, j) in enumerate(pairs):
            self.partner[i, fill[i]] = j
            self.index[i, fill[i]] = b
            fill[i] += 1
            self.partner[j, fill[j]] = i
            self.index[j, fill[j]] = b
            fill[j] += 1

    @property
    def n_bonds(self) -> int:
        return int(self.ij.shape[0])

    @property
    def intact(self) -> np.ndarray:
        return self.state == INTACT

    def counts(self) -> dict[str, int]:
        """Numbers of intact bonds and of bonds broken in tension and in shear."""
        return {"intact": int(np.sum(self.state == INTACT)),
                "broken_tension": int(np.sum(self.state == BROKEN_TENSION)),
                "broken_shear": int(np.sum((self.state == BROKEN_SHEAR)
                                           | (self.state == BROKEN_SHEAR_SLIDING)))}

    def stiffness_sums(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Per-sphere sums of translational (N/m) and rotational (N m/rad) bond stiffness."""
        a = self.props[:, P_AREA]
        rb = self.props[:, P_RBAR]
        kt = np.maximum(self.props[:, P_KN], self.props[:, P_KS]) * a
        inertia = math.pi * rb**4 / 4.0
        kr = self.beta * np.maximum(self.props[:, P_KN] * inertia,
                                    self.props[:, P_KS] * 2.0 * inertia)
        k_sum = np.zeros(n)
        r_sum = np.zeros(n)
        for col in (0, 1):
            np.add.at(k_sum, self.ij[:, col], kt)
            np.add.at(r_sum, self.ij[:, col], kr)
        return k_sum, r_sum

    def elastic_energy_J(self) -> float:
        """Strain energy stored in the intact bonds."""
        ok = self.state == INTACT
        a = self.props[ok, P_AREA]
        rb = self.props[ok, P_RBAR]
        kn = self.props[ok, P_KN]
        ks = self.props[ok, P_KS]
        inertia = math.pi * rb**4 / 4.0
        e = (self.fn[ok] ** 2 / (2 * kn * a) + np.sum(self.fs[ok] ** 2, axis=1) / (2 * ks * a))
        if self.beta > 0:
            e = e + (np.sum(self.mb[ok] ** 2, axis=1) / (2 * kn * inertia)
                     + self.mt[ok] ** 2 / (2 * ks * 2 * inertia))
        return float(np.sum(e))

    def damage(self) -> np.ndarray:
        """Current ``max(sigma / tensile strength, tau / shear strength)`` of each bond (0 if broken)."""
        out = np.zeros(self.n_bonds)
        for b in range(self.n_bonds):
            if self.state[b] == INTACT:
                s, t, smax, tmax = bond_stresses(b, self.props, self.fn, self.fs, self.mb,
                                                 self.mt, self.beta)
                out[b] = max(s / smax, t / tmax)
        return out


@nb.njit(cache=True)
def bond_stresses(b, props, b_fn, b_fs, b_mb, b_mt, beta):
    """(sigma, tau, tensile strength, shear strength) of bond b, tension positive."""
    a = props[b, P_AREA]
    rb = props[b, P_RBAR]
    inertia = math.pi * rb**4 / 4.0
    polar = 2.0 * inertia
    fs = math.sqrt(b_fs[b, 0] ** 2 + b_fs[b, 1] ** 2 + b_fs[b, 2] ** 2)
    mb = math.sqrt(b_mb[b, 0] ** 2 + b_mb[b, 1] ** 2 + b_mb[b, 2] ** 2)
    sigma = b_fn[b] / a + beta * mb * rb / inertia
    tau = fs / a + beta * abs(b_mt[b]) * rb / polar
    comp = -b_fn[b] / a
    if comp < 0.0 and props[b, P_SIGNED_MC] == 0.0:
        comp = 0.0
    return sigma, tau, props[b, P_SIGT], props[b, P_COH] + comp * props[b, P_TANPHI]


@nb.njit(cache=True)
def bond_forces(pos, vel, omega, rad, force, torque, lz, dt, b_ij, props, b_fn, b_fs, b_mb,
                b_mt, b_len, b_state, beta):
    """Update every intact bond incrementally, test it for failure and apply its loads.

    Velocities must be mid-step values (those that moved the spheres over the last ``dt``).
    Returns the number of bonds that broke during this call.
    """
    nbroken = 0
    for b in range(b_ij.shape[0]):
        if b_state[b] != INTACT and b_state[b] != BROKEN_SHEAR_SLIDING:
            continue
        i = b_ij[b, 0]
        j = b_ij[b, 1]
        dx = pos[j, 0] - pos[i, 0]
        dy = pos[j, 1] - pos[i, 1]
        dz = pos[j, 2] - pos[i, 2]
        if lz > 0.0:
            dz -= lz * math.floor(dz / lz + 0.5)
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        nx = dx / d
        ny = dy / d
        nz = dz / d
        a = props[b, P_AREA]
        rb = props[b, P_RBAR]
        kn = props[b, P_KN]
        ks = props[b, P_KS]
        inertia = math.pi * rb**4 / 4.0
        polar = 2.0 * inertia
        # bond centre: midway across the gap between the surfaces
        gap = d - rad[i] - rad[j]
        ai = rad[i] + 0.5 * gap
        aj = rad[j] + 0.5 * gap
        if props[b, P_SIGNED_MC] != 0.0:
            # "yade_jcfpm": Yade's ScGeom::getIncidentVel (avoidGranularRatcheting): centre
            # velocities scaled by (R1+R2)/d, spins times the sphere radii
            alpha = (rad[i] + rad[j]) / d
            qi = rad[i]
            qj = rad[j]
        else:
            alpha = 1.0
            qi = ai
            qj = aj
        vix = alpha * vel[i, 0] + qi * (omega[i, 1] * nz - omega[i, 2] * ny)
        viy = alpha * vel[i, 1] + qi * (omega[i, 2] * nx - omega[i, 0] * nz)
        viz = alpha * vel[i, 2] + qi * (omega[i, 0] * ny - omega[i, 1] * nx)
        vjx = alpha * vel[j, 0] - qj * (omega[j, 1] * nz - omega[j, 2] * ny)
        vjy = alpha * vel[j, 1] - qj * (omega[j, 2] * nx - omega[j, 0] * nz)
        vjz = alpha * vel[j, 2] - qj * (omega[j, 0] * ny - omega[j, 1] * nx)
        vrx = vjx - vix
        vry = vjy - viy
        vrz = vjz - viz
        vn = vrx * nx + vry * ny + vrz * nz
        # normal: dF_n = k_n A du_n with du_n the exact change of the centre distance
        b_fn[b] += kn * a * (d - b_len[b])
        b_len[b] = d
        # shear: rotate the stored force into the new tangent plane, then dF_s = -k_s A du_s
        rotate_into_plane(b_fs, b, nx, ny, nz)
        b_fs[b, 0] -= ks * a * (vrx - vn * nx) * dt
        b_fs[b, 1] -= ks * a * (vry - vn * ny) * dt
        b_fs[b, 2] -= ks * a * (vrz - vn * nz) * dt
        if beta > 0.0:
            wx = (omega[j, 0] - omega[i, 0]) * dt
            wy = (omega[j, 1] - omega[i, 1]) * dt
            wz = (omega[j, 2] - omega[i, 2]) * dt
            wt = wx * nx + wy * ny + wz * nz
            b_mt[b] -= ks * polar * wt
            rotate_into_plane(b_mb, b, nx, ny, nz)
            b_mb[b, 0] -= kn * inertia * (wx - wt * nx)
            b_mb[b, 1] -= kn * inertia * (wy - wt * ny)
            b_mb[b, 2] -= kn * inertia * (wz - wt * nz)
        if b_state[b] == BROKEN_SHEAR_SLIDING:
            # JCFpm after a shear break: no tension (the interaction is erased when the pair
            # is farther apart than at bonding), Coulomb friction |F_s| <= -F_n tan(phi)
            if b_fn[b] > 0.0:
                b_state[b] = BROKEN_SHEAR
                pen = rad[i] + rad[j] - d
                props[b, P_OVERLAP0] = pen if pen > 0.0 else 0.0
                b_fn[b] = 0.0
                b_fs[b, 0] = 0.0
                b_fs[b, 1] = 0.0
                b_fs[b, 2] = 0.0
                continue
            fsm = math.sqrt(b_fs[b, 0] ** 2 + b_fs[b, 1] ** 2 + b_fs[b, 2] ** 2)
            lim = -b_fn[b] * props[b, P_TANPHI]
            if fsm > lim:
                sc = lim / fsm
                b_fs[b, 0] *= sc
                b_fs[b, 1] *= sc
                b_fs[b, 2] *= sc
        else:
            sigma, tau, smax, tmax = bond_stresses(b, props, b_fn, b_fs, b_mb, b_mt, beta)
            if sigma > smax:
                b_state[b] = BROKEN_TENSION
            elif tau > tmax:
                b_state[b] = BROKEN_SHEAR
                if props[b, P_SIGNED_MC] != 0.0 and b_fn[b] <= 0.0:
                    # JCFpm: the pair stays in frictional contact about its bonding distance;
                    # this step the shear force is cut to the strength it exceeded
                    b_state[b] = BROKEN_SHEAR_SLIDING
                    fsm = math.sqrt(b_fs[b, 0] ** 2 + b_fs[b, 1] ** 2 + b_fs[b, 2] ** 2)
                    sc = tmax * a / fsm
                    b_fs[b, 0] *= sc
                    b_fs[b, 1] *= sc
                    b_fs[b, 2] *= sc
                    nbroken += 1
            if b_state[b] == BROKEN_SHEAR_SLIDING:
                pass
            elif b_state[b] != INTACT and props[b, P_SIGNED_MC] != 0.0:
                # JCFpm erases the interaction; a new (stress-free) contact forms at the
                # current overlap if the spheres still overlap
                pen = rad[i] + rad[j] - d
                props[b, P_OVERLAP0] = pen if pen > 0.0 else 0.0
        if b_state[b] != INTACT and b_state[b] != BROKEN_SHEAR_SLIDING:
            nbroken += 1
            b_fn[b] = 0.0
            b_fs[b, 0] = 0.0
            b_fs[b, 1] = 0.0
            b_fs[b, 2] = 0.0
            b_mb[b, 0] = 0.0
            b_mb[b, 1] = 0.0
            b_mb[b, 2] = 0.0
            b_mt[b] = 0.0
            continue
        # loads on j: -F_n n (tension pulls j back) + F_s ; on i the opposite
        fx = -b_fn[b] * nx + b_fs[b, 0]
        fy = -b_fn[b] * ny + b_fs[b, 1]
        fz = -b_fn[b] * nz + b_fs[b, 2]
        add_pair_load(force, torque, i, j, fx, fy, fz, nx, ny, nz, ai, aj)
        if beta > 0.0:
            mx = b_mb[b, 0] + b_mt[b] * nx
            my = b_mb[b, 1] + b_mt[b] * ny
            mz = b_mb[b, 2] + b_mt[b] * nz
            torque[j, 0] += mx
            torque[j, 1] += my
            torque[j, 2] += mz
            torque[i, 0] -= mx
            torque[i, 1] -= my
            torque[i, 2] -= mz
    return nbroken
