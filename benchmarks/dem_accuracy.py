"""What accuracy costs in the DEM compression test: resolution, time step, platen speed.

Three sweeps on the issue's benchmark material (22 mm particle, E = 30 GPa, ks/kn = 0.4,
tensile 10 MPa, cohesion 20 MPa, friction 30°, 2700 kg/m³, local damping 0.7), each point the
mean over the same ``SEEDS`` agglomerates:

1. spheres per particle (time_step_factor 0.5, platen 0.1 m/s) -> peak force, fracture energy,
   wall time; the reference is the finest resolution. Note: with *fixed* bond parameters the
   particle strength of a bonded-particle model changes with resolution (Potyondy & Cundall
   2004 §3.3), so this sweep says how far a calibration at one resolution carries to another;
2. time_step_factor (250 spheres) -> same; reference is the smallest factor;
3. platen speed (250 spheres) -> top/bottom force mismatch before the peak (quasi-static
   check) and peak force; reference is the slowest.

Writes benchmarks/results/dem_accuracy.csv and .md. Run: ``python benchmarks/dem_accuracy.py [--fast]``
(about 10 min on one free core; ``--fast``: 2 seeds, coarser sweeps).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import load_average, write_table
from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams, kn_from_modulus_Pa_m
from dem.lab import compression_test

SEEDS, SEEDS_FAST = [0, 1, 2], [0, 1]


def point(n, seeds, factor=0.5, speed=0.1):
    peaks, energies, walls, mism = [], [], [], []
    for seed in seeds:
        agg = make_agglomerate(0.022, n, random_state=seed)
        kn = kn_from_modulus_Pa_m(30e9, agg.mean_radius_m)
        bp = BondParams(kn_Pa_m=kn, ks_Pa_m=0.4 * kn, tensile_strength_Pa=10e6, cohesion_Pa=20e6)
        r = compression_test(agg, bp, time_step_factor=factor, platen_speed_m_s=speed)
        peaks.append(r.peak_force_N)
        energies.append(r.fracture_energy_J)
        walls.append(r.wall_time_s)
        mism.append(r.force_mismatch_rel)
    return {"peak_force_N": float(np.mean(peaks)),
            "peak_force_sd_N": float(np.std(peaks, ddof=1)),
            "fracture_energy_J": float(np.mean(energies)),
            "force_mismatch_rel": float(np.mean(mism)),
            "wall_time_per_test_s": float(np.mean(walls))}


def sweep(name, values, fn):
    rows = []
    for v in values:
        t0 = time.perf_counter()
        row = {"sweep": name, "value": v}
        row.update(fn(v))
        rows.append(row)
        print(row, f"({time.perf_counter() - t0:.1f} s)", flush=True)
    ref = rows[-1] if name != "time_step_factor" else rows[0]
    if name == "platen_speed_m_s":
        ref = rows[0]
    for r in rows:
        r["peak_err_pct"] = 100 * (r["peak_force_N"] / ref["peak_force_N"] - 1)
        r["energy_err_pct"] = 100 * (r["fracture_energy_J"] / ref["fracture_energy_J"] - 1)
        r["reference"] = ref["value"]
    return rows


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fast", action="store_true", help="2 seeds and coarser sweeps (a smoke run)")
    fast = ap.parse_args(argv).fast
    seeds = SEEDS_FAST if fast else SEEDS
    res = [60, 125, 250, 500] if fast else [60, 125, 250, 500, 1000]
    rows = []
    rows += sweep("spheres_per_particle", res, lambda n: point(n, seeds))
    factors = [0.25, 0.5, 1.0] if fast else [0.125, 0.25, 0.5, 1.0]
    speeds = [0.05, 0.1, 0.2, 0.4] if fast else [0.025, 0.05, 0.1, 0.2, 0.4]
    rows += sweep("time_step_factor", factors, lambda f: point(250, seeds, factor=f))
    rows += sweep("platen_speed_m_s", speeds, lambda v: point(250, seeds, speed=v))
    df = pd.DataFrame(rows)
    write_table(df, "dem_accuracy", "DEM compression test: accuracy against time",
                f"Command: `python benchmarks/dem_accuracy.py {' '.join(argv)}`, load average "
                f"{load_average()} at the end (2 cores; wall times vary "
                "with the load, the step counts do not: a time step twice as large takes half the steps). "
                f"Mean of seeds {seeds}, the same packings at every point; errors relative to the "
                "`reference` value of each sweep (finest resolution, smallest time step, slowest platen). "
                "Peak-force scatter between particles (peak_force_sd_N) is the natural limit of any "
                "comparison across packings.")


if __name__ == "__main__":
    main()
