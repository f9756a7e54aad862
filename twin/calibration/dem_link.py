"""The DEM's virtual tests behind the default calibration (MISSION.md sections 2-4): what
``grindtwin calibrate`` runs in its DEM step (:func:`run_dem`), before the laws across ores
(twin.calibration.dem_map) and the table step (twin.calibration.calibrate).

Units: SI inside the DEM part (N, Pa, J/kg, m); the twin's units (um, t/kWh, 1/h) at the end.

1. Target peak forces per ore type
----------------------------------
Type B: 4.2 kN for a -25+19 mm particle (MISSION.md section 2, measured). A, C and D are
derived from B with the mineralogy, as the geometric mean of two strength proxies:

    F_X = F_B * sqrt( (E_X / E_B) * (H_X / H_B) )

- E: aggregate Young's modulus (Voigt-Reuss-Hill of the modal mineralogy, twin.ore.mineralogy).
  Rock strength is proportional to the modulus within a rock class (the "modulus ratio"
  E/UCS of Deere & Miller 1966, Engineering classification and index properties for intact
  rock, AFWL-TR-65-116: 200-500 for most rocks), tensile strength is a fixed fraction of UCS
  (Hoek 1966; ~1/10), and the point-load / diametral-compression strength of an irregular
  particle is ``sigma_t = 2.8 F / (pi d^2)`` (Hiramatsu & Oka 1966, Int. J. Rock Mech. 3, 89),
  so at one particle size F ~ sigma_t ~ E.
- H: mineralogical hardness index H_min = sum w_i H_i (Vickers; MISSION.md eq. 1). Rock
  strength rises with the Vickers hardness of the rock (the correlation behind the
  hardness-grindability relation of Ozkahraman 2005, Int. J. Rock Mech. 42, 1022, already
  used by twin.calibration.breakage_map).
Both proxies are proportional to strength; with no data to weight them, the geometric mean
weights them equally (their exponents sum to 1, so F stays proportional to a strength).
With the reference ores this gives A 5.2, B 4.2, C 2.5, D 2.3 kN: A > B > C > D (C and D only
~8 % apart: their moduli and hardness indices are close; their difference in the mill comes
mostly from cushioning, a named twin effect).

Particle size: the DEM particle is a 22 mm sphere (geometric mean of the -25+19 mm class is
21.8 mm) of ``SPHERES`` bonded spheres (the resolution the 2-core budget affords; the bond
parameters are resolution-specific, see dem.calibrate). t10 is not resolved at this
resolution (a sphere is ~D0/5), t2 and t4 are.

2. Bond calibration
-------------------
``dem.BondCalibrator`` per ore: bond modulus = the ore's E (so k_n = E / (2 r_mean), P&C 2004
eq. 9), k_s/k_n = 0.4 and cohesion/tensile = 2 (the issue's benchmark ratios), sphere density
= ore density, contact modulus = E. Only the bond tensile strength (cohesion with it) is
fitted to the target mean peak force over ``n_particles`` seeded agglomerates. Type B is
fitted first; A, C, D start from B's strength times F_X/F_B (the DEM is nearly self-similar
in (E, sigma), so one or two iterations follow).

3. Fracture energies and fragments
----------------------------------
- Fracture-energy distribution per ore: the specific energies absorbed to the peak of the
  calibration particles' compression tests (Tavares & King 1998, IJMP 54, 1: energy to
  primary fracture), fitted log-normal by twin.ore.fracture_energy.fit_fracture_energy.
- Drop-weight tests (JKMRC, Napier-Munn et al. 1996) at specific energies
  ``DROP_ENERGY_MULTIPLES x E50``: the product size distributions on the sqrt(2) series.
  Austin's cumulative form ``B(y) = phi y^gamma + (1 - phi) y^beta`` (y = size / parent size,
  beta fixed at twin.calibration.breakage_map.AUSTIN_SHAPE's 4) is fitted per energy to the resolved
  part (y >= n^-1/3, about one sphere) of the fragments that left the parent's sqrt(2) class
  (see :func:`fit_austin_B`); ``t10`` extrapolates it below the DEM's resolution.
  ``t10 = A (1 - exp(-b E))`` (Narayanan & Whiten 1988, Trans. IMM C 97, 115; E in kWh/t as
  in the JK drop-weight test) is fitted to those t10 values.

4. Selection function (mechanistic, after Tavares & Carvalho 2009, Powder Technol. 190, 425
   and the UFRJ model of Tavares & de Carvalho 2011)
--------------------------------------------------------------------------------------------
The drum DEM (dem.drum_test, lab mill 0.5 m x 0.3 m, 0.70 of critical, 35 % balls, 25 mm
balls; the charge is ore-independent) gives the collision frequency f_k [1/s] per impact-energy
class E_k [J]. A collision between two balls captures the bed inside the circle where the gap
between the balls is below one particle size, r_c = sqrt(R_ball d) (geometric capture), one
particle layer thick: ``m_c(d) = rho_s (1 - eps) pi R_ball d^2``. It breaks a captured particle
of size d with probability ``P(E_k / m_c(d))`` (the ore's log-normal fracture-energy
distribution; E shared evenly by the captured mass). Breakage rate of size d [1/h]:

    S(d) = 3600 sum_k f_k m_c(d) P(E_k / m_c(d)) / H

and the energy-specific selection (Herbst & Fuerstenau 1980) ``S^E(d) = S H / P`` [t/kWh]
with P the drum DEM's net power: independent of hold-up. Austin's form
``S^E = S^E_1 (d/1 mm)^alpha / (1 + (d/mu)^Lambda)`` is fitted (least squares on ln S^E) over
the size grid between ``FIT_MIN_UM`` and the feed top size; that smooth form is what the
CasADi model uses (speed enters through twin.effects.speed as before).
How hardness reaches it: a harder, stiffer ore has a larger E50 (E50 ~ sigma^2/(E rho) scales
with the target force), so fewer of the same collisions break it: S^E falls from A to D in the
opposite order of the targets. The DEM has no flaw-size population: E50 does not grow for
finer particles (Tavares & King's size effect is absent), which is why alpha comes out near
2 (the captured mass ~ d^2). The capture model and the laws that carry these numbers to any
ore are in twin.calibration.dem_map.

Every ore's particles are the same seeded packings (agglomerate k has seed ``seed + k`` for
every ore): the ores differ by their bonds and materials only (common random numbers), and a
bootstrap resamples packings jointly across ores (twin.calibration.uncertainty).
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.optimize

from ..errors import TwinInputError
from ..ore.mineralogy import Mineralogy
from ..ore.ores import load_ore
from ..ore.fracture_energy import fit_fracture_energy
from .dem_map import fit_austin_B
from .strength import TARGET_B_N, target_peak_force_N

REFERENCE_ORES = ("A", "B", "C", "D")
PARTICLE_DIAMETER_M = 0.022
SPHERES = 150
PLATEN_SPEED_M_S = 0.25
STIFFNESS_RATIO = 0.4
#: starting guess only: bond strength / particle tensile strength (a 150-sphere packing breaks
#: through a few bonds per unit fracture area; the calibration moves it)
START_BOND_TO_PARTICLE_STRENGTH = 2.5
COHESION_RATIO = 2.0
#: drop-weight energies as multiples of the ore's compression E50
DROP_ENERGY_MULTIPLES = (0.3, 0.6, 1.2, 2.5, 5.0)
DROP_MASS_KG = 1.0
#: drop tests' time step, a fraction of System's critical step: the impact's stability was not
#: measured beyond 0.5 (the compression test's, dem.lab.DEFAULT_TIME_STEP_FACTOR, was); the tests' outcomes
#: at 0.5 agree with 0.0625's within the packings' scatter (benchmarks/dem_drop_time_step.py)
DROP_TIME_STEP_FACTOR = 0.5
#: a drop test ends at the weight's rebound or after this many D/v0 (the weight has then
#: travelled 0.6 D into the particle at its initial speed; longer runs only grind the debris)
DROP_MAX_TIME_FACTOR = 0.6
#: drum of the lab mill (MISSION.md) and twin.mill.LAB
DRUM = {"speed_frac_critical": 0.70, "ball_filling": 0.35, "mill_diameter_m": 0.5, "mill_length_m": 0.3,
        "ball_diameter_m": 0.025}
FIT_MIN_UM = 20.0
FEED_TOP_UM = 6000.0
#: The DEM step's settings. ``full``: 30 particles per ore, so that E50's standard error
#: (sigma / sqrt(n) in ln E50, sigma ~0.3-0.45) stays below 10 %; 4 drop-test packings per
#: energy. The drum window settles 1 revolution: measured (benchmarks/results/dem_drum_accuracy.md),
#: 0.5 revolution of settling reads power 3 % high, while 1 + 1 is within 0.1 % (power) and 1 %
#: (S^E at 1 mm) of 10 revolutions. The fast window (0.3 + 0.3) reads S^E 20-25 % low; ``fast``
#: is a check of the machinery, not a calibration.
SETTINGS = {
    "full": {"n_particles": 30, "drop_particles": 4, "drop_energy_multiples": DROP_ENERGY_MULTIPLES,
             "calibration_tol_pct": 2.0, "max_iter": 5, "drum_settle_rev": 1.0, "drum_measure_rev": 1.0,
             "drum_section_length_m": 0.1},
    "fast": {"n_particles": 4, "drop_particles": 2, "drop_energy_multiples": (0.6, 1.2, 5.0),
             "calibration_tol_pct": 4.0, "max_iter": 3, "drum_settle_rev": 0.3, "drum_measure_rev": 0.3,
             "drum_section_length_m": 0.0625},
}


# ---------------------------------------------------------------------- 1. targets
def targets(ores=REFERENCE_ORES) -> dict:
    out = {}
    for name in ores:
        o = load_ore(name)
        out[name] = {"target_peak_force_N": target_peak_force_N(o), "youngs_gpa": o.youngs_gpa,
                     "hardness_index_gpa": o.hardness_index_gpa, "density_t_m3": o.density_t_m3}
    return out


# ---------------------------------------------------------------------- 2. bonds
def _material(ore: Mineralogy):
    from dem import Material

    return Material(youngs_modulus_Pa=ore.youngs_gpa * 1e9, density_kg_m3=ore.density_t_m3 * 1000.0)


def bond_calibrator(ore: Mineralogy, settings: dict, seed: int, initial_tensile_Pa: float, workers: int = 1):
    """The DEM step's bond calibrator of ``ore`` (its packings, test and bond ratios), not fitted;
    its compression tests on ``workers`` processes."""
    from dem import BondCalibrator

    return BondCalibrator(n_particles=settings["n_particles"], particle_diameter_m=PARTICLE_DIAMETER_M,
                          spheres_per_particle=SPHERES, random_state=seed, material=_material(ore),
                          bond_modulus_Pa=ore.youngs_gpa * 1e9, stiffness_ratio=STIFFNESS_RATIO,
                          cohesion_ratio=COHESION_RATIO, initial_tensile_strength_Pa=initial_tensile_Pa,
                          platen_speed_m_s=PLATEN_SPEED_M_S, tol_pct=settings["calibration_tol_pct"],
                          max_iter=settings["max_iter"], n_jobs=workers)


def calibrate_bonds(ore: Mineralogy, target_N: float, settings: dict, seed: int, initial_tensile_Pa: float,
                    workers: int = 1):
    return bond_calibrator(ore, settings, seed, initial_tensile_Pa, workers).fit(target_N)


# ---------------------------------------------------------------------- 3. fragments
def fit_t10(e_kwh_t, t10) -> dict:
    """t10 = A (1 - exp(-b E)) (Narayanan & Whiten 1988); t10 as a fraction (A in %, reported)."""
    e = np.asarray(e_kwh_t, float)
    t = np.asarray(t10, float)

    def res(q):
        return q[0] * (1.0 - np.exp(-q[1] * e)) - t

    a0 = min(max(float(t.max()) * 1.2, 0.05), 0.99)
    b0 = 1.0 / max(float(np.median(e)), 1e-6)
    sol = scipy.optimize.least_squares(res, [a0, b0], bounds=([1e-3, 1e-6], [1.0, 1e6]))
    a, b = sol.x
    ss = float(np.sum((t - t.mean()) ** 2))
    return {"A_pct": float(100.0 * a), "b_t_kwh": float(b), "A_times_b": float(100.0 * a * b),
            "rmse": float(np.sqrt(np.mean(sol.fun ** 2))),
            "r2": float(1.0 - np.sum(sol.fun ** 2) / ss) if ss > 0 else float("nan")}


def drop_tests(ore: Mineralogy, bond_params, e50_j_kg: float, settings: dict, seed: int, tick=None,
               workers: int = 1, time_step_factor: float = DROP_TIME_STEP_FACTOR) -> dict:
    """Drop-weight tests at ``drop_energy_multiples`` x E50 on ``drop_particles`` packings, on
    ``workers`` processes (the same answer for any number); each row keeps its packing index and
    energy multiple (for the bootstrap and the pooled B). ``time_step_factor``: the calibration's
    (benchmarks/dem_drop_time_step.py runs others)."""
    from dem import drop_weight_test, make_agglomerate, run_in_processes

    kw = {"drop_mass_kg": DROP_MASS_KG, "material": _material(ore), "time_step_factor": time_step_factor,
          "max_time_factor": DROP_MAX_TIME_FACTOR}
    aggs = [make_agglomerate(PARTICLE_DIAMETER_M, SPHERES, random_state=seed + k)
            for k in range(settings["drop_particles"])]
    energies = [float(mult * e50_j_kg) for mult in settings["drop_energy_multiples"]]
    results = iter(run_in_processes(drop_weight_test, [((agg, bond_params, e), kw) for e in energies for agg in aggs],
                                    workers, on_result=tick))
    y_min = SPHERES ** (-1.0 / 3.0)
    rows, per_energy = [], []
    for mult, e in zip(settings["drop_energy_multiples"], energies):
        ys, ps = [], []
        for k in range(len(aggs)):
            r = next(results)
            sd = r.fragments.size_distribution
            keep = (sd["sieve_size_rel"] >= y_min) & (sd["sieve_size_rel"] < 1.0)
            ys.append(sd["sieve_size_rel"][keep].to_numpy())
            ps.append(sd["passing_frac"][keep].to_numpy())
            row = {"particle": k, "energy_multiple": float(mult), "specific_energy_J_kg": e,
                   "sieve_size_rel": ys[-1].tolist(), "passing_frac": ps[-1].tolist()}
            row.update({key: float(v) for key, v in r.summary().items()
                        if key in ("t2", "t4", "broken_fraction", "largest_fragment_frac", "n_fragments",
                                   "absorbed_energy_J", "wall_time_s")})
            rows.append(row)
        fit = fit_austin_B(np.concatenate(ys), np.concatenate(ps))
        fit.update({"n_tests": len(aggs), "energy_multiple": float(mult), "specific_energy_J_kg": e,
                    "specific_energy_kwh_t": e / 3600.0})
        per_energy.append(fit)
    t10 = fit_t10([p["specific_energy_kwh_t"] for p in per_energy], [p["t10"] for p in per_energy])
    return {"tests": rows, "per_energy": per_energy, "t10_fit": t10, "resolved_size_rel_min": y_min}


# ---------------------------------------------------------------------- 4. drum
def drum_spectrum(settings: dict, seed: int) -> dict:
    from dem import drum_test

    r = drum_test(DRUM["speed_frac_critical"], DRUM["ball_filling"], mill_diameter_m=DRUM["mill_diameter_m"],
                  mill_length_m=DRUM["mill_length_m"], ball_diameter_m=DRUM["ball_diameter_m"],
                  settle_revolutions=settings["drum_settle_rev"], measure_revolutions=settings["drum_measure_rev"],
                  section_length_m=settings["drum_section_length_m"], random_state=seed)
    sp = r.spectrum
    keep = sp["total_per_s"].to_numpy() > 0
    return {"power_W": r.power_W, "collisions_per_s": r.collisions_per_s, "n_balls": r.n_balls,
            "wall_time_s": r.wall_time_s, "ball_diameter_m": DRUM["ball_diameter_m"],
            "energy_mid_J": sp["energy_mid_J"].to_numpy()[keep].tolist(),
            "collisions_per_s_by_class": sp["total_per_s"].to_numpy()[keep].tolist()}


def fit_sizes_um(grid) -> list:
    """The sizes the Austin selection is fitted over: the grid's classes from FIT_MIN_UM to the feed top."""
    return [float(x) for x in grid.mid_um if FIT_MIN_UM <= x <= FEED_TOP_UM]


# ---------------------------------------------------------------------- the DEM step
def _progress_total(settings: dict, n_ores: int) -> int:
    """Simulations in the DEM step: the drum, then per ore the bond iterations' compression tests
    (counted at the most iterations) and the drop tests."""
    per_ore = settings["max_iter"] * settings["n_particles"] + settings["drop_particles"] * len(
        settings["drop_energy_multiples"])
    return 1 + n_ores * per_ore


def run_dem(fast: bool = False, seed: int = 0, ores=REFERENCE_ORES, progress: bool = True,
            workers: int | None = None) -> dict:
    """Steps 1-4 on the reference ores: the DEM record of a calibration file (per ore: target,
    bonds, per-particle fracture energies, drop tests; the drum spectrum; settings; times).
    A progress bar (tqdm, on stderr) counts the simulations and shows the wall time. The
    compression and drop-weight tests run on ``workers`` processes (default: every core this
    process may use); the record is the same for any number (dem.parallel)."""
    from tqdm.auto import tqdm

    from dem import DEFAULT_TIME_STEP_FACTOR

    from .model_code import dem_step_digest

    unknown = [o for o in ores if o not in REFERENCE_ORES]
    if unknown:
        raise TwinInputError(f"The DEM step runs reference ores {REFERENCE_ORES}. Got {unknown}.")
    settings = SETTINGS["fast" if fast else "full"]
    workers = check_workers(workers)
    t0 = time.perf_counter()
    tg = targets(ores)
    order = ["B"] + [o for o in ores if o != "B"] if "B" in ores else list(ores)
    out, sigma_b = {}, None
    with tqdm(total=_progress_total(settings, len(ores)), desc="DEM step", unit="sim", disable=not progress) as bar:
        bar.set_postfix_str("drum")
        drum = drum_spectrum(settings, seed)
        bar.update(1)
        for name in order:
            bar.set_postfix_str(f"ore {name}")
            out[name], sigma = _dem_ore(name, tg[name], settings, seed, sigma_b, bar, workers)
            sigma_b = sigma_b or sigma
    return {"settings": {**{k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()},
                         "spheres_per_particle": SPHERES, "particle_diameter_m": PARTICLE_DIAMETER_M,
                         "platen_speed_m_s": PLATEN_SPEED_M_S, "stiffness_ratio": STIFFNESS_RATIO,
                         "cohesion_ratio": COHESION_RATIO, "drop_mass_kg": DROP_MASS_KG, "drum": DRUM,
                         "time_step_factor": DEFAULT_TIME_STEP_FACTOR, "drop_time_step_factor": DROP_TIME_STEP_FACTOR,
                         "seed": seed, "fast": fast},
            "sources_sha256": dem_step_digest(), "drum": drum, "ores": {n: out[n] for n in ores},
            "dem_seconds": time.perf_counter() - t0}


def check_workers(workers) -> int:
    """``workers`` processes for the DEM step's tests (None: every core this process may use);
    TwinInputError unless a whole number >= 1."""
    from dem import available_cores

    if workers is None:
        return available_cores()
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise TwinInputError(f"The DEM step's 'workers' (processes) must be a whole number >= 1. Got {workers!r}.")
    return int(workers)


def _dem_ore(name: str, target: dict, settings: dict, seed: int, sigma_b: float | None, bar, workers: int):
    """One ore's bond calibration and drop tests; returns (record, fitted bond strength)."""
    ore = load_ore(name)
    t1 = time.perf_counter()
    force = target["target_peak_force_N"]
    # first guess (a start only, the fit moves it): B from the particle's tensile strength
    # 2.8 F / (pi d^2) (Hiramatsu & Oka 1966) times START_BOND_TO_PARTICLE_STRENGTH; the others
    # from B's fitted strength scaled with the force (Potyondy & Cundall 2004 s3.2)
    s0 = (sigma_b * force / TARGET_B_N if sigma_b else
          START_BOND_TO_PARTICLE_STRENGTH * 2.8 * force / (math.pi * PARTICLE_DIAMETER_M ** 2))
    cal = calibrate_bonds(ore, force, settings, seed, s0, workers)
    bar.update(settings["max_iter"] * settings["n_particles"])  # counted at the most iterations
    fe = fit_fracture_energy(cal.specific_fracture_energy_J_kg_)
    drops = drop_tests(ore, cal.bond_params_, fe.e50_j_kg, settings, seed, tick=lambda: bar.update(1),
                       workers=workers)
    rec = {
        "target_peak_force_N": force, "youngs_gpa": ore.youngs_gpa,
        "hardness_index_gpa": ore.hardness_index_gpa, "density_t_m3": ore.density_t_m3,
        "bond": {"kn_GPa_m": cal.kn_Pa_m_ / 1e9, "ks_GPa_m": cal.ks_Pa_m_ / 1e9,
                 "tensile_strength_MPa": cal.tensile_strength_Pa_ / 1e6, "cohesion_MPa": cal.cohesion_Pa_ / 1e6,
                 "bond_modulus_GPa": ore.youngs_gpa},
        "mean_peak_force_N": cal.mean_peak_force_N_, "calibration_error_pct": cal.calibration_error_pct_,
        "peak_force_cv_pct": cal.peak_force_cv_pct_, "iterations": cal.n_iter_,
        "n_particles": int(settings["n_particles"]),
        "peak_force_N": [float(v) for v in cal.peak_force_N_],
        "quasi_static_mismatch_rel": float(np.nanmean([r.force_mismatch_rel for r in cal.results_])),
        "specific_fracture_energy_J_kg": cal.specific_fracture_energy_J_kg_.tolist(),
        "fracture_energy": {"model": fe.model, "e50_j_kg": fe.e50_j_kg, "sigma": fe.sigma, "n": fe.n,
                            "ln_e50_se": fe.ln_e50_se, "ks_statistic": fe.ks_statistic, "ks_pvalue": fe.ks_pvalue},
        "drop_weight": drops,
        "wall_time_s": time.perf_counter() - t1,
    }
    return rec, cal.tensile_strength_Pa_


def per_ore_selection(dem: dict, sizes_um) -> dict:
    """Each reference ore's own S^E (its own E50 and sigma, before any law) and Austin fit: the
    numbers the laws are checked against (benchmarks/twin_dem_link.py)."""
    from .dem_map import fit_austin_selection, selection_energy_specific

    out = {}
    for name, o in dem["ores"].items():
        fe = o["fracture_energy"]
        se = selection_energy_specific(sizes_um, dem["drum"], fe["e50_j_kg"], fe["sigma"], o["density_t_m3"] * 1000.0)
        out[name] = {**fit_austin_selection(sizes_um, se), "se_t_kwh_per_size": se.tolist()}
    return out
