"""Drum-mill DEM of the laboratory mill (0.5 m x 0.3 m): power and collision spectra.

1. speed sweep at J = 0.35 (0.5 ... 0.9 of critical): power draw (W) and collision rate, beside
   the twin's power models for the same mill (twin.mill.LAB): Bond's equation
   (``bond_power_kw``, the one the twin uses, published form: power_factor 1) and Hogg &
   Fuerstenau's torque-arm model (``hogg_fuerstenau_power_kw``); difference in % of the model;
2. at 0.7 of critical: ball stiffness (Young's modulus 1 GPa default vs 10 GPa) -> power and
   collision rate (``--checks``; the revolutions / ball-number accuracy study is
   benchmarks/dem_drum_accuracy.py);
3. the collision-energy spectrum per speed (dem_drum_spectrum.csv at 0.7, all speeds run in
   dem_drum_spectrum_speeds.csv).

Writes benchmarks/results/dem_drum.csv/.md. ``--speeds 0.8 0.9`` runs only those speeds and
merges them into the existing table (rows of the same case and speed are replaced), so a sweep
stopped early on a shared machine can be finished piecewise; ``--models-only`` recomputes the
model columns of the existing table without running the DEM.
Run: ``python benchmarks/dem_drum.py [--speeds ...] [--checks]`` (1-3 min per speed measured here, single thread).
"""

from __future__ import annotations

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import OUT, write_table
from dem.drum import drum_test
from dem.materials import Material
from twin.calibration import load_calibration
from twin.mill import LAB, bond_power_kw, hogg_fuerstenau_power_kw

SPEEDS = (0.5, 0.6, 0.7, 0.8, 0.9)
#: the settings of every speed_sweep row (the rows of one table must share them)
SETTLE_REV, MEASURE_REV = 1.0, 3.0

#: the default calibration's fitted lab-mill power factor, read when the table is written (the
#: note quoted a value typed in by hand, which went stale when the calibration was regenerated)
_CALIBRATION = load_calibration()
_LAB_POWER_FACTOR = _CALIBRATION.record["mills"]["lab"]["power_factor"]
TITLE = "Drum DEM of the lab mill (0.5 m x 0.3 m, 25 mm balls, 8 lifters, J = 0.35)"
NOTES = (
    "3D periodic slice 0.1 m long (504 balls) scaled to 0.3 m; power = -torque x omega; ball Young's "
    "modulus 1 GPa unless stated; impact energy = m* v_n^2/2 at first contact; settle 1 rev, measure "
    "3 revs. Speeds as fractions of the DEM's critical speed sqrt(2g/(D-d)). Models: twin.mill for "
    "the LAB mill at the same fraction of critical and J: bond_W = Bond (1961) as the twin uses it "
    "with power_factor 1 (the published equation; the twin's fitted lab power_factor "
    f"{_LAB_POWER_FACTOR:.3g} in the default calibration {_CALIBRATION.name!r} "
    f"({_CALIBRATION.identity()['path']}) is fitted to MISSION's "
    "energies, not to this DEM), hf_W = Hogg & "
    "Fuerstenau (1972) torque arm at a 35 deg dynamic angle (omega from sqrt(2g/D), 2.5 % below the "
    "DEM's omega at the same fraction; no centrifuging loss). diff_*_pct = (DEM - model) / model. "
    "Rows of a `--speeds` run replace those of the same case and speed; wall times (single thread) are "
    "on a shared 2-core machine.")


def notes(df: pd.DataFrame) -> str:
    """:data:`NOTES` and the 10 GPa check beside the 1 GPa run's same window (settle 1, measure 1
    rev: the 'measure 1 rev' row of dem_drum_accuracy.csv, when that table exists)."""
    e = df[df["case"] == "E_ball_10GPa"]
    path = os.path.join(OUT, "dem_drum_accuracy.csv")
    if e.empty or not os.path.exists(path):
        return NOTES
    acc = pd.read_csv(path)
    ref = acc[acc["setting"].str.startswith("measure 1 rev")]
    if ref.empty:
        return NOTES
    p1, c1 = float(ref["power_W"].iloc[0]), float(ref["collisions_per_s"].iloc[0])
    p10, c10 = float(e["power_W"].iloc[0]), float(e["collisions_per_s"].iloc[0])
    return (NOTES + f" E_ball_10GPa: 0.7 critical, settle 1, measure 1 rev; the 1 GPa run's same window "
            f"(dem_drum_accuracy.md) {p1:.1f} W, {c1:.3g} collisions/s: power moves {100 * (p10 / p1 - 1):+.1f} %, "
            f"the collision count x {c10 / c1:.2f} (the stiffer balls' extra contacts are low-energy).")


def row(label, r):
    d = {"case": label}
    d.update(r.summary())
    d["power_per_rev_W"] = " ".join(f"{p:.1f}" for p in r.power_per_rev_W)
    d["ball_ball_frac"] = float(r.spectrum["ball_ball_per_s"].sum() / max(r.collisions_per_s, 1e-30))
    e = r.spectrum["energy_mid_J"].to_numpy()
    w = r.spectrum["total_per_s"].to_numpy()
    d["mean_impact_energy_J"] = float(np.sum(e * w) / max(np.sum(w), 1e-30))
    d["impact_power_W"] = float(np.sum(e * w))
    # JSON (NaN written as NaN, numpy scalars as numbers): a dict's repr prints a bare nan, which
    # dem_drum_table_from_log.py could not read back
    print(json.dumps(d, default=lambda v: v.item()), flush=True)
    return d


def add_models(df: pd.DataFrame) -> pd.DataFrame:
    """Bond and Hogg-Fuerstenau power (twin.mill, LAB at the row's speed and J) and the DEM's
    difference from each, on the speed_sweep rows."""
    df = df.drop(columns=[c for c in ("bond_W", "diff_bond_pct", "hf_W", "diff_hf_pct") if c in df], errors="ignore")
    bond, hf = [], []
    for _, r in df.iterrows():
        if r["case"] != "speed_sweep":
            bond.append(np.nan)
            hf.append(np.nan)
            continue
        mill = LAB.with_(ball_filling_frac=float(r["ball_filling"]))
        bond.append(1000.0 * bond_power_kw(mill, float(r["speed_frac_critical"])))
        hf.append(1000.0 * hogg_fuerstenau_power_kw(mill, float(r["speed_frac_critical"])))
    pos = list(df.columns).index("power_W") + 1
    df.insert(pos, "bond_W", bond)
    df.insert(pos + 1, "diff_bond_pct", 100.0 * (df["power_W"] - df["bond_W"]) / df["bond_W"])
    df.insert(pos + 2, "hf_W", hf)
    df.insert(pos + 3, "diff_hf_pct", 100.0 * (df["power_W"] - df["hf_W"]) / df["hf_W"])
    return df


def merge(old: pd.DataFrame, new: pd.DataFrame) -> pd.DataFrame:
    """Rows of ``new`` replace those of ``old`` with the same case and speed."""
    if old is None or old.empty:
        return new
    key = lambda d: list(zip(d["case"], np.round(d["speed_frac_critical"].astype(float), 6)))
    drop = set(key(new))
    keep = old[[k not in drop for k in key(old)]]
    out = pd.concat([keep, new], ignore_index=True)
    order = {"speed_sweep": 0}
    out["_o"] = [order.get(c, 1) for c in out["case"]]
    return out.sort_values(["_o", "speed_frac_critical"], kind="stable").drop(columns="_o").reset_index(drop=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speeds", type=float, nargs="*", default=list(SPEEDS))
    ap.add_argument("--checks", action="store_true", help="also the 10 GPa ball-stiffness check at 0.7")
    ap.add_argument("--models-only", action="store_true")
    a = ap.parse_args(argv)
    path = os.path.join(OUT, "dem_drum.csv")
    old = pd.read_csv(path) if os.path.exists(path) else None
    rows, spectra = [], []
    if not a.models_only:
        for phi in a.speeds:
            r = drum_test(phi, 0.35, settle_revolutions=SETTLE_REV, measure_revolutions=MEASURE_REV)
            rows.append(row("speed_sweep", r))
            spectra.append(r.spectrum.assign(speed_frac_critical=phi))
            if phi == 0.7:
                r.spectrum.to_csv(os.path.join(OUT, "dem_drum_spectrum.csv"), index=False)
        if a.checks:
            stiff = Material(youngs_modulus_Pa=1e10, poisson_ratio=0.3, density_kg_m3=7800.0,
                             friction_coef=0.3, restitution=0.7)
            r = drum_test(0.7, 0.35, ball_material=stiff, settle_revolutions=1.0, measure_revolutions=1.0)
            rows.append(row("E_ball_10GPa", r))
    if spectra:
        sp_path = os.path.join(OUT, "dem_drum_spectrum_speeds.csv")
        new_sp = pd.concat(spectra, ignore_index=True)
        if os.path.exists(sp_path):
            old_sp = pd.read_csv(sp_path)
            old_sp = old_sp[~np.isin(np.round(old_sp["speed_frac_critical"], 6), np.round(a.speeds, 6))]
            new_sp = pd.concat([old_sp, new_sp], ignore_index=True).sort_values(
                ["speed_frac_critical", "energy_lo_J"], kind="stable")
        cols = ["speed_frac_critical"] + [c for c in new_sp.columns if c != "speed_frac_critical"]
        new_sp[cols].to_csv(sp_path, index=False)
    df = merge(old, pd.DataFrame(rows)) if rows else old
    write_table(add_models(df), "dem_drum", TITLE, notes(df))


if __name__ == "__main__":
    main()
