"""The link from the DEM (``dem``) to the twin's breakage parameters (MISSION.md sections 2-4).

``calibrate_from_dem(fast, seed)`` regenerates ``twin/calibration/files/dem.json`` from nothing
but the repository; ``dem_breakage(ore, coefficients)`` is a breakage map usable as
``Twin(ore, breakage_map=dem_breakage, calibration=dem_twin_calibration())``.
Command line: ``python -m twin.calibration --dem [--fast] [--seed N]`` (or ``python -m twin.calibration.dem_link``;
``--table-only`` reruns only step 5 on the file's DEM numbers). ``grindtwin calibrate`` forwards
only ``--fast``/``--out`` to twin.calibration (scenarios/commands.py), so it still runs the
mineralogy-map fit; forwarding ``--dem`` there is one line in scenarios (not this module's).
The shipped twin/calibration/files/table.json (mineralogy map) stays the default of ``Twin``: the
DEM-based table fit meets the 5 % goal with less room (see
benchmarks/results/twin_dem_link_table.md).

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
2 (the captured mass ~ d^2); see the report.

5. The map and the remaining fit
--------------------------------
``dem_breakage`` interpolates each DEM-derived parameter (ln S^E_1, alpha, ln mu, Lambda,
gamma, phi) piecewise-linearly in ln F_target(mineralogy) between the reference ores and
refuses ores outside the span of the reference types. One number scales all S^E: the capture
efficiency ``dem_capture_scale`` (the fraction of captured mass that is really nipped; fitted
in the UFRJ model too), fitted to MISSION.md's table together with the cushioning coefficients
(twin.effects.cushioning), the clay-crowding coefficient (twin.effects.rheology) and the lab
mill's power factor, grate cut size, sharpness and discharge factor.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import scipy.optimize

from ..breakage import BreakageParams
from .breakage_map import AUSTIN_SHAPE
from .files import DEM_CALIBRATION_PATH, lab_mill_values, shipped_dem_calibration, versions, write_json_atomically
from .fitting import FAILED_POINT_RESIDUAL, failed_points_record, fit_log_ratios
from .reference import KPIS, reference_table
from ..errors import SolverError, TwinError, TwinInputError
from ..ore.fracture_energy import breakage_probability, fit_fracture_energy
from ..ore.mineralogy import Mineralogy
from ..ore.ores import load_ore

REFERENCE_ORES = ("A", "B", "C", "D")
#: MISSION.md section 2: measured peak fracture force of a -25+19 mm Type B particle.
TARGET_B_N = 4200.0
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
#: a drop test ends at the weight's rebound or after this many D/v0 (the weight has then
#: travelled 0.6 D into the particle at its initial speed; longer runs only grind the debris)
DROP_MAX_TIME_FACTOR = 0.6
#: drum of the lab mill (MISSION.md) and twin.mill.LAB
DRUM = {"speed_frac_critical": 0.70, "ball_filling": 0.35, "mill_diameter_m": 0.5, "mill_length_m": 0.3,
        "ball_diameter_m": 0.025}
BED_POROSITY = 0.4
FIT_MIN_UM = 20.0
FEED_TOP_UM = 6000.0
#: The full drum window settles 1 revolution: measured (benchmarks/results/dem_drum_accuracy.md),
#: 0.5 revolution of settling reads power 3 % high, while 1 + 1 is within 0.1 % (power) and 1 %
#: (S^E at 1 mm) of 10 revolutions. The fast window (0.3 + 0.3) reads S^E 20-25 % low.
SETTINGS = {
    "full": {"n_particles": 10, "drop_particles": 3, "drop_energy_multiples": DROP_ENERGY_MULTIPLES,
             "calibration_tol_pct": 2.0, "max_iter": 5, "drum_settle_rev": 1.0, "drum_measure_rev": 1.0,
             "drum_section_length_m": 0.1, "table_max_nfev": 60},
    "fast": {"n_particles": 3, "drop_particles": 1, "drop_energy_multiples": (0.4, 1.2, 4.0),
             "calibration_tol_pct": 4.0, "max_iter": 3, "drum_settle_rev": 0.3, "drum_measure_rev": 0.3,
             "drum_section_length_m": 0.0625, "table_max_nfev": 3},
}


# ---------------------------------------------------------------------- 1. targets
def target_peak_force_N(ore: Mineralogy, reference: Mineralogy | None = None) -> float:
    """F_X = F_B sqrt((E_X/E_B)(H_X/H_B)) (module docstring, section 1)."""
    b = reference or load_ore("B")
    return TARGET_B_N * math.sqrt((ore.youngs_gpa / b.youngs_gpa) * (ore.hardness_index_gpa / b.hardness_index_gpa))


def targets() -> dict:
    out = {}
    for name in REFERENCE_ORES:
        o = load_ore(name)
        out[name] = {"target_peak_force_N": target_peak_force_N(o), "youngs_gpa": o.youngs_gpa,
                     "hardness_index_gpa": o.hardness_index_gpa, "density_t_m3": o.density_t_m3}
    return out


# ---------------------------------------------------------------------- 2. bonds
def _material(ore: Mineralogy):
    from dem import Material

    return Material(youngs_modulus_Pa=ore.youngs_gpa * 1e9, density_kg_m3=ore.density_t_m3 * 1000.0)


def calibrate_bonds(ore: Mineralogy, target_N: float, settings: dict, seed: int, initial_tensile_Pa: float):
    from dem import BondCalibrator

    cal = BondCalibrator(n_particles=settings["n_particles"], particle_diameter_m=PARTICLE_DIAMETER_M,
                         spheres_per_particle=SPHERES, random_state=seed, material=_material(ore),
                         bond_modulus_Pa=ore.youngs_gpa * 1e9, stiffness_ratio=STIFFNESS_RATIO,
                         cohesion_ratio=COHESION_RATIO, initial_tensile_strength_Pa=initial_tensile_Pa,
                         platen_speed_m_s=PLATEN_SPEED_M_S, tol_pct=settings["calibration_tol_pct"],
                         max_iter=settings["max_iter"])
    return cal.fit(target_N)


# ---------------------------------------------------------------------- 3. fragments
def _austin_B(y, gamma, phi, beta):
    return phi * y ** gamma + (1.0 - phi) * y ** beta


def fit_austin_B(y, passing, beta: float = AUSTIN_SHAPE["beta"]) -> dict:
    """gamma, phi of Austin's B to a product size distribution (beta fixed).

    ``y`` = sieve size / parent size, ``passing`` = cumulative mass fraction finer. Austin's B
    describes the fragments that *left* the parent's size class (twin.breakage's convention:
    B = 1 at the parent's lower size, sizes relative to it), so the product is renormalised by
    the mass passing the first sieve below the parent, y0 = 1/sqrt(2):
    ``B(r) = passing(y) / passing(y0)``, ``r = y / y0``, and ``t10 = passing(y0) B(0.1 / y0)``.
    Bounds gamma in [0.3, 3], phi in [0.01, 1] (Austin et al. 1984 report gamma 0.5-1.5)."""
    y = np.asarray(y, float)
    p = np.asarray(passing, float)
    y0 = 2.0 ** -0.5
    top = np.isclose(y, y0)
    p0 = float(np.mean(p[top])) if np.any(top) else float("nan")
    below = y < y0 * (1 - 1e-9)
    if not (p0 > 1e-6) or not np.any(below):
        return {"gamma": float("nan"), "phi": float("nan"), "beta": float(beta), "rmse": float("nan"),
                "passing_y0": p0 if np.isfinite(p0) else 0.0, "t10": 0.0}
    r = y[below] / y0
    b = np.clip(p[below] / p0, 0.0, 1.0)

    def res(q):
        return _austin_B(r, q[0], q[1], beta) - b

    sol = scipy.optimize.least_squares(res, [1.0, 0.5], bounds=([0.3, 0.01], [3.0, 1.0]))
    g, ph = sol.x
    return {"gamma": float(g), "phi": float(ph), "beta": float(beta),
            "rmse": float(np.sqrt(np.mean(sol.fun ** 2))), "passing_y0": p0,
            "t10": float(p0 * _austin_B(0.1 / y0, g, ph, beta))}


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


def drop_tests(ore: Mineralogy, bond_params, e50_j_kg: float, settings: dict, seed: int) -> dict:
    from dem import drop_weight_test, make_agglomerate

    mat = _material(ore)
    aggs = [make_agglomerate(PARTICLE_DIAMETER_M, SPHERES, random_state=seed + k)
            for k in range(settings["drop_particles"])]
    y_min = SPHERES ** (-1.0 / 3.0)
    rows, per_energy = [], []
    for mult in settings["drop_energy_multiples"]:
        e = float(mult * e50_j_kg)
        ys, ps = [], []
        for k, agg in enumerate(aggs):
            r = drop_weight_test(agg, bond_params, e, drop_mass_kg=DROP_MASS_KG, material=mat,
                                 time_step_factor=0.5, max_time_factor=DROP_MAX_TIME_FACTOR)
            sd = r.fragments.size_distribution
            keep = (sd["sieve_size_rel"] >= y_min) & (sd["sieve_size_rel"] < 1.0)
            ys.append(sd["sieve_size_rel"][keep].to_numpy())
            ps.append(sd["passing_frac"][keep].to_numpy())
            row = {"particle": k, "specific_energy_J_kg": e,
                   "sieve_size_rel": ys[-1].tolist(), "passing_frac": ps[-1].tolist()}
            row.update({key: float(v) for key, v in r.summary().items()
                        if key in ("t2", "t4", "broken_fraction", "largest_fragment_frac", "n_fragments",
                                   "absorbed_energy_J", "wall_time_s")})
            rows.append(row)
        fit = fit_austin_B(np.concatenate(ys), np.concatenate(ps))
        fit["n_tests"] = len(aggs)
        fit["specific_energy_J_kg"] = e
        fit["specific_energy_kwh_t"] = e / 3600.0
        per_energy.append(fit)
    t10 = fit_t10([p["specific_energy_kwh_t"] for p in per_energy], [p["t10"] for p in per_energy])
    return {"tests": rows, "per_energy": per_energy, "t10_fit": t10,
            "resolved_size_rel_min": y_min}


# ---------------------------------------------------------------------- 4. selection
def drum_spectrum(settings: dict, seed: int) -> dict:
    from dem import drum_test

    r = drum_test(DRUM["speed_frac_critical"], DRUM["ball_filling"], mill_diameter_m=DRUM["mill_diameter_m"],
                  mill_length_m=DRUM["mill_length_m"], ball_diameter_m=DRUM["ball_diameter_m"],
                  settle_revolutions=settings["drum_settle_rev"], measure_revolutions=settings["drum_measure_rev"],
                  section_length_m=settings["drum_section_length_m"], random_state=seed)
    sp = r.spectrum
    keep = sp["total_per_s"].to_numpy() > 0
    return {"power_W": r.power_W, "collisions_per_s": r.collisions_per_s, "n_balls": r.n_balls,
            "wall_time_s": r.wall_time_s,
            "energy_mid_J": sp["energy_mid_J"].to_numpy()[keep].tolist(),
            "collisions_per_s_by_class": sp["total_per_s"].to_numpy()[keep].tolist()}


def captured_mass_kg(d_m, density_kg_m3: float):
    """m_c = rho_s (1 - eps) pi R_ball d^2 (module docstring, section 4)."""
    return density_kg_m3 * (1.0 - BED_POROSITY) * math.pi * 0.5 * DRUM["ball_diameter_m"] * np.asarray(d_m) ** 2


def selection_energy_specific(size_um, drum: dict, e50_j_kg: float, sigma: float, density_kg_m3: float):
    """S^E(d) [t/kWh] = 3.6 sum_k f_k m_c P(E_k/m_c) / P_kW (per-collision capture model)."""
    d = np.asarray(size_um, float) * 1e-6
    e = np.asarray(drum["energy_mid_J"])
    f = np.asarray(drum["collisions_per_s_by_class"])
    mc = captured_mass_kg(d, density_kg_m3)
    p = breakage_probability(e[None, :] / mc[:, None], e50_j_kg, sigma)
    kg_per_s = np.sum(f[None, :] * mc[:, None] * p, axis=1)
    return kg_per_s * 3.6 / (drum["power_W"] / 1000.0)   # (kg/s * 3600 / 1000) t/h per kW


def fit_austin_selection(size_um, se_t_kwh) -> dict:
    """S^E = S1 (d/1000)^alpha / (1 + (d/mu)^Lambda), least squares on ln S^E."""
    x = np.asarray(size_um, float)
    y = np.log(np.asarray(se_t_kwh, float))

    def model(q):
        ls1, alpha, lmu, lam = q
        return ls1 + alpha * np.log(x / 1000.0) - np.log1p((x / math.exp(lmu)) ** lam)

    best = None
    for lmu0 in (math.log(300.0), math.log(1000.0), math.log(3000.0)):
        sol = scipy.optimize.least_squares(lambda q: model(q) - y, [y.max(), 1.5, lmu0, 3.0],
                                           bounds=([-30, 0.0, math.log(10.0), 0.05], [30, 5.0, math.log(1e6), 20.0]))
        if best is None or sol.cost < best.cost:
            best = sol
    ls1, alpha, lmu, lam = best.x
    return {"se_1mm_t_kwh": float(math.exp(ls1)), "alpha": float(alpha), "mu_um": float(math.exp(lmu)),
            "Lambda": float(lam), "rmse_ln": float(np.sqrt(np.mean(best.fun ** 2)))}


# ---------------------------------------------------------------------- the pipeline
def dem_part(fast: bool = False, seed: int = 0, ores=REFERENCE_ORES, verbose: bool = True) -> dict:
    """Steps 1-4 (the DEM-derived numbers); no table fit."""
    from twin.sizes import SizeGrid

    settings = SETTINGS["fast" if fast else "full"]
    t0 = time.perf_counter()
    tg = targets()
    order = ["B"] + [o for o in ores if o != "B"] if "B" in ores else list(ores)
    drum = drum_spectrum(settings, seed)
    if verbose:
        print(f"drum: {drum['power_W']:.1f} W, {drum['collisions_per_s']:.0f} collisions/s "
              f"({drum['wall_time_s']:.0f} s)", flush=True)
    grid = SizeGrid()
    sizes = grid.mid_um[(grid.mid_um >= FIT_MIN_UM) & (grid.mid_um <= FEED_TOP_UM)]
    out, sigma_b = {}, None
    for name in order:
        ore = load_ore(name)
        t1 = time.perf_counter()
        target = tg[name]["target_peak_force_N"]
        # first guess (a start only, the fit moves it): B from the particle's tensile strength
        # 2.8 F / (pi d^2) (Hiramatsu & Oka 1966) times START_BOND_TO_PARTICLE_STRENGTH; the others
        # from B's fitted strength scaled with the force (Potyondy & Cundall 2004 s3.2)
        s0 = (sigma_b * target / TARGET_B_N if sigma_b else
              START_BOND_TO_PARTICLE_STRENGTH * 2.8 * target / (math.pi * PARTICLE_DIAMETER_M ** 2))
        cal = calibrate_bonds(ore, target, settings, seed, s0)
        if name == "B":
            sigma_b = cal.tensile_strength_Pa_
        fe = fit_fracture_energy(cal.specific_fracture_energy_J_kg_)
        drops = drop_tests(ore, cal.bond_params_, fe.e50_j_kg, settings, seed)
        se = selection_energy_specific(sizes, drum, fe.e50_j_kg, fe.sigma, ore.density_t_m3 * 1000.0)
        sel = fit_austin_selection(sizes, se)
        # breakage function: the Austin B fitted at the drop energy nearest the mill's typical
        # specific collision energy (energy-weighted mean collision energy over m_c at 1 mm)
        e = np.asarray(drum["energy_mid_J"])
        f = np.asarray(drum["collisions_per_s_by_class"])
        e_typ = float(np.sum(e * e * f) / np.sum(e * f)) / float(captured_mass_kg(1e-3, ore.density_t_m3 * 1000.0))
        pe = drops["per_energy"]
        k = int(np.argmin([abs(math.log(p["specific_energy_J_kg"] / e_typ)) if np.isfinite(p["gamma"]) else np.inf
                           for p in pe]))
        out[name] = {
            "target_peak_force_N": target, "youngs_gpa": ore.youngs_gpa,
            "hardness_index_gpa": ore.hardness_index_gpa, "density_t_m3": ore.density_t_m3,
            "bond": {"kn_GPa_m": cal.kn_Pa_m_ / 1e9, "ks_GPa_m": cal.ks_Pa_m_ / 1e9,
                     "tensile_strength_MPa": cal.tensile_strength_Pa_ / 1e6, "cohesion_MPa": cal.cohesion_Pa_ / 1e6,
                     "bond_modulus_GPa": ore.youngs_gpa},
            "mean_peak_force_N": cal.mean_peak_force_N_, "calibration_error_pct": cal.calibration_error_pct_,
            "peak_force_cv_pct": cal.peak_force_cv_pct_, "iterations": cal.n_iter_,
            "n_particles": int(settings["n_particles"]),
            "quasi_static_mismatch_rel": float(np.nanmean([r.force_mismatch_rel for r in cal.results_])),
            "specific_fracture_energy_J_kg": cal.specific_fracture_energy_J_kg_.tolist(),
            "fracture_energy": {"model": fe.model, "e50_j_kg": fe.e50_j_kg, "sigma": fe.sigma, "n": fe.n,
                                "ks_statistic": fe.ks_statistic, "ks_pvalue": fe.ks_pvalue},
            "drop_weight": drops,
            "selection": {**sel, "sizes_um": sizes.tolist(), "se_t_kwh_per_size": se.tolist(),
                          "typical_specific_energy_1mm_J_kg": e_typ},
            "breakage_function": {"gamma": pe[k]["gamma"], "phi": pe[k]["phi"], "beta": pe[k]["beta"],
                                  "at_specific_energy_J_kg": pe[k]["specific_energy_J_kg"],
                                  "t10_there": pe[k]["t10"]},
            "wall_time_s": time.perf_counter() - t1,
        }
        if verbose:
            o = out[name]
            print(f"{name}: target {target:.0f} N, sigma_t {o['bond']['tensile_strength_MPa']:.2f} MPa, "
                  f"err {o['calibration_error_pct']:.2f} %, E50 {fe.e50_j_kg:.1f} J/kg s {fe.sigma:.3f}, "
                  f"t10 A {drops['t10_fit']['A_pct']:.1f} b {drops['t10_fit']['b_t_kwh']:.3g}, "
                  f"S^E1 {sel['se_1mm_t_kwh']:.3g} alpha {sel['alpha']:.2f} mu {sel['mu_um']:.0f} "
                  f"L {sel['Lambda']:.2f} ({o['wall_time_s']:.0f} s)", flush=True)
    return {"settings": {**{k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()},
                         "spheres_per_particle": SPHERES, "particle_diameter_m": PARTICLE_DIAMETER_M,
                         "platen_speed_m_s": PLATEN_SPEED_M_S, "stiffness_ratio": STIFFNESS_RATIO,
                         "cohesion_ratio": COHESION_RATIO, "drop_mass_kg": DROP_MASS_KG, "drum": DRUM},
            "drum": drum, "ores": {n: out[n] for n in ores}, "dem_seconds": time.perf_counter() - t0}


# ---------------------------------------------------------------------- 5. map + table fit
MAP_KEYS = ("ln_se_1mm", "alpha", "ln_mu", "Lambda", "gamma", "phi")


def _nodes(record: dict):
    rows = []
    for name, o in record["ores"].items():
        s, b = o["selection"], o["breakage_function"]
        rows.append((math.log(o["target_peak_force_N"]),
                     [math.log(s["se_1mm_t_kwh"]), s["alpha"], math.log(s["mu_um"]), s["Lambda"],
                      b["gamma"], b["phi"]]))
    rows.sort()
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])


#: ores may lie this far (in ln F_target) outside the reference span before the map refuses
EXTRAPOLATION_TOL_LN = 0.02


def dem_breakage(ore: Mineralogy, coefficients: dict, record: dict | None = None) -> BreakageParams:
    """DEM-derived breakage parameters of an ore (module docstring, section 5).

    ``coefficients['dem_capture_scale']`` multiplies S^E (default 1: the DEM alone)."""
    rec = record or coefficients.get("_dem_record") or shipped_dem_calibration()
    x, y = _nodes(rec)
    xi = math.log(target_peak_force_N(ore))
    if not (x[0] - EXTRAPOLATION_TOL_LN <= xi <= x[-1] + EXTRAPOLATION_TOL_LN):
        raise TwinInputError(
            f"dem_breakage cannot map ore {ore.name!r}: its strength index F_target = {math.exp(xi):.0f} N "
            f"lies outside the DEM-calibrated reference ores ({math.exp(x[0]):.0f}-{math.exp(x[-1]):.0f} N). "
            "Use twin.calibration.breakage_map.mineralogy_breakage or add DEM calibrations for such ores.")
    v = [float(np.interp(xi, x, y[:, j])) if len(x) > 1 else float(y[0, j]) for j in range(y.shape[1])]
    p = dict(zip(MAP_KEYS, v))
    return BreakageParams(se_1mm_t_kwh=math.exp(p["ln_se_1mm"]) * float(coefficients.get("dem_capture_scale", 1.0)),
                          alpha=p["alpha"], mu_um=math.exp(p["ln_mu"]), Lambda=p["Lambda"],
                          gamma=p["gamma"], beta=AUSTIN_SHAPE["beta"], phi=p["phi"], delta=0.0,
                          source="DEM map (twin.calibration.dem_link)")


#: Start of the table fit (a starting point only; the fit moves every value).
TABLE_START = {"dem_capture_scale": 0.02, "cushioning_rate_coeff": 0.4, "cushioning_power_coeff": 0.6,
               "clay_crowding_coeff": 1.6, "lab_power_factor": 1.3, "lab_grate_d50_um": 450.0,
               "lab_grate_sharpness": 6.5, "lab_discharge_factor": 1.25}
TABLE_BOUNDS = {"dem_capture_scale": (1e-4, 1e4), "cushioning_rate_coeff": (1e-6, 20.0),
                "cushioning_power_coeff": (1e-6, 20.0), "clay_crowding_coeff": (1e-6, 5.0),
                "lab_power_factor": (0.3, 3.0), "lab_grate_d50_um": (10.0, 3000.0),
                "lab_grate_sharpness": (0.5, 10.0), "lab_discharge_factor": (0.5, 50.0)}


def twin_calibration(values: dict, record: dict | None = None) -> dict:
    """{'coefficients', 'mills'} for Twin(..., breakage_map=dem_breakage, calibration=...)."""
    coef = {k: values[k] for k in ("dem_capture_scale", "cushioning_rate_coeff", "cushioning_power_coeff",
                                   "clay_crowding_coeff")}
    if record is not None:
        coef["_dem_record"] = record
    return {"coefficients": coef, "mills": {"lab": lab_mill_values(values)}}


def dem_twin_calibration() -> dict:
    """The shipped DEM-path calibration (table-fitted coefficients) for Twin(calibration=...)."""
    rec = shipped_dem_calibration()
    if "table_fit" not in rec:
        raise TwinError("twin/calibration/files/dem.json has no table fit (made with table_fit=False).")
    return twin_calibration(rec["table_fit"]["values"])


def predict(values: dict, record: dict | None = None, ores=REFERENCE_ORES) -> dict:
    from ..twin import Twin

    cal = twin_calibration(values, record)
    out = {}
    for ore in ores:
        ss = Twin(ore, mill="lab", breakage_map=dem_breakage, calibration=cal) \
            .steady_at_constant_load(speed_frac_critical=0.70)
        out[ore] = {"p80_um": ss.p80_um, "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"],
                    "throughput_kg_h": ss.feed_tph * 1000.0}
    return out


def fit_table(record: dict, max_nfev: int = 60) -> dict:
    ref = reference_table()
    names = tuple(TABLE_START)
    lo = np.log([TABLE_BOUNDS[n][0] for n in names])
    hi = np.log([TABLE_BOUNDS[n][1] for n in names])

    def unpack(z):
        return {n: float(math.exp(v)) for n, v in zip(names, z)}

    failures: list[str] = []

    def resid(z):  # a steady state's solver failure is a bad point (counted); anything else propagates
        try:
            pred = predict(unpack(z), record)
        except SolverError as exc:
            failures.append(str(exc))
            return np.full(len(ref) * len(KPIS), FAILED_POINT_RESIDUAL)
        return np.array([math.log(pred[o][k] / ref[o][k]) for o in ref for k in KPIS])

    t0 = time.perf_counter()
    sol = fit_log_ratios(resid, np.log([TABLE_START[n] for n in names]), lo, hi, max_nfev)
    values = unpack(sol.x)
    pred = predict(values, record)
    err = {o: {k: 100.0 * (pred[o][k] / ref[o][k] - 1.0) for k in KPIS} for o in ref}
    return {"fitted_to": "twin/calibration/data/reference_table.csv (MISSION.md reference table)",
            "parameters_fitted": list(names), "values": values, "predicted": pred, "error_pct": err,
            "max_abs_error_pct": max(abs(e) for r in err.values() for e in r.values()),
            "solver_failures": failed_points_record(failures),
            "from_dem_alone": ["se_1mm_t_kwh ratios between ores", "alpha", "mu_um", "Lambda", "gamma", "phi"],
            "typed_in": {"beta": AUSTIN_SHAPE["beta"], "delta": 0.0},
            "optimizer": {"status": int(sol.status), "message": str(sol.message), "nfev": int(sol.nfev),
                          "seconds": time.perf_counter() - t0}}


def calibrate_from_dem(fast: bool = False, seed: int = 0, *, ores=REFERENCE_ORES, table_fit: bool = True,
                       out: Path | str | None = DEM_CALIBRATION_PATH, verbose: bool = True) -> dict:
    """Regenerate the DEM-derived calibration; writes ``out`` (None: do not write) and returns it."""
    t0 = time.perf_counter()
    record = dem_part(fast=fast, seed=seed, ores=ores, verbose=verbose)
    if table_fit:
        record["table_fit"] = fit_table(record, SETTINGS["fast" if fast else "full"]["table_max_nfev"])
        if verbose:
            print(f"table fit: max |error| {record['table_fit']['max_abs_error_pct']:.1f} %", flush=True)
    record["provenance"] = {"command": "python -m twin.calibration --dem" + (" --fast" if fast else ""),
                            "function": f"twin.calibration.dem_link.calibrate_from_dem(fast={fast}, seed={seed})",
                            "seed": seed, "fast": fast, **versions(),
                            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                            "seconds": time.perf_counter() - t0}
    if out is not None:
        out = Path(out)
        write_json_atomically(out, record, indent=1)
        shipped_dem_calibration.cache_clear()
        if verbose:
            print(f"wrote {out}", flush=True)
    return record


def refit_table(path: Path | str = DEM_CALIBRATION_PATH, max_nfev: int | None = None, verbose: bool = True) -> dict:
    """Rerun only step 5 (the table fit) on a DEM calibration file's own DEM numbers; records it."""
    path = Path(path)
    record = json.loads(path.read_text(encoding="utf-8"))
    for key in ("table_fit",):
        record.pop(key, None)
    fast = bool(record["provenance"]["fast"])
    n = max_nfev or SETTINGS["fast" if fast else "full"]["table_max_nfev"]
    record["table_fit"] = fit_table(record, n)
    record["provenance"]["table_fit_rerun"] = {
        "function": f"twin.calibration.dem_link.refit_table(max_nfev={n})", "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    write_json_atomically(path, record, indent=1)
    shipped_dem_calibration.cache_clear()
    if verbose:
        print(f"table fit: max |error| {record['table_fit']['max_abs_error_pct']:.1f} %; wrote {path}", flush=True)
    return record


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m twin.calibration.dem_link", description=__doc__.split("\n\n")[0])
    ap.add_argument("--fast", action="store_true", help="fewer particles and energies (< 2 min)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=DEM_CALIBRATION_PATH)
    ap.add_argument("--no-table-fit", action="store_true")
    ap.add_argument("--table-only", action="store_true", help="rerun only the table fit on --out's DEM numbers")
    a = ap.parse_args(argv)
    if a.table_only:
        refit_table(a.out)
        return 0
    calibrate_from_dem(a.fast, a.seed, table_fit=not a.no_table_fit, out=a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
