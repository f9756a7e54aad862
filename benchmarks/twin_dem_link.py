"""DEM -> twin link: what the shipped (full) DEM calibration says per ore, what the --fast path
gives and what each costs in time; the table reproduction of the DEM-based twin.

Reads twin/calibration/files/dem.json (made by ``python -m twin.calibration --dem``), runs the
``--fast`` DEM part (no table fit, not written) and writes
benchmarks/results/twin_dem_link.csv/.md (one row per ore and path) and
twin_dem_link_table.csv/.md (P80, specific energy, throughput at constant load vs MISSION.md).
Run: ``python benchmarks/twin_dem_link.py`` (~2-3 min on one free core).
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

import pandas as pd

from dem_common import write_table
from twin.calibration import dem_link
from twin.calibration import reference_table


def rows_of(rec: dict, path: str, seconds: float) -> list:
    out = []
    for o, r in rec["ores"].items():
        out.append({"path": path, "ore": o, "target_peak_force_N": r["target_peak_force_N"],
                    "n_particles": r["n_particles"], "kn_GPa_m": r["bond"]["kn_GPa_m"],
                    "ks_GPa_m": r["bond"]["ks_GPa_m"], "tensile_MPa": r["bond"]["tensile_strength_MPa"],
                    "cohesion_MPa": r["bond"]["cohesion_MPa"], "cal_error_pct": r["calibration_error_pct"],
                    "peak_cv_pct": r["peak_force_cv_pct"], "E50_J_kg": r["fracture_energy"]["e50_j_kg"],
                    "sigma": r["fracture_energy"]["sigma"], "t10_A_pct": r["drop_weight"]["t10_fit"]["A_pct"],
                    "t10_b_t_kwh": r["drop_weight"]["t10_fit"]["b_t_kwh"],
                    "SE_1mm_t_kwh": r["selection"]["se_1mm_t_kwh"], "alpha": r["selection"]["alpha"],
                    "mu_um": r["selection"]["mu_um"], "Lambda": r["selection"]["Lambda"],
                    "gamma": r["breakage_function"]["gamma"], "phi": r["breakage_function"]["phi"],
                    "ore_wall_s": r["wall_time_s"], "total_dem_s": seconds})
    return out


#: MISSION.md section 3 reference calibration (k_n, k_s GPa/m; tensile, cohesion MPa): compared, never used
MISSION_BONDS = {"A": (850, 340, 95, 120), "B": (620, 250, 68, 85), "C": (310, 120, 32, 40), "D": (180, 70, 18, 22)}


def mission_comparison(full: dict) -> None:
    rows = []
    for o, (kn, ks, st, co) in MISSION_BONDS.items():
        b = full["ores"][o]["bond"]
        r_mean_mm = 0.5 * b["bond_modulus_GPa"] / b["kn_GPa_m"] * 1000.0
        rows.append({"ore": o, "kn_GPa_m": b["kn_GPa_m"], "kn_mission": kn, "ks_GPa_m": b["ks_GPa_m"],
                     "ks_mission": ks, "tensile_MPa": b["tensile_strength_MPa"], "tensile_mission": st,
                     "cohesion_MPa": b["cohesion_MPa"], "cohesion_mission": co,
                     "mean_sphere_radius_mm": r_mean_mm,
                     "mission_bond_modulus_at_our_radius_GPa": kn * 2 * r_mean_mm / 1000.0,
                     "tensile_ratio_to_B": b["tensile_strength_MPa"] / full["ores"]["B"]["bond"]["tensile_strength_MPa"],
                     "mission_tensile_ratio_to_B": st / 68.0,
                     "cal_error_pct": full["ores"][o]["calibration_error_pct"]})
    write_table(pd.DataFrame(rows), "twin_dem_link_bonds",
                "Fitted bond parameters vs MISSION.md's reference calibration",
                "k_n = E_b / (2 r_mean) (Potyondy & Cundall 2004 eq. 9) depends on the sphere size: MISSION's "
                "k_n at our sphere radius would be a bond modulus of ~0.6-2.9 GPa (ours: the ore's Young's "
                "modulus, 34-77 GPa). Bond strength is resolution- and convention-specific (bond area "
                "pi (lambda r)^2, lambda = 1 here; see benchmarks/dem_yade.py); only the ratios between "
                "ores compare: ours follow sqrt(E H), MISSION's fall faster (D/B 0.26 vs 0.56).")


def main():
    full = dem_link.shipped_dem_calibration()
    mission_comparison(full)
    rows = rows_of(full, "full (shipped)", full["dem_seconds"])
    fast = dem_link.dem_part(fast=True, seed=full["provenance"]["seed"])
    rows += rows_of(fast, "fast", fast["dem_seconds"])
    write_table(pd.DataFrame(rows), "twin_dem_link",
                "DEM-derived breakage per ore: full (shipped) vs --fast",
                f"{dem_link.SPHERES} spheres per 22 mm particle; bond modulus = ore VRH Young's modulus; "
                "targets F_B = 4.2 kN, F_X = F_B sqrt(E_X H_X / (E_B H_B)). E50/sigma: log-normal of the "
                "compression fracture energies. t10 extrapolated by Austin's B fitted to the resolved "
                "fragment sizes. S^E from the drum DEM spectrum at 0.70 critical x P_break (capture "
                "model), before the table-fitted capture scale.")
    if "table_fit" in full:
        ref = reference_table()
        tf = full["table_fit"]
        trows = []
        for o in ref:
            for k in ref[o]:
                trows.append({"ore": o, "kpi": k, "mission": ref[o][k], "twin_dem": tf["predicted"][o][k],
                              "error_pct": tf["error_pct"][o][k]})
        write_table(pd.DataFrame(trows), "twin_dem_link_table",
                    "DEM-based twin vs MISSION.md reference table (lab mill, 70 % critical, constant load)",
                    "Fitted to the table: " + ", ".join(tf["parameters_fitted"]) + ". From the DEM alone: "
                    + ", ".join(tf["from_dem_alone"]) + ".")


if __name__ == "__main__":
    main()
