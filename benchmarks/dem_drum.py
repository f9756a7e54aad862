"""Drum-mill DEM of the laboratory mill (0.5 m x 0.3 m): power and collision spectra.

1. speed sweep at J = 0.35 (0.5 ... 0.9 of critical): power draw (W) and collision rate;
2. at 0.7 of critical: accuracy against time — revolutions measured and ball stiffness
   (Young's modulus 1 GPa default vs 10 GPa) -> power and collision rate;
3. the collision-energy spectrum at 0.7 / J = 0.35.

The DEM power is *not* compared with a power model here: ``twin`` owns that model.
Writes benchmarks/results/dem_drum.csv/.md and dem_drum_spectrum.csv.
Run: ``python benchmarks/dem_drum.py`` (about 10 min on one free core).
"""

from __future__ import annotations

import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import OUT, write_table
from dem.drum import SOFT_STEEL_BALL, drum_test
from dem.materials import Material


def row(label, r):
    d = {"case": label}
    d.update(r.summary())
    d["power_per_rev_W"] = " ".join(f"{p:.1f}" for p in r.power_per_rev_W)
    d["ball_ball_frac"] = float(r.spectrum["ball_ball_per_s"].sum() / max(r.collisions_per_s, 1e-30))
    e = r.spectrum["energy_mid_J"].to_numpy()
    w = r.spectrum["total_per_s"].to_numpy()
    d["mean_impact_energy_J"] = float(np.sum(e * w) / max(np.sum(w), 1e-30))
    d["impact_power_W"] = float(np.sum(e * w))
    print(d, flush=True)
    return d


def main():
    rows = []
    for phi in [0.5, 0.6, 0.7, 0.8, 0.9]:
        r = drum_test(phi, 0.35, settle_revolutions=1.0, measure_revolutions=3.0)
        rows.append(row("speed_sweep", r))
        if phi == 0.7:
            r.spectrum.to_csv(os.path.join(OUT, "dem_drum_spectrum.csv"), index=False)
    r = drum_test(0.7, 0.35, settle_revolutions=1.0, measure_revolutions=1.0)
    rows.append(row("1_rev_measured", r))
    stiff = Material(youngs_modulus_Pa=1e10, poisson_ratio=0.3, density_kg_m3=7800.0,
                     friction_coef=0.3, restitution=0.7)
    r = drum_test(0.7, 0.35, ball_material=stiff, settle_revolutions=1.0, measure_revolutions=1.0)
    rows.append(row("E_ball_10GPa", r))
    write_table(pd.DataFrame(rows), "dem_drum",
                "Drum DEM of the lab mill (0.5 m x 0.3 m, 25 mm balls, 8 lifters, J = 0.35)",
                "3D periodic slice 0.1 m long scaled to 0.3 m; power = -torque x omega; ball "
                "Young's modulus 1 GPa unless stated; impact energy = m* v_n^2/2 at first contact.")


if __name__ == "__main__":
    main()
