"""`System`: the state of one DEM simulation; it holds arrays and calls the numba kernels.

Spheres (positions, velocities, spins, radii, masses), optional bonds (:class:`dem.bonds.BondSet`),
planar walls (platens, anvil, drop weight), an optional rotating drum with lifters, gravity,
optional periodicity along z. The time step is ``time_step_factor`` times the critical step
(the smaller of the Rayleigh step of the smallest sphere and the bond-spring step, see
:mod:`dem.materials`); a user time step above the critical one is refused.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numba
import numpy as np
from numba.core.errors import NumbaPerformanceWarning

from dem import kernels as K
from dem.bonds import BROKEN_SHEAR_SLIDING, INTACT, P_LENGTH0, P_OVERLAP0, BondParams, BondSet
from dem.contacts import CONTACT_LAW_HERTZ_MINDLIN, CONTACT_LAW_LINEAR_YADE
from dem.errors import DemInputError, DemInstabilityError
from dem.materials import (RAYLEIGH_SAFETY_FACTOR, STEEL, Material, bond_time_step_s, check_density,
                           damping_coefficient, effective_shear_Pa, effective_youngs_Pa,
                           rayleigh_time_step_s)
from dem.state import DrumArrays, SphereArrays, WallArrays

#: default energy classes of the collision histograms: log10(E/J) from -9 to 2 in 0.25 steps
HIST_LO_LOG10 = -9.0
HIST_DLOG10 = 0.25
HIST_NBINS = 44

#: systems of fewer spheres run their steps on one thread: a step has two parallel regions,
#: and each costs a barrier. On a quiet machine (with three regions a step) two threads gained
#: from the smallest size measured, 500 spheres (1.1-1.5x in wall time; the drum's 504 balls
#: 1.05x), and 1.7-1.9x from 1,000 to 32,000 (benchmarks/results/dem_parallel_scale.md,
#: dem_parallel_drum.md)
PARALLEL_MIN_SPHERES = 500

#: how far from 1 the length of a wall's normal may be (a normal typed to six digits, 0.707107,
#: passes and is scaled to unit length): a normal of another length, (1, 1, 0) for
#: (0.7071, 0.7071, 0) or a typo, is refused rather than scaled into another wall than written
WALL_NORMAL_TOL = 1e-6

#: ``contact_law`` choices of :class:`System`: Hertz–Mindlin with restitution damping
#: (default) or Yade's linear spring (``Law2_ScGeom_FrictPhys_CundallStrack``; the material's
#: ``poisson_ratio`` is then Yade's ks/kn ratio; see :data:`dem.contacts.CONTACT_LAW_LINEAR_YADE`)
CONTACT_LAWS = {"hertz_mindlin": float(CONTACT_LAW_HERTZ_MINDLIN),
                "linear_yade": float(CONTACT_LAW_LINEAR_YADE)}


@dataclass
class PlaneWall:
    """An infinite plane: a point on it, the unit normal pointing into the domain (length 1 within
    :data:`WALL_NORMAL_TOL`), its velocity. Every sphere centre must start on the normal's side.

    ``mass_kg > 0`` makes it a free body moving along its normal (a drop weight).
    """

    point_m: tuple[float, float, float]
    normal: tuple[float, float, float]
    velocity_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mass_kg: float = 0.0


@dataclass
class DrumGeometry:
    """Drum shell of radius ``radius_m`` about the z axis, rotating at ``omega_rad_s`` (counter-clockwise).

    ``n_lifters`` equally spaced radial lifter bars of ``lifter_height_m`` and
    ``lifter_width_m`` (rounded ends).
    """

    radius_m: float
    omega_rad_s: float
    n_lifters: int = 0
    lifter_height_m: float = 0.0
    lifter_width_m: float = 0.0


@dataclass
class Records:
    """Per-step records of a run (appended chunk by chunk)."""

    wall_force_N: list = field(default_factory=list)
    wall_pos_m: list = field(default_factory=list)
    torque_Nm: list = field(default_factory=list)
    broken: list = field(default_factory=list)


class System:
    """State of one DEM run; see the module docstring.

    The kernels' bundles (:mod:`dem.state`): ``spheres``, ``bonds.arrays``, ``pairs``,
    ``walls``, ``drum_arrays``; ``pos``, ``vel``, ``omega``, ``rad``, ``mass``, ``inertia``,
    ``force``, ``torque`` and ``w_p``, ``w_n``, ``w_v``, ``w_mass``, ``w_f``, ``w_xi``,
    ``w_in`` name the same arrays.
    """

    def __init__(self, pos_m, radius_m, material: Material, *, density_kg_m3=None,
                 bonds: BondSet | None = None, wall_material: Material = STEEL,
                 walls: list[PlaneWall] | None = None, drum: DrumGeometry | None = None,
                 gravity_m_s2=(0.0, 0.0, 0.0), periodic_z_m: float = 0.0,
                 local_damping: float = 0.0, time_step_factor: float = RAYLEIGH_SAFETY_FACTOR,
                 dt_s: float | None = None, skin_fraction: float = 0.3,
                 contact_law: str = "hertz_mindlin", damping_velocity: str = "mid_step") -> None:
        pos, rad = _checked_spheres(pos_m, radius_m)
        _check_options(local_damping, time_step_factor, contact_law, damping_velocity)
        _check_law_restitution(contact_law, material, wall_material if walls or drum is not None else None)
        periodic_z_m, gravity_m_s2 = _check_setup(rad, material, wall_material, density_kg_m3, bonds,
                                                  walls, drum, gravity_m_s2, periodic_z_m, skin_fraction)
        _check_placement(pos, rad, bonds, walls or [], drum, periodic_z_m)
        n = pos.shape[0]
        self.n = n
        self.contact_law = contact_law
        self.material = material
        self.wall_material = wall_material
        rho = material.density_kg_m3 if density_kg_m3 is None else float(density_kg_m3)
        self.density_kg_m3 = rho
        mass = rho * 4.0 / 3.0 * math.pi * rad**3
        self.spheres = SphereArrays(pos, np.zeros((n, 3)), np.zeros((n, 3)), rad, mass,
                                    0.4 * mass * rad**2, np.zeros((n, 3)), np.zeros((n, 3)))
        (self.pos, self.vel, self.omega, self.rad, self.mass, self.inertia, self.force,
         self.torque) = self.spheres
        self.bonds = bonds if bonds is not None else BondSet(
            np.zeros((0, 2), dtype=np.int64), pos, rad, BondParams(moment_factor=0.0))
        self.walls = _wall_arrays(walls or [], n)
        (self.w_p, self.w_n, self.w_v, self.w_mass, self.w_f, self.w_xi, self.w_in, _, _) = self.walls
        self.drum = drum
        nl = drum.n_lifters if drum is not None else 0
        self.drum_arrays = DrumArrays(np.arange(nl) * (2.0 * math.pi / max(nl, 1)),
                                      np.zeros((n, 1 + nl, 3)), np.zeros((n, 1 + nl), dtype=np.int8),
                                      np.full((n, 1 + nl), -1.0), np.zeros(n))
        self.drum_angle = 0.0
        self.cp = _contact_parameters(material, wall_material, contact_law, local_damping,
                                      damping_velocity, gravity_m_s2, periodic_z_m,
                                      skin_fraction * float(np.min(rad)), self.bonds, drum)
        self.hist_pp = np.zeros(HIST_NBINS)
        self.hist_pw = np.zeros(HIST_NBINS)
        self._set_time_step(time_step_factor, dt_s)
        self.time_s = 0.0
        self.steps = 0
        self.records = Records()
        self.pos_ref = self.pos.copy()
        self.pairs = K.new_pair_arrays(*K.build_neighbour_list(
            self.pos, self.rad, self.cp[K.CP_SKIN], self.cp[K.CP_LZ], self.bonds.partner,
            self.bonds.index), self.bonds.state)
        _check_pair_distances(self.pos, self.rad, self.pairs.i, self.pairs.j, periodic_z_m)
        self._forces(0.0)

    def _set_time_step(self, time_step_factor: float, dt_s: float | None) -> None:
        """Critical step: the smaller of the contact step (Rayleigh, or for linear springs
        ``sqrt(m / k)`` of a sphere on one platen and one sphere) and the bond-spring step."""
        m = self.material
        cp = self.cp
        if self.contact_law == "linear_yade":
            k_c = 2.0 * (cp[K.CP_ESTAR_PW] + 0.5 * cp[K.CP_ESTAR_PP]) * self.rad
            dt_r = float(np.min(np.sqrt(self.mass / k_c)))
        else:
            mat_for_dt = Material(m.youngs_modulus_Pa, m.poisson_ratio, self.density_kg_m3,
                                  m.friction_coef, m.restitution)
            dt_r = rayleigh_time_step_s(float(np.min(self.rad)), mat_for_dt)
        k_sum, r_sum = self.bonds.stiffness_sums(self.n, self.rad)
        dt_b = bond_time_step_s(self.mass, self.inertia, k_sum, r_sum)
        self.critical_dt_s = min(dt_r, dt_b)
        self.rayleigh_dt_s = dt_r
        self.bond_dt_s = dt_b
        self.dt_s = time_step_factor * self.critical_dt_s if dt_s is None else dt_s

    @property
    def dt_s(self) -> float:
        """The time step (s), in (0, ``critical_dt_s``]; assigning it is checked as the
        constructor's ``dt_s`` is (past the critical step a run may blow up or, before it does,
        break bonds and miss forces without a word: benchmarks/results/dem_time_step.md).
        Stability studies go past it with :meth:`set_dt_beyond_critical`."""
        return self._dt_s

    @dt_s.setter
    def dt_s(self, value: float) -> None:
        dt = _finite("System", "dt_s", value, 0.0, lo_open=True)
        if dt > self.critical_dt_s:
            raise DemInputError(
                f"The 'dt_s' parameter of System must be a float in (0, {self.critical_dt_s:.4g}] (the critical "
                f"time step; set_dt_beyond_critical for stability studies). Got {value!r}.")
        self._dt_s = dt

    def set_dt_beyond_critical(self, dt_s: float) -> None:
        """Set a time step (s, finite and > 0) past ``critical_dt_s`` on purpose: for studies of
        where the integration becomes unstable only; the results of such a run are not trusted."""
        self._dt_s = _finite("System.set_dt_beyond_critical", "dt_s", dt_s, 0.0, lo_open=True)

    # ------------------------------------------------------------------
    @property
    def pi(self) -> np.ndarray:
        return self.pairs.i

    @property
    def pj(self) -> np.ndarray:
        return self.pairs.j

    @property
    def pb(self) -> np.ndarray:
        return self.pairs.bond

    def _forces(self, dt: float):
        """Evaluate the forces at the current state; returns (drum torque, bonds broken). Every
        argument typed as run_steps passes it, so numba compiles one copy of the kernel."""
        return K.compute_forces(self.spheres, self.bonds.arrays, self.pairs, self.walls,
                                self.drum_arrays, self.cp, dt, self.drum_angle, self.hist_pp,
                                self.hist_pw, False, False, self.pos_ref, 0.0)[:2]

    def run(self, n_steps: int) -> None:
        """Advance ``n_steps`` steps (a whole number >= 0) and append the per-step records.

        Raises :class:`DemInstabilityError` if the state is not finite after any step: the run
        stops there, and its records up to that step are kept."""
        n_steps = _checked_step_count(n_steps)
        if n_steps == 0:
            return
        nw = self.w_p.shape[0]
        rec_f = np.zeros((n_steps, nw))
        rec_p = np.zeros((n_steps, nw))
        rec_t = np.zeros(n_steps)
        rec_b = np.zeros(n_steps, dtype=np.int64)
        threads = numba.get_num_threads()
        if self.n < PARALLEL_MIN_SPHERES:
            numba.set_num_threads(1)
        try:
            done, status = self._advance(n_steps, rec_f, rec_p, rec_t, rec_b)
        finally:
            numba.set_num_threads(threads)
        self.steps += done
        self.time_s += done * self.dt_s
        self.records.wall_force_N.append(rec_f[:done])
        self.records.wall_pos_m.append(rec_p[:done])
        self.records.torque_Nm.append(rec_t[:done])
        self.records.broken.append(rec_b[:done])
        if status == K.STATUS_OK and not self._state_finite():
            # the kernel samples three numbers after a step's forces and checks every position
            # at the next drift only: a force gone non-finite in the call's last step is found here
            status = K.STATUS_NONFINITE
        if status == K.STATUS_NONFINITE:
            raise DemInstabilityError(
                f"Non-finite state at step {self.steps} (t = {self.time_s:.4g} s, dt = {self.dt_s:.3g} s); "
                "reduce time_step_factor or check the material parameters.")

    def _advance(self, n_steps, rec_f, rec_p, rec_t, rec_b) -> tuple[int, int]:
        """The kernel's steps, the neighbour list rebuilt between calls when it asks (see
        :func:`dem.kernels.run_steps`). Returns (steps done, status)."""
        done, status, drifted = 0, K.STATUS_REBUILD, False
        while status == K.STATUS_REBUILD:
            with warnings.catch_warnings():
                # run_steps has no parallel loop of its own but must be compiled parallel=True
                # (see dem.kernels.compute_forces); numba says so when it compiles it
                warnings.filterwarnings("ignore", message=r"(?s).*no transformation for parallel",
                                        category=NumbaPerformanceWarning)
                status, k, self.drum_angle = self._run_steps(n_steps - done, drifted, rec_f[done:],
                                                             rec_p[done:], rec_t[done:], rec_b[done:])
            done += k
            drifted = status == K.STATUS_REBUILD
            if drifted:
                self.pairs = K.rebuild_pairs(self.spheres, self.bonds.arrays, self.pairs,
                                             self.cp[K.CP_SKIN], self.cp[K.CP_LZ])
                self.pos_ref[:, :] = self.pos
        return done, status

    def _run_steps(self, n_steps, drifted, rec_f, rec_p, rec_t, rec_b):
        return K.run_steps(n_steps, self.dt_s, self.spheres, self.bonds.arrays, self.pairs,
                           self.walls, self.drum_arrays, self.cp, self.pos_ref, self.drum_angle,
                           self.hist_pp, self.hist_pw, rec_f, rec_p, rec_t, rec_b, drifted)

    def _state_finite(self) -> bool:
        """Every sphere's position, velocity, spin, force and torque, and the walls' positions,
        velocities and forces are finite."""
        return all(bool(np.isfinite(a).all()) for a in (self.pos, self.vel, self.omega, self.force,
                                                        self.torque, self.w_p, self.w_v, self.w_f))

    def set_wall_velocity(self, k: int, velocity_m_s) -> None:
        """Set the velocity (m/s, 3 finite components) of wall ``k``."""
        nw = self.w_p.shape[0]
        if not (isinstance(k, (int, np.integer)) and -nw <= k < nw):
            raise DemInputError(
                f"The 'k' parameter of System.set_wall_velocity must be a wall index in [0, {nw}). Got {k!r}.")
        self.w_v[k, :] = _vector3("set_wall_velocity", "velocity_m_s", velocity_m_s)

    def record_arrays(self) -> dict[str, np.ndarray]:
        """Concatenated per-step records."""
        r = self.records
        nw = self.w_p.shape[0]
        cat = (lambda lst, shape: np.concatenate(lst) if lst else np.zeros(shape))
        return {"wall_force_N": cat(r.wall_force_N, (0, nw)), "wall_pos_m": cat(r.wall_pos_m, (0, nw)),
                "torque_Nm": cat(r.torque_Nm, (0,)), "broken": cat(r.broken, (0,))}

    # energies ------------------------------------------------------------
    def kinetic_energy_J(self) -> float:
        return float(0.5 * np.sum(self.mass[:, None] * self.vel**2)
                     + 0.5 * np.sum(self.inertia[:, None] * self.omega**2))

    def contact_energy_J(self) -> float:
        """Normal strain energy of sphere–sphere contacts not held by an intact bond (Hertz
        ``8/15 E* sqrt(R*) delta^2.5``; linear law ``k_n delta^2 / 2``)."""
        e_star = self.cp[K.CP_ESTAR_PP]
        lz = self.cp[K.CP_LZ]
        tot = 0.0
        for k in range(self.pi.shape[0]):
            b = self.pb[k]
            ov0 = 0.0
            if b >= 0:
                if self.bonds.state[b] in (INTACT, BROKEN_SHEAR_SLIDING):  # held by the bond
                    continue
                ov0 = self.bonds.props[b, P_OVERLAP0]
            i, j = self.pi[k], self.pj[k]
            d = self.pos[j] - self.pos[i]
            if lz > 0:
                d[2] -= lz * math.floor(d[2] / lz + 0.5)
            delta = self.rad[i] + self.rad[j] - ov0 - float(np.linalg.norm(d))
            if delta > 0:
                r_eff = self.rad[i] * self.rad[j] / (self.rad[i] + self.rad[j])
                if self.contact_law == "linear_yade":
                    tot += e_star * r_eff * delta**2
                else:
                    tot += 8.0 / 15.0 * e_star * math.sqrt(r_eff) * delta**2.5
        return tot

    def total_energy_J(self) -> float:
        return self.kinetic_energy_J() + self.contact_energy_J() + self.bonds.elastic_energy_J()


def _checked_spheres(pos_m, radius_m) -> tuple[np.ndarray, np.ndarray]:
    """Fresh C-ordered float64 copies (integer, Fortran-ordered or strided input alike) of the
    centres, shape (n, 3) (or (3,) for one sphere), and of the radii, one per sphere."""
    arrays = []
    for name, value in (("pos_m", pos_m), ("radius_m", radius_m)):
        try:
            arrays.append(np.array(value, dtype=np.float64))
        except (TypeError, ValueError):
            raise DemInputError(
                f"The '{name}' parameter of System must be an array of numbers (m). Got {value!r}.") from None
    pos, rad = arrays
    if pos.shape == (3,):
        pos = pos.reshape(1, 3)
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] < 1:
        raise DemInputError(
            "The 'pos_m' parameter of System must be an (n, 3) array of sphere centres (m), n >= 1. "
            f"Got shape {pos.shape}.")
    rad = rad.reshape(-1)
    n = pos.shape[0]
    if rad.shape[0] != n:
        raise DemInputError(
            f"The 'radius_m' parameter of System must have one entry per sphere ({n}). Got {rad.shape[0]}.")
    if not np.all(np.isfinite(pos)):
        raise DemInputError("The 'pos_m' parameter of System must be finite. Got non-finite entries.")
    if np.any(rad <= 0) or not np.all(np.isfinite(rad)):
        raise DemInputError(
            f"The 'radius_m' parameter of System must be finite and > 0. Got min {rad.min()!r}.")
    return pos, rad


def _vector3(owner: str, name: str, value) -> np.ndarray:
    """``value`` as 3 finite floats, or a DemInputError naming it."""
    try:
        v = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        v = np.zeros(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise DemInputError(f"The '{name}' parameter of {owner} must be 3 finite floats (x, y, z). Got {value!r}.")
    return v


def _finite(owner: str, name: str, value, lo: float, hi: float = math.inf, lo_open: bool = False) -> float:
    """``value`` as a finite float in [lo, hi] ((lo, hi] with ``lo_open``), or a DemInputError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if isinstance(value, (bool, np.bool_, str)) or not (math.isfinite(v) and (v > lo if lo_open else v >= lo)
                                                        and v <= hi):
        raise DemInputError(
            f"The '{name}' parameter of {owner} must be a finite float in {'(' if lo_open else '['}{lo}, {hi}]. "
            f"Got {value!r}.")
    return v


def _checked_step_count(n_steps) -> int:
    """A whole number of steps >= 0 (a float such as 1e4 is taken if it is whole)."""
    ok = isinstance(n_steps, (int, np.integer, float, np.floating)) and not isinstance(n_steps, (bool, np.bool_))
    if ok:
        f = float(n_steps)
        ok = math.isfinite(f) and f >= 0 and f == math.floor(f)
    if not ok:
        raise DemInputError(f"The 'n_steps' parameter of System.run must be a whole number >= 0. Got {n_steps!r}.")
    return int(n_steps)


def _check_setup(rad, material, wall_material, density_kg_m3, bonds, walls, drum, gravity_m_s2,
                 periodic_z_m, skin_fraction) -> tuple[float, np.ndarray]:
    """System's arguments besides the spheres, checked before any array is built. Returns the
    periodic length and gravity as checked numbers."""
    o = "System"
    for name, m in (("material", material), ("wall_material", wall_material)):
        if not isinstance(m, Material):
            raise DemInputError(f"The '{name}' parameter of System must be a dem.materials.Material. Got {m!r}.")
    if density_kg_m3 is not None:
        check_density(o, "density_kg_m3", density_kg_m3)
    g = _vector3(o, "gravity_m_s2", gravity_m_s2)
    lz = _finite(o, "periodic_z_m", periodic_z_m, 0.0)
    if 0.0 < lz < 4.0 * float(np.max(rad)):
        raise DemInputError(
            "The 'periodic_z_m' parameter of System must be 0 (not periodic) or at least two largest "
            f"sphere diameters ({4.0 * float(np.max(rad)):.4g} m; a sphere must meet one image of a "
            f"neighbour only). Got {periodic_z_m!r}.")
    _finite(o, "skin_fraction", skin_fraction, 0.0, 2.0, lo_open=True)
    if bonds is not None:
        if not isinstance(bonds, BondSet):
            raise DemInputError(f"The 'bonds' parameter of System must be a dem.bonds.BondSet or None. Got {bonds!r}.")
        if bonds.n_spheres != rad.shape[0]:
            raise DemInputError(
                f"The 'bonds' parameter of System must be a BondSet made for its {rad.shape[0]} spheres. "
                f"Got one made for {bonds.n_spheres}.")
    for k, w in enumerate(walls or []):
        if not isinstance(w, PlaneWall):
            raise DemInputError(f"The 'walls' parameter of System must be a list of PlaneWall. Got {w!r} at {k}.")
        _vector3(o, f"walls[{k}].point_m", w.point_m)
        _vector3(o, f"walls[{k}].velocity_m_s", w.velocity_m_s)
        norm = float(np.linalg.norm(_vector3(o, f"walls[{k}].normal", w.normal)))
        if not abs(norm - 1.0) <= WALL_NORMAL_TOL:
            raise DemInputError(
                f"The 'walls[{k}].normal' parameter of System must be a unit vector (length 1 within "
                f"{WALL_NORMAL_TOL:g}; divide it by its length {norm:.6g} if that wall is meant). Got {w.normal!r}.")
        _finite(o, f"walls[{k}].mass_kg", w.mass_kg, 0.0)
    if drum is not None:
        if not isinstance(drum, DrumGeometry):
            raise DemInputError(f"The 'drum' parameter of System must be a DrumGeometry or None. Got {drum!r}.")
        r_d = _finite(o, "drum.radius_m", drum.radius_m, 0.0, lo_open=True)
        _finite(o, "drum.omega_rad_s", drum.omega_rad_s, -math.inf)
        nl = drum.n_lifters
        if not (isinstance(nl, (int, np.integer)) and not isinstance(nl, (bool, np.bool_)) and 0 <= nl <= 64):
            raise DemInputError(f"The 'drum.n_lifters' parameter of System must be an int in [0, 64]. Got {nl!r}.")
        _finite(o, "drum.lifter_height_m", drum.lifter_height_m, 0.0, r_d)
        _finite(o, "drum.lifter_width_m", drum.lifter_width_m, 0.0, r_d)
    return lz, g


def _check_placement(pos, rad, bonds, walls, drum, lz) -> None:
    """Spheres in front of every wall and inside the drum; bonds at the length they were made (a
    BondSet of other positions would start pre-stressed, and a bond across the periodic boundary
    would take the image's distance). A centre behind a wall (a normal of the wrong sign) has an
    overlap of its radius plus its depth: a Hertz force far outside the law's range."""
    for k, w in enumerate(walls):
        n = np.asarray(w.normal, dtype=np.float64)
        h = (pos - np.asarray(w.point_m, dtype=np.float64)) @ (n / np.linalg.norm(n))
        behind = np.nonzero(h <= 0.0)[0]
        if behind.size:
            i = int(behind[0])
            raise DemInputError(
                f"The 'walls[{k}]' parameter of System must have every sphere centre on the side its normal "
                f"{tuple(w.normal)} points to. Got sphere {i} at {pos[i].tolist()}, {-h[i]:.4g} m behind the "
                f"plane ({behind.size} behind; is the normal's sign right?).")
    if drum is not None:
        out = np.nonzero(np.hypot(pos[:, 0], pos[:, 1]) >= drum.radius_m)[0]
        if out.size:
            raise DemInputError(
                f"The 'pos_m' parameter of System must put every sphere centre inside the drum (radius "
                f"{drum.radius_m!r} m about the z axis). Got sphere {int(out[0])} at {pos[out[0]].tolist()} "
                f"({out.size} outside).")
        _check_lifters(pos, drum)
    if bonds is not None and bonds.n_bonds:
        d = pos[bonds.ij[:, 1]] - pos[bonds.ij[:, 0]]
        if lz > 0:
            d[:, 2] -= lz * np.floor(d[:, 2] / lz + 0.5)
        length = np.linalg.norm(d, axis=1)
        tol = 1e-9 * (rad[bonds.ij[:, 0]] + rad[bonds.ij[:, 1]])
        bad = np.nonzero(np.abs(length - bonds.props[:, P_LENGTH0]) > tol)[0]
        if bad.size:
            b = int(bad[0])
            raise DemInputError(
                f"The 'bonds' parameter of System must be a BondSet made at these positions: bond {b} "
                f"(spheres {bonds.ij[b].tolist()}) was made {bonds.props[b, P_LENGTH0]:.6g} m long, its spheres "
                f"are {length[b]:.6g} m apart here ({bad.size} bonds differ; a bond across the periodic "
                "boundary is not supported).")


def _check_lifters(pos, drum: DrumGeometry) -> None:
    """No sphere centre inside a lifter bar at the start (drum angle 0): the bar is the capsule
    of :func:`dem.contacts.drum_walls`, a radial segment from the shell inwards of height
    ``lifter_height_m``, widened by half ``lifter_width_m``."""
    r_d, h, hw = float(drum.radius_m), float(drum.lifter_height_m), 0.5 * float(drum.lifter_width_m)
    for k in range(drum.n_lifters):
        a = k * (2.0 * math.pi / drum.n_lifters)    # the lifter angles System gives the kernels
        u = np.array([math.cos(a), math.sin(a)])
        s = np.clip(r_d - pos[:, :2] @ u, 0.0, h)
        inside = np.nonzero(np.linalg.norm(pos[:, :2] - (r_d - s)[:, None] * u, axis=1) < hw)[0]
        if inside.size:
            raise DemInputError(
                f"The 'pos_m' parameter of System must put no sphere centre inside a lifter bar of the drum. Got "
                f"sphere {int(inside[0])} at {pos[inside[0]].tolist()} inside lifter {k} ({inside.size} inside).")


def _check_pair_distances(pos, rad, pi, pj, lz) -> None:
    """No sphere centre inside another sphere (coincident centres give no contact normal; the
    Hertz law is far outside its range there): usually positions and radii in different units."""
    if pi.shape[0] == 0:
        return
    d = pos[pj] - pos[pi]
    if lz > 0:
        d[:, 2] -= lz * np.floor(d[:, 2] / lz + 0.5)
    dist = np.linalg.norm(d, axis=1)
    bad = np.nonzero(dist < np.maximum(rad[pi], rad[pj]))[0]
    if bad.size:
        k = int(bad[0])
        i, j = int(pi[k]), int(pj[k])
        raise DemInputError(
            "The 'pos_m' parameter of System must not put a sphere centre inside another sphere "
            f"(centre distance at least the larger radius). Got spheres {i} and {j} {dist[k]:.4g} m apart "
            f"with radii {rad[i]:.4g} and {rad[j]:.4g} m ({bad.size} such pairs; are pos_m and radius_m "
            "in the same unit, m?).")


def _check_options(local_damping, time_step_factor, contact_law, damping_velocity) -> None:
    if not (0.0 <= local_damping < 1.0):
        raise DemInputError(
            f"The 'local_damping' parameter of System must be a float in [0, 1). Got {local_damping!r}.")
    if not (0.0 < time_step_factor <= 1.0):
        raise DemInputError(
            f"The 'time_step_factor' parameter of System must be a float in (0, 1]. Got {time_step_factor!r}.")
    if contact_law not in CONTACT_LAWS:
        raise DemInputError(
            f"The 'contact_law' parameter of System must be one of {sorted(CONTACT_LAWS)}. Got {contact_law!r}.")
    if damping_velocity not in ("mid_step", "at_force"):
        raise DemInputError(
            "The 'damping_velocity' parameter of System must be 'mid_step' or 'at_force'. "
            f"Got {damping_velocity!r}.")


def _check_law_restitution(contact_law, material, wall_material) -> None:
    """Yade's linear law (Law2_ScGeom_FrictPhys_CundallStrack) has no viscous damping, and the kernels'
    damping is solved for a Hertz spring (materials.damping_coefficient): on a linear spring e = 0.3 gave
    0.326. Energy leaves the Yade mirror by Cundall's local damping, so its restitutions are 1 (the wall's, if
    the system has walls: ``wall_material`` None otherwise)."""
    if contact_law != "linear_yade":
        return
    for owner, m in (("material", material), ("wall_material", wall_material)):
        if m is not None and m.restitution != 1.0:
            raise DemInputError(
                f"The '{owner}' of System has restitution {m.restitution!r}; contact_law 'linear_yade' (Yade's "
                "undamped linear law) takes restitution 1 (energy leaves by local_damping), or use 'hertz_mindlin'.")


def _wall_arrays(walls: list[PlaneWall], n: int) -> WallArrays:
    nw = len(walls)
    wn = np.array([w.normal for w in walls], dtype=np.float64).reshape(nw, 3)
    if nw:
        wn /= np.linalg.norm(wn, axis=1)[:, None]
    return WallArrays(np.array([w.point_m for w in walls], dtype=np.float64).reshape(nw, 3), wn,
                      np.array([w.velocity_m_s for w in walls], dtype=np.float64).reshape(nw, 3),
                      np.array([w.mass_kg for w in walls], dtype=np.float64).reshape(nw),
                      np.zeros((nw, 3)), np.zeros((n, nw, 3)), np.zeros((n, nw), dtype=np.int8),
                      np.zeros((n, nw, 3)), np.full((n, nw), -1.0))


def _contact_parameters(material, wall_material, contact_law, local_damping, damping_velocity,
                        gravity_m_s2, periodic_z_m, skin_m, bonds, drum) -> np.ndarray:
    """The kernels' scalar parameter vector (indices ``kernels.CP_*``). A sphere-wall pair takes the
    geometric mean of the two restitutions and the lower friction coefficient: a convention of this
    package (EDEM and LIGGGHTS take a value per pair of materials, given by the user)."""
    cp = np.zeros(K.N_CP)
    cp[K.CP_ESTAR_PP] = effective_youngs_Pa(material, material)
    cp[K.CP_GSTAR_PP] = effective_shear_Pa(material, material)
    cp[K.CP_MU_PP] = material.friction_coef
    cp[K.CP_ETA_PP] = damping_coefficient(material.restitution)
    cp[K.CP_ESTAR_PW] = effective_youngs_Pa(material, wall_material)
    cp[K.CP_GSTAR_PW] = effective_shear_Pa(material, wall_material)
    cp[K.CP_MU_PW] = min(material.friction_coef, wall_material.friction_coef)
    cp[K.CP_ETA_PW] = damping_coefficient(math.sqrt(material.restitution * wall_material.restitution))
    if contact_law == "linear_yade":
        # Yade's linear spring (see dem.contacts.CONTACT_LAW_LINEAR_YADE): k = 2 e_star r_eff
        es, ew = material.youngs_modulus_Pa, wall_material.youngs_modulus_Pa
        gs, gw = es * material.poisson_ratio, ew * wall_material.poisson_ratio
        cp[K.CP_ESTAR_PP] = es
        cp[K.CP_GSTAR_PP] = gs
        cp[K.CP_ESTAR_PW] = es * ew / (es + ew)
        cp[K.CP_GSTAR_PW] = gs * gw / (gs + gw) if gs + gw > 0 else 0.0
    cp[K.CP_CONTACT_LAW] = CONTACT_LAWS[contact_law]
    cp[K.CP_LOCAL_DAMPING] = local_damping
    cp[K.CP_DAMP_AT_STEP] = 1.0 if damping_velocity == "at_force" else 0.0
    cp[K.CP_GX:K.CP_GZ + 1] = np.asarray(gravity_m_s2, dtype=float)
    cp[K.CP_LZ] = float(periodic_z_m)
    cp[K.CP_SKIN] = skin_m
    cp[K.CP_BETA] = bonds.beta
    cp[K.CP_CENTRAL_BONDS] = 1.0 if bonds.central else 0.0
    if drum is not None:
        cp[K.CP_DRUM_R] = drum.radius_m
        cp[K.CP_DRUM_OMEGA] = drum.omega_rad_s
        cp[K.CP_LIFTER_H] = drum.lifter_height_m
        cp[K.CP_LIFTER_HW] = 0.5 * drum.lifter_width_m
    cp[K.CP_HIST_LO] = HIST_LO_LOG10
    cp[K.CP_HIST_DLOG] = HIST_DLOG10
    return cp
