"""Drop-weight impacts: breakage and t10 against specific energy (input for twin's t10 relation).

Bond parameters: read from benchmarks/results/dem_calibration.csv (the ``issue_material`` Type B
calibration, fitted by benchmarks/dem_calibration.py), never typed in. Agglomerates at the
calibration's resolution (bond parameters are resolution-specific) at 22 mm; seeds 0-2;
specific energies 20 J/kg ... 3 kJ/kg. Writes benchmarks/results/dem_impact.csv/.md and
dem_impact_runs.csv. Run: ``python benchmarks/dem_impact.py [--spheres N] [--energies 20,40,300]``
(defaults: the calibration's resolution, energies 20,40,70,100,300,1000,3000 J/kg).
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

import pandas as pd

from dem_common import OUT, POSITIVE_LIST, SPHERES_MAX, SPHERES_MIN, option_type, write_table
from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams
from dem.lab import drop_weight_test

ENERGIES = "20,40,70,100,300,1000,3000"
SEEDS = [0, 1, 2]


def options(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    spheres = option_type(int, lambda v: v == 0 or SPHERES_MIN <= v <= SPHERES_MAX,
                          f"0 (the calibration's resolution) or an integer in [{SPHERES_MIN}, {SPHERES_MAX}]")
    ap.add_argument("--spheres", type=spheres, default=0,
                    help="spheres per particle; 0 (the default): the calibration's own resolution")
    ap.add_argument("--energies", type=POSITIVE_LIST, default=ENERGIES,
                    help="specific energies, J/kg, comma-separated (default %(default)s)")
    return ap.parse_args(argv)


def main(argv=None):
    o = options(argv)
    cal = pd.read_csv(os.path.join(OUT, "dem_calibration.csv")).set_index("calibration").loc["issue_material"]
    cal_n = int(cal["spheres_per_particle"])
    n = o.spheres or cal_n
    rows = []
    for seed in SEEDS:
        agg = make_agglomerate(0.022, n, random_state=seed)
        kn = float(cal["kn_GPa_m"]) * 1e9
        bp = BondParams(kn_Pa_m=kn, ks_Pa_m=float(cal["ks_GPa_m"]) * 1e9,
                        tensile_strength_Pa=float(cal["tensile_strength_MPa"]) * 1e6,
                        cohesion_Pa=float(cal["cohesion_MPa"]) * 1e6)
        for e in o.energies:
            r = drop_weight_test(agg, bp, e, time_step_factor=0.5)
            row = {"seed": seed}
            row.update(r.summary())
            rows.append(row)
            print(row, flush=True)
    df = pd.DataFrame(rows)
    mean = df.groupby("specific_energy_J_kg")[["t2", "t4", "t10", "broken_fraction", "largest_fragment_frac",
                                                "n_fragments", "wall_time_s"]].mean().reset_index()
    df.to_csv(os.path.join(OUT, "dem_impact_runs.csv"), index=False)
    write_table(mean, "dem_impact", "Drop-weight impacts with the Type B calibration (mean of 3 particles)",
                f"{n} spheres per 22 mm particle ({'the calibration' if n == cal_n else 'not the calibration'}'s "
                f"resolution{'' if n == cal_n else f', {cal_n}: its bond parameters are resolution-specific'}), "
                "1 kg drop weight. "
                "t_n = mass fraction finer than D0/n; at this resolution a single sphere is about "
                f"D0/{n ** (1 / 3):.1f}, so t10 is not resolved (t2, t4 are; twin can map them to t10 "
                "with the t-family of Narayanan & Whiten 1988).")


if __name__ == "__main__":
    main()
