"""The DEM chain, read from the shipped default calibration (twin/calibration/files/dem.json,
made by ``grindtwin calibrate``): what the DEM step gives per ore, how the laws across ores
carry it (with bootstrap standard errors), the table reproduced by the DEM chain and by the
plain regression, and MISSION.md's physics claims as predictions with 90 % intervals over the
bootstrap replicates (the DEM's particle-to-particle scatter).

Writes benchmarks/results/twin_dem_link.md/.csv (per ore), twin_dem_link_bonds.md/.csv (bonds
against MISSION.md's reference calibration), twin_dem_link_table.md/.csv (table) and
twin_dem_link_claims.md/.csv (claims). Run: ``python benchmarks/twin_dem_link.py`` (~1-3 min).
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import write_table
from twin import Blend, Mineralogy, load_ore
from twin.calibration import law_e50_j_kg, load_calibration, reference_table
from twin.calibration.uncertainty import INTERVAL_LEVEL, replicate_steady_states
from twin.twin import Twin

#: MISSION.md section 3 reference calibration (k_n, k_s GPa/m; tensile, cohesion MPa): compared, never used
MISSION_BONDS = {"A": (850, 340, 95, 120), "B": (620, 250, 68, 85), "C": (310, 120, 32, 40), "D": (180, 70, 18, 22)}


def per_ore(cal) -> pd.DataFrame:
    dem, law = cal.record["dem"], cal.record["law"]
    se = cal.record["bootstrap"]["standard_errors"]["e50"]
    own = cal.record["derived"]["per_ore_own_selection"]
    rows = []
    for o, r in dem["ores"].items():
        ore = load_ore(o)
        p = cal.breakage(ore)
        scale = cal.coefficients["dem_capture_scale"]
        rows.append({"ore": o, "target_peak_force_N": r["target_peak_force_N"], "n_particles": r["n_particles"],
                     "tensile_MPa": r["bond"]["tensile_strength_MPa"], "cal_error_pct": r["calibration_error_pct"],
                     "peak_cv_pct": r["peak_force_cv_pct"], "E50_own_J_kg": se[o]["own_particles_j_kg"],
                     "E50_own_se_pct": 100 * se[o]["own_particles_rel_se"], "E50_law_J_kg": law_e50_j_kg(law, ore),
                     "E50_law_se_pct": 100 * se[o]["law_rel_se"], "sigma_own": r["fracture_energy"]["sigma"],
                     "SE1_own_t_kwh": own[o]["se_1mm_t_kwh"], "SE1_law_t_kwh": p.se_1mm_t_kwh / scale,
                     "alpha": p.alpha, "mu_um": p.mu_um, "Lambda": p.Lambda, "gamma": p.gamma, "phi": p.phi,
                     "t10_A_pct": r["drop_weight"]["t10_fit"]["A_pct"], "t10_b_t_kwh": r["drop_weight"]["t10_fit"]["b_t_kwh"],
                     "ore_wall_s": r["wall_time_s"]})
    return pd.DataFrame(rows)


def bonds(cal) -> pd.DataFrame:
    rows = []
    ores = cal.record["dem"]["ores"]
    for o, (kn, ks, st, co) in MISSION_BONDS.items():
        b = ores[o]["bond"]
        rows.append({"ore": o, "kn_GPa_m": b["kn_GPa_m"], "kn_mission": kn, "ks_GPa_m": b["ks_GPa_m"],
                     "ks_mission": ks, "tensile_MPa": b["tensile_strength_MPa"], "tensile_mission": st,
                     "cohesion_MPa": b["cohesion_MPa"], "cohesion_mission": co,
                     "tensile_ratio_to_B": b["tensile_strength_MPa"] / ores["B"]["bond"]["tensile_strength_MPa"],
                     "mission_tensile_ratio_to_B": st / 68.0})
    return pd.DataFrame(rows)


def table_rows(cals) -> pd.DataFrame:
    ref = reference_table()
    rows = []
    for cal in cals:
        fit = cal.record["fit"]
        for o in ref:
            for k in ref[o]:
                rows.append({"calibration": cal.name, "ore": o, "kpi": k, "mission": ref[o][k],
                             "twin": fit["predicted"][o][k], "error_pct": fit["error_pct"][o][k]})
    return pd.DataFrame(rows)


def pyrite_b() -> Mineralogy:
    b = load_ore("B")
    return Mineralogy(dict(b.wt_pct, pyrite=b.wt_pct["pyrite"] + 15.0, biotite=b.wt_pct["biotite"] - 15.0),
                      b.texture, name="B_pyrite")


def _nominal(ore, cal) -> dict:
    ss = Twin(ore, calibration=cal).steady_at_constant_load(0.70)
    return {"p80_um": ss.p80_um, "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"],
            "throughput_tph": ss.feed_tph}


def claim_rows(cal) -> pd.DataFrame:
    """Each claim's change (case over its reference case) at constant load, 70 % critical, lab
    mill: nominal and the 90 % interval of the paired replicates."""
    a, d = load_ore("A"), load_ore("D")
    cases = {"+15 pyrite / -15 biotite in B": (load_ore("B"), pyrite_b()), "A -> D": (a, d),
             "A -> 50 % A / 50 % D (mixed mineralogy)": (a, a.mix(d, 0.5)),
             "blend 80 % A / 20 % C vs A": ("A", Blend.parse("A=0.8,C=0.2")),
             "blend 50 % B / 50 % D vs B": ("B", Blend.parse("B=0.5,D=0.5")),
             "blend A, B, C thirds vs B": ("B", Blend.parse("A=0.3333333333333333,B=0.3333333333333333,C=0.3333333333333334"))}
    lo_q, hi_q = 50 * (1 - INTERVAL_LEVEL), 50 * (1 + INTERVAL_LEVEL)
    rows = []
    for label, (ref_ore, ore) in cases.items():
        n_ref, n_case = _nominal(ref_ore, cal), _nominal(ore, cal)
        r_ref = replicate_steady_states(ref_ore, cal, at_load=True)
        r_case = replicate_steady_states(ore, cal, at_load=True)
        pairs = [(x, y) for x, y in zip(r_ref, r_case) if x is not None and y is not None]
        for k in ("p80_um", "specific_energy_kwh_t", "throughput_tph"):
            ch = np.array([100 * (y[k] / x[k] - 1) for x, y in pairs])
            rows.append({"case": label, "kpi": k, "reference": n_ref[k], "case_value": n_case[k],
                         "change_pct": 100 * (n_case[k] / n_ref[k] - 1), "change_lo_pct": float(np.percentile(ch, lo_q)),
                         "change_hi_pct": float(np.percentile(ch, hi_q)), "replicates": len(pairs)})
    return pd.DataFrame(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.parse_args(argv)
    cal, table = load_calibration("dem"), load_calibration("table")
    law = cal.record["law"]["energy"]
    se = cal.record["bootstrap"]["standard_errors"]
    times = cal.record["provenance"].get("times_s", {})
    write_table(per_ore(cal), "twin_dem_link", "DEM chain per reference ore (shipped dem.json)",
                f"{cal.record['dem']['settings']['spheres_per_particle']} spheres per 22 mm particle, "
                f"{cal.record['dem']['settings']['n_particles']} particles per ore. Energy law ln E50 = c0 + c1 ln Pi: "
                f"c0 {law['c0']:.3f} +/- {se['c0']:.3f}, c1 {law['c1']:.3f} +/- {se['c1']:.3f} (dimensional "
                f"analysis: 1), sigma {law['sigma']:.3f} +/- {se['sigma']:.3f} (bootstrap SEs, "
                f"{cal.record['bootstrap']['n']} replicates). SE1_law before the fitted capture scale "
                f"{cal.coefficients['dem_capture_scale']:.4g}. Times: DEM step {times.get('dem_step_s', float('nan')):.0f} s, "
                f"table step {times.get('table_step_s', float('nan')):.0f} s, bootstrap "
                f"{times.get('bootstrap_s', float('nan')):.0f} s ({cal.record['provenance']['command']}).")
    write_table(bonds(cal), "twin_dem_link_bonds", "Fitted bond parameters vs MISSION.md's reference calibration",
                "k_n = E_b / (2 r_mean) (Potyondy & Cundall 2004 eq. 9) depends on the sphere size; bond strength is "
                "resolution- and convention-specific; only the ratios between ores compare.")
    write_table(table_rows([cal, table]), "twin_dem_link_table",
                "MISSION.md's table by the DEM chain (dem) and the plain regression (table)",
                f"dem fits {len(cal.fitted)} ore-independent numbers ({', '.join(cal.fitted)}); table fits "
                f"{len(table.fitted)} ({', '.join(table.fitted)}).")
    write_table(claim_rows(cal), "twin_dem_link_claims",
                "MISSION.md's claims as predictions of the default calibration (lab mill, 0.70, constant load)",
                f"change_lo/hi: {INTERVAL_LEVEL:.0%} interval of the change over the bootstrap replicates (paired).")


if __name__ == "__main__":
    main()
