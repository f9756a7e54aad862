"""Speed of the DEM compression test: particle-steps per second at ~500, 2000, 8000 spheres.

Single-threaded numba (no ``parallel=True`` anywhere in ``dem``). For each size: one seeded
agglomerate (22 mm, radii r(1 ± 0.25), bonds within 1.3 (R1 + R2)), the issue's benchmark
material (E = 30 GPa, ks/kn = 0.4, tensile 10 MPa, cohesion 20 MPa, friction 30°, 2700 kg/m³,
platen 0.1 m/s, local damping 0.7), the loading phase of the compression test timed over
``steps`` steps, median of ``repeats`` runs (after a warm-up that compiles the kernels).

Writes benchmarks/results/dem_speed.csv and .md. Run: ``python benchmarks/dem_speed.py`` (no options).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numba
import numpy as np
import pandas as pd

from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams, BondSet, kn_from_modulus_Pa_m
from dem.materials import STEEL, Material
from dem.system import PlaneWall, System
from dem_common import write_table

SIZES = [(500, 1500, 5), (2000, 400, 5), (8000, 100, 3)]


def make_system(agg):
    kn = kn_from_modulus_Pa_m(30e9, agg.mean_radius_m)
    bp = BondParams(kn_Pa_m=kn, ks_Pa_m=0.4 * kn, tensile_strength_Pa=10e6, cohesion_Pa=20e6)
    pos = agg.pos_m.copy()
    bs = BondSet(agg.bond_pairs, pos, agg.radius_m, bp)
    z_lo = float(np.min(pos[:, 2] - agg.radius_m))
    z_hi = float(np.max(pos[:, 2] + agg.radius_m))
    walls = [PlaneWall((0, 0, z_lo), (0, 0, 1)), PlaneWall((0, 0, z_hi), (0, 0, -1), (0, 0, -0.1))]
    mat = Material(youngs_modulus_Pa=30e9, density_kg_m3=2700.0)
    return System(pos, agg.radius_m, mat, density_kg_m3=2700.0 / agg.solid_fraction, bonds=bs,
                  wall_material=STEEL, walls=walls, local_damping=0.7, time_step_factor=0.5)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="Sizes, steps and repeats: " + ", ".join(
                                     f"{n} spheres x {steps} steps x {repeats}" for n, steps, repeats in SIZES))
    ap.parse_args(argv)
    numba.set_num_threads(1)
    rows = []
    warm = make_system(make_agglomerate(0.022, 100, random_state=0))
    warm.run(10)
    for n, steps, repeats in SIZES:
        t0 = time.perf_counter()
        agg = make_agglomerate(0.022, n, random_state=0)
        t_pack = time.perf_counter() - t0
        times = []
        for _ in range(repeats):
            s = make_system(agg)
            t0 = time.perf_counter()
            s.run(steps)
            times.append(time.perf_counter() - t0)
        med = float(np.median(times))
        rows.append({"n_spheres": n, "n_bonds": agg.n_bonds, "steps": steps, "repeats": repeats,
                     "median_wall_s": med, "min_wall_s": float(np.min(times)),
                     "particle_steps_per_s": n * steps / med,
                     "ns_per_particle_step": med / (n * steps) * 1e9, "packing_s": t_pack,
                     "dt_s": s.dt_s})
        print(rows[-1], flush=True)
    df = pd.DataFrame(rows)
    write_table(df, "dem_speed", "DEM compression-test speed (single thread)",
                f"machine: {platform.machine()}, {os.cpu_count()} cores shared with other jobs while "
                f"measured (numbers are lower bounds); numba {numba.__version__}; "
                "time_step_factor 0.5; loading phase of the compression test.")


if __name__ == "__main__":
    main()
