"""Virtual laboratory: slow compression between platens and drop-weight impact of one agglomerate.

- **Slow compression** (single-particle compression, e.g. Tavares & King, IJMP 54 (1998) 1):
  the bottom platen is fixed, the top platen moves down at ``platen_speed_m_s`` (default
  0.1 m/s, the issue's test spec; stress waves cross a 22 mm particle in ~10 µs, the peak comes
  after ~1 ms, so the test is quasi-static; the result reports how well top and bottom platen
  forces agree before the peak). Cundall local damping (default 0.7, Potyondy & Cundall 2004)
  removes kinetic energy as in a servo-controlled lab test. The test stops after the primary
  fracture, when three things hold at once: the force is below ``stop_force_fraction``
  (default 0.5) of the peak so far; the platen has moved past that peak by the post-peak
  window, the larger of ``post_peak_strain`` (default 0.5 %) of the height and
  ``post_peak_radii`` (default 1) mean sphere radii, without the force recovering above it;
  and the particle has split: its largest fragment (:func:`dem.fragments.find_fragments`)
  holds less than ``split_largest_fraction`` (default 0.9; 1 leaves this out) of its mass. A sphere breaking
  off at a platen contact is a local drop: the load comes back, or the particle is still
  whole, and the test goes on (with the old end, the first two conditions at a 0.5 % window,
  6 of 20 particles of 22 mm ended on such a chip, benchmarks/results/dem_size_effect.md).
  Otherwise it ends at ``max_strain`` (default 8 %).
  ``time_step_factor`` defaults to the largest System allows, 1 of the critical step
  (:data:`DEFAULT_TIME_STEP_FACTOR`: a measured margin of 1.5 to instability;
  benchmarks/dem_accuracy.py measures the accuracy it costs).
  Fracture energy = ``∫ F_top dδ`` from contact to the peak force (Tavares & King 1998).
- **Drop weight**: the particle rests on a fixed anvil; a free flat drop weight of mass
  ``drop_mass_kg`` touches its top with speed ``v0 = sqrt(2 E_s m_p / M)`` so that the
  kinetic energy per particle mass is ``E_s`` (J/kg), as in the JKMRC drop-weight test
  (Napier-Munn et al. 1996). No local damping; gravity is negligible over the impact and is
  left out. The run ends when the weight has rebounded and left the particle (or after
  ``max_time_factor * D / v0``), then the pieces are counted.

Particle mass: spheres get the density ``rho_rock / solid_fraction`` so that the agglomerate
has the mass of the solid particle it stands for (density scaling); specific energies are
per this mass.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from dem.agglomerate import Agglomerate
from dem.bonds import BondParams, BondSet
from dem.errors import DemInputError, UnfracturedWarning
from dem.fragments import FragmentResult, find_fragments
from dem.materials import RAYLEIGH_SAFETY_FACTOR, STEEL, Material, check_float
from dem.system import PlaneWall, System

#: Default time step of the compression test, as a fraction of System's critical step (for
#: bonded agglomerates the bond-spring step ``sqrt(m / sum k)``, translational and rotational):
#: System's largest. Measured, the loading stays within 1 % of the force at 0.25 up to 1.5 on
#: every packing tried, and bonds break spuriously from 1.75 (benchmarks/results/dem_time_step.md),
#: so 1 keeps a margin of 1.5; its accuracy cost on whole tests against 0.25 is in
#: benchmarks/results/dem_accuracy.md.
DEFAULT_TIME_STEP_FACTOR = 1.0


@dataclass(frozen=True)
class CompressionResult:
    """Result of :func:`compression_test` (SI units).

    peak_force_N : largest top-platen force; displacement_at_peak_m : platen travel at the peak;
    fracture_energy_J : work of the top platen up to the peak; specific_fracture_energy_J_kg :
    that per particle mass; stiffness_N_m : secant stiffness at half the peak force;
    force_mismatch_rel : mean |F_top - F_bottom| / peak over the pre-peak part where F_top >
    0.2 peak (quasi-static check); broken_at_peak / broken_final : {"tension", "shear"} counts;
    fractured : the particle broke (the force fell below ``stop_force_fraction`` of the peak after it, or
    its largest piece is below ``split_largest_fraction``); False (warned, :class:`dem.errors.
    UnfracturedWarning`) when it did not within ``max_strain``: the peak and fracture energy are then the
    end of travel's, not a strength (a particle that never broke reported 66 kN and 2624 J/kg);
    n_spheres, n_bonds, particle_mass_kg, diameter_m, dt_s, n_steps, wall_time_s;
    curve : DataFrame ``time_s, displacement_m, force_top_N, force_bottom_N, broken_bonds``;
    fragments : pieces at the end (:class:`dem.fragments.FragmentResult`).
    """

    peak_force_N: float
    displacement_at_peak_m: float
    fracture_energy_J: float
    specific_fracture_energy_J_kg: float
    stiffness_N_m: float
    force_mismatch_rel: float
    broken_at_peak: dict
    broken_final: dict
    fractured: bool
    n_spheres: int
    n_bonds: int
    particle_mass_kg: float
    diameter_m: float
    dt_s: float
    n_steps: int
    wall_time_s: float
    curve: pd.DataFrame = field(repr=False)
    fragments: FragmentResult = field(repr=False)

    def summary(self) -> dict:
        """Scalar results as a flat dict (one row of a DataFrame)."""
        return {"peak_force_N": self.peak_force_N, "displacement_at_peak_m": self.displacement_at_peak_m,
                "fracture_energy_J": self.fracture_energy_J,
                "specific_fracture_energy_J_kg": self.specific_fracture_energy_J_kg,
                "stiffness_N_m": self.stiffness_N_m, "force_mismatch_rel": self.force_mismatch_rel,
                "broken_tension_at_peak": self.broken_at_peak["tension"],
                "broken_shear_at_peak": self.broken_at_peak["shear"],
                "broken_tension_final": self.broken_final["tension"],
                "broken_shear_final": self.broken_final["shear"], "fractured": self.fractured,
                "n_spheres": self.n_spheres,
                "n_bonds": self.n_bonds, "particle_mass_kg": self.particle_mass_kg,
                "n_fragments": self.fragments.n_fragments,
                "largest_fragment_frac": self.fragments.largest_mass_fraction,
                "t10": self.fragments.t10, "dt_s": self.dt_s, "n_steps": self.n_steps,
                "wall_time_s": self.wall_time_s}


@dataclass(frozen=True)
class ImpactResult:
    """Result of :func:`drop_weight_test` (SI units).

    specific_energy_J_kg : input kinetic energy per particle mass; impact_speed_m_s;
    drop_mass_kg; absorbed_energy_J : input minus the drop weight's kinetic energy at the end
    (rebounding, or still moving down in a test cut short by ``max_time_factor``);
    peak_force_N : largest anvil force; broken_final : {"tension", "shear"}; broken_fraction :
    broken bonds / bonds; n_spheres, n_bonds, particle_mass_kg, dt_s, n_steps, wall_time_s;
    curve : DataFrame ``time_s, weight_pos_m, weight_force_N, anvil_force_N, broken_bonds``;
    fragments : :class:`dem.fragments.FragmentResult` (``fragments.t10`` is the t10).
    """

    specific_energy_J_kg: float
    impact_speed_m_s: float
    drop_mass_kg: float
    absorbed_energy_J: float
    peak_force_N: float
    broken_final: dict
    broken_fraction: float
    n_spheres: int
    n_bonds: int
    particle_mass_kg: float
    dt_s: float
    n_steps: int
    wall_time_s: float
    curve: pd.DataFrame = field(repr=False)
    fragments: FragmentResult = field(repr=False)

    @property
    def t10(self) -> float:
        return self.fragments.t10

    def summary(self) -> dict:
        return {"specific_energy_J_kg": self.specific_energy_J_kg,
                "impact_speed_m_s": self.impact_speed_m_s, "drop_mass_kg": self.drop_mass_kg,
                "absorbed_energy_J": self.absorbed_energy_J, "peak_force_N": self.peak_force_N,
                "broken_tension": self.broken_final["tension"],
                "broken_shear": self.broken_final["shear"], "broken_fraction": self.broken_fraction,
                "n_fragments": self.fragments.n_fragments,
                "largest_fragment_frac": self.fragments.largest_mass_fraction,
                "t2": self.fragments.t(2), "t4": self.fragments.t(4),
                "t10": self.fragments.t10, "n_spheres": self.n_spheres,
                "particle_mass_kg": self.particle_mass_kg, "n_steps": self.n_steps,
                "wall_time_s": self.wall_time_s}


def _check(name: str, value: float, lo: float, hi: float, owner: str) -> float:
    return check_float(owner, name, value, lo, hi, lo_open=True)


def _check_inputs(owner: str, agglomerate, bonds, chunk_steps, materials: dict) -> None:
    """The test's particle, bonds, chunk length and materials (``{name: value}``: a dict for a Material
    raised AttributeError; the System checks their values, damping and time step before any step)."""
    for name, value in materials.items():
        if not isinstance(value, Material):
            raise DemInputError(f"The '{name}' parameter of {owner} must be a dem.Material. Got {value!r}.")
    if not isinstance(agglomerate, Agglomerate):
        raise DemInputError(
            f"The 'agglomerate' parameter of {owner} must be a dem.agglomerate.Agglomerate "
            f"(make_agglomerate). Got {type(agglomerate).__name__}.")
    if not isinstance(bonds, BondParams):
        raise DemInputError(f"The 'bonds' parameter of {owner} must be a dem.bonds.BondParams. Got {bonds!r}.")
    if not (isinstance(chunk_steps, (int, np.integer)) and not isinstance(chunk_steps, bool)
            and 1 <= chunk_steps <= 10**7):
        raise DemInputError(
            f"The 'chunk_steps' parameter of {owner} must be an int in [1, 10000000]. Got {chunk_steps!r}.")


def _sphere_density(agg: Agglomerate, material: Material) -> float:
    return material.density_kg_m3 / agg.solid_fraction


def _counts(bonds: BondSet) -> dict:
    c = bonds.counts()
    return {"tension": c["broken_tension"], "shear": c["broken_shear"]}


def _load_until_split(sys_: System, bset: BondSet, v: float, max_disp: float, ended,
                      chunk_steps: int) -> tuple[float, dict]:
    """Run the platen in chunks until ``ended(peak, disp_at_peak, last force, disp)`` or the
    platen has travelled ``max_disp``. Returns (peak force, broken-bond counts at the peak)."""
    peak = 0.0
    disp_peak = 0.0
    broken_at_peak = _counts(bset)
    while True:
        first = sys_.steps
        sys_.run(chunk_steps)
        f_top = sys_.records.wall_force_N[-1][:, 1]
        k = int(np.argmax(f_top))
        disp_now = v * sys_.time_s
        if f_top[k] > peak:
            peak = float(f_top[k])
            disp_peak = v * (first + k + 1) * sys_.dt_s
            broken_at_peak = _counts(bset)
        if disp_now >= max_disp or ended(peak, disp_peak, float(f_top[-1]), disp_now):
            return peak, broken_at_peak


def compression_test(agglomerate: Agglomerate, bonds: BondParams, *, material: Material = Material(),
                     platen_material: Material = STEEL, platen_speed_m_s: float = 0.1,
                     local_damping: float = 0.7,
                     time_step_factor: float = DEFAULT_TIME_STEP_FACTOR, max_strain: float = 0.08,
                     stop_force_fraction: float = 0.5, post_peak_strain: float = 0.005,
                     post_peak_radii: float = 1.0, split_largest_fraction: float = 0.9,
                     chunk_steps: int = 250, contact_law: str = "hertz_mindlin",
                     damping_velocity: str = "mid_step") -> CompressionResult:
    """Slow compression of one agglomerate between flat platens; see the module docstring.

    ``contact_law`` and ``damping_velocity`` go to :class:`dem.system.System`; with
    ``BondParams.yade_jcfpm`` bonds, ``contact_law="linear_yade"`` and
    ``damping_velocity="at_force"`` the test is Yade's JCFpm model (benchmarks/dem_yade.py).
    """
    owner = "compression_test"
    _check_inputs(owner, agglomerate, bonds, chunk_steps, {"material": material, "platen_material": platen_material})
    v = _check("platen_speed_m_s", platen_speed_m_s, 0.0, 10.0, owner)
    _check("max_strain", max_strain, 0.0, 0.9, owner)
    _check("stop_force_fraction", stop_force_fraction, 0.0, 1.0, owner)
    _check("post_peak_strain", post_peak_strain, -1e-12, 0.5, owner)
    _check("post_peak_radii", post_peak_radii, -1e-12, 100.0, owner)
    _check("split_largest_fraction", split_largest_fraction, 0.0, 1.0, owner)
    t0 = time.perf_counter()
    agg = agglomerate
    pos = agg.pos_m.copy()
    rad = agg.radius_m
    bset = BondSet(agg.bond_pairs, pos, rad, bonds)
    z_lo = float(np.min(pos[:, 2] - rad))
    z_hi = float(np.max(pos[:, 2] + rad))
    walls = [PlaneWall((0.0, 0.0, z_lo), (0.0, 0.0, 1.0)),
             PlaneWall((0.0, 0.0, z_hi), (0.0, 0.0, -1.0), (0.0, 0.0, -v))]
    sys_ = System(pos, rad, material, density_kg_m3=_sphere_density(agg, material), bonds=bset,
                  wall_material=platen_material, walls=walls, local_damping=local_damping,
                  time_step_factor=time_step_factor, contact_law=contact_law,
                  damping_velocity=damping_velocity)
    height = z_hi - z_lo
    window = max(post_peak_strain * height, post_peak_radii * agg.mean_radius_m)
    volumes = 4.0 / 3.0 * math.pi * rad**3

    def split(peak, disp_peak, f_last, disp):
        if not (peak > 0 and f_last < stop_force_fraction * peak and disp > disp_peak + window):
            return False
        return split_largest_fraction >= 1.0 or find_fragments(
            agg.bond_pairs, bset.intact, volumes, agg.diameter_m).largest_mass_fraction < split_largest_fraction

    peak, broken_at_peak = _load_until_split(sys_, bset, v, max_strain * height, split, chunk_steps)
    rec = sys_.record_arrays()
    f_top = rec["wall_force_N"][:, 1]
    f_bot = rec["wall_force_N"][:, 0]
    nstep = f_top.shape[0]
    t = (np.arange(nstep) + 1) * sys_.dt_s
    disp = v * t
    kp = int(np.argmax(f_top))
    e_frac = float(np.trapezoid(np.r_[0.0, f_top[:kp + 1]], np.r_[0.0, disp[:kp + 1]]))
    mass = float(np.sum(sys_.mass))
    pre = f_top[:kp + 1] > 0.2 * peak
    mismatch = float(np.mean(np.abs(f_top[:kp + 1][pre] - f_bot[:kp + 1][pre])) / peak) if np.any(pre) else float("nan")
    half = np.nonzero(f_top[:kp + 1] >= 0.5 * peak)[0]
    stiff = float(f_top[half[0]] / disp[half[0]]) if half.size else float("nan")
    every = max(1, nstep // 2000)
    curve = pd.DataFrame({"time_s": t[::every], "displacement_m": disp[::every],
                          "force_top_N": f_top[::every], "force_bottom_N": f_bot[::every],
                          "broken_bonds": np.cumsum(rec["broken"])[::every]})
    frags = find_fragments(agg.bond_pairs, bset.intact, volumes, agg.diameter_m)
    dropped = kp < nstep - 1 and f_top[-1] < stop_force_fraction * peak
    fractured = bool(dropped or frags.largest_mass_fraction < split_largest_fraction)
    if not fractured:
        warnings.warn(f"{owner}: the particle did not fracture within max_strain = {max_strain:g} "
                      f"({1e3 * max_strain * height:.3g} mm of platen travel): the peak force {peak:.4g} N and the "
                      "fracture energy are the end of travel's, not a strength", UnfracturedWarning, stacklevel=2)
    return CompressionResult(peak_force_N=peak, displacement_at_peak_m=float(disp[kp]),
                             fracture_energy_J=e_frac, specific_fracture_energy_J_kg=e_frac / mass,
                             stiffness_N_m=stiff, force_mismatch_rel=mismatch,
                             broken_at_peak=broken_at_peak, broken_final=_counts(bset), fractured=fractured,
                             n_spheres=agg.n_spheres, n_bonds=agg.n_bonds, particle_mass_kg=mass,
                             diameter_m=agg.diameter_m, dt_s=sys_.dt_s, n_steps=nstep,
                             wall_time_s=time.perf_counter() - t0, curve=curve, fragments=frags)


def drop_weight_test(agglomerate: Agglomerate, bonds: BondParams, specific_energy_J_kg: float, *,
                     drop_mass_kg: float = 1.0, material: Material = Material(),
                     platen_material: Material = STEEL,
                     time_step_factor: float = RAYLEIGH_SAFETY_FACTOR,
                     max_time_factor: float = 3.0, chunk_steps: int = 250) -> ImpactResult:
    """Drop-weight impact at ``specific_energy_J_kg`` (J per kg of particle); see the module docstring."""
    owner = "drop_weight_test"
    _check_inputs(owner, agglomerate, bonds, chunk_steps, {"material": material, "platen_material": platen_material})
    es = _check("specific_energy_J_kg", specific_energy_J_kg, 0.0, 1e6, owner)
    m_dw = _check("drop_mass_kg", drop_mass_kg, 0.0, 1e4, owner)
    _check("max_time_factor", max_time_factor, 0.0, 100.0, owner)
    t0 = time.perf_counter()
    agg = agglomerate
    pos = agg.pos_m.copy()
    rad = agg.radius_m
    bset = BondSet(agg.bond_pairs, pos, rad, bonds)
    rho = _sphere_density(agg, material)
    m_p = float(np.sum(rho * 4.0 / 3.0 * math.pi * rad**3))
    v0 = math.sqrt(2.0 * es * m_p / m_dw)
    z_lo = float(np.min(pos[:, 2] - rad))
    z_hi = float(np.max(pos[:, 2] + rad))
    walls = [PlaneWall((0.0, 0.0, z_lo), (0.0, 0.0, 1.0)),
             PlaneWall((0.0, 0.0, z_hi), (0.0, 0.0, -1.0), (0.0, 0.0, -v0), mass_kg=m_dw)]
    sys_ = System(pos, rad, material, density_kg_m3=rho, bonds=bset, wall_material=platen_material,
                  walls=walls, time_step_factor=time_step_factor)
    height = z_hi - z_lo
    t_max = max_time_factor * height / v0
    touched = False
    while sys_.time_s < t_max:
        sys_.run(chunk_steps)
        f_w = sys_.records.wall_force_N[-1][:, 1]
        touched = touched or bool(np.any(f_w > 0))
        rebounding = sys_.w_v[1, 2] > 0.0
        if touched and rebounding and f_w[-1] <= 0.0:
            break
        if sys_.w_p[1, 2] - z_lo < 0.05 * height:
            break  # crushed flat
    # let the pieces separate for a short while
    sys_.run(chunk_steps)
    rec = sys_.record_arrays()
    f_w = rec["wall_force_N"][:, 1]
    f_a = rec["wall_force_N"][:, 0]
    nstep = f_w.shape[0]
    t = (np.arange(nstep) + 1) * sys_.dt_s
    v_end = float(sys_.w_v[1, 2])
    # the weight's kinetic energy at the end is not absorbed whichever way it moves: a test cut
    # short (max_time_factor, crushed flat) with the weight still moving down had it counted in
    absorbed = 0.5 * m_dw * (v0**2 - v_end**2)
    every = max(1, nstep // 2000)
    curve = pd.DataFrame({"time_s": t[::every], "weight_pos_m": rec["wall_pos_m"][::every, 1] * -1.0,
                          "weight_force_N": f_w[::every], "anvil_force_N": f_a[::every],
                          "broken_bonds": np.cumsum(rec["broken"])[::every]})
    frags = find_fragments(agg.bond_pairs, bset.intact, 4.0 / 3.0 * math.pi * rad**3, agg.diameter_m)
    counts = _counts(bset)
    return ImpactResult(specific_energy_J_kg=es, impact_speed_m_s=v0, drop_mass_kg=m_dw,
                        absorbed_energy_J=absorbed, peak_force_N=float(np.max(f_a)),
                        broken_final=counts,
                        broken_fraction=(counts["tension"] + counts["shear"]) / max(agg.n_bonds, 1),
                        n_spheres=agg.n_spheres, n_bonds=agg.n_bonds, particle_mass_kg=m_p,
                        dt_s=sys_.dt_s, n_steps=nstep, wall_time_s=time.perf_counter() - t0,
                        curve=curve, fragments=frags)
