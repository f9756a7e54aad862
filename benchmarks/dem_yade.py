"""grindtwin DEM against Yade on the issue's compression test, side by side.

Builds one packing (22 mm, 500 spheres, seed 0), runs ``dem.lab.compression_test`` with the
issue's parameters, writes the packing for Yade, runs ``yade -n -x dem_yade_compression.py`` on
the same packing, and compares peak force, energy to the peak and particle-steps per second.
Model differences: grindtwin bonds are parallel bonds ``k_n = E/(R1+R2)`` per unit area with
Hertz contacts after breakage; Yade's CohFrictMat bonds are linear springs
``k_n = 2 E R1 R2/(R1+R2)`` with Cundall–Strack (linear) contacts; so forces agree only to
within the difference of the two bond stiffness/strength conventions.
Writes benchmarks/results/dem_yade.csv/.md. Needs ``yade`` on PATH (Debian package ``yade``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import OUT, write_table
from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams, kn_from_modulus_Pa_m
from dem.lab import compression_test
from dem.materials import Material

N = int(os.environ.get("DEM_SPHERES", "500"))


def main():
    yade = shutil.which("yade") or shutil.which("yade-batch")
    agg = make_agglomerate(0.022, N, random_state=0)
    os.makedirs(OUT, exist_ok=True)
    pack = os.path.join(OUT, f"dem_yade_pack_{N}.txt")
    with open(pack, "w") as fh:
        fh.write(f"# x_m y_m z_m r_m solid_fraction {agg.solid_fraction}\n")
        for p, r in zip(agg.pos_m, agg.radius_m):
            fh.write(f"{p[0]:.9g} {p[1]:.9g} {p[2]:.9g} {r:.9g}\n")
    rows = []
    cases = [("grindtwin, own conventions (kn = E/(R1+R2) per area, bond moments, c const)", 1.0, 1.0, 0.0),
             ("grindtwin, Yade-JCFpm conventions (kn A = 2E R1R2/(R1+R2), no moments, c + sigma tan 30)",
              2.0 / np.pi, 0.0, 30.0)]
    for label, kn_conv, beta, phi_b in cases:
        kn = kn_from_modulus_Pa_m(30e9, agg.mean_radius_m) * kn_conv
        bp = BondParams(kn_Pa_m=kn, ks_Pa_m=0.4 * kn, tensile_strength_Pa=10e6, cohesion_Pa=20e6,
                        moment_factor=beta, friction_angle_deg=phi_b)
        r = compression_test(agg, bp, material=Material(youngs_modulus_Pa=30e9, poisson_ratio=0.25,
                                                        density_kg_m3=2700.0),
                             platen_speed_m_s=0.1, local_damping=0.7, time_step_factor=0.5)
        rows.append({"code": label, "n_spheres": N, "n_bonds": agg.n_bonds,
                     "peak_force_N": r.peak_force_N, "fracture_energy_J": r.fracture_energy_J,
                     "dt_s": r.dt_s, "steps": r.n_steps, "wall_s": r.wall_time_s,
                     "particle_steps_per_s": N * r.n_steps / r.wall_time_s})
        print(rows[-1], flush=True)
    if yade is None:
        print("yade not found; only the grindtwin row is written")
    else:
        out = os.path.join(OUT, f"dem_yade_curve_{N}.csv")
        script = os.path.join(os.path.dirname(__file__), "dem_yade_compression.py")
        t0 = time.perf_counter()
        subprocess.run([yade, "-n", "-j", "1", "-x", script, pack, out], check=True,
                       env=dict(os.environ, OMP_NUM_THREADS="1"))
        total = time.perf_counter() - t0
        head = open(out).readline().split()
        info = {head[k]: float(head[k + 1]) for k in range(1, len(head) - 1, 2)}
        c = pd.read_csv(out, comment="#")
        kp = int(np.argmax(c["force_top_N"]))
        e = float(np.trapezoid(np.r_[0, c["force_top_N"][:kp + 1]], np.r_[0, c["displacement_m"][:kp + 1]]))
        rows.append({"code": "Yade JCFpm", "n_spheres": N, "n_bonds": int(info["n_bonds"]),
                     "peak_force_N": float(c["force_top_N"].max()), "fracture_energy_J": e,
                     "dt_s": info["dt_s"], "steps": int(info["steps"]), "wall_s": info["wall_s"],
                     "particle_steps_per_s": N * info["steps"] / info["wall_s"]})
        print(rows[-1], f"(yade process {total:.1f} s)", flush=True)
    df = pd.DataFrame(rows)
    if yade is not None:
        df["speed_ratio_vs_yade"] = df["particle_steps_per_s"] / rows[-1]["particle_steps_per_s"]
        df["peak_ratio_vs_yade"] = df["peak_force_N"] / rows[-1]["peak_force_N"]
        df["energy_ratio_vs_yade"] = df["fracture_energy_J"] / rows[-1]["fracture_energy_J"]
    write_table(df, f"dem_yade_{N}", "grindtwin DEM vs Yade: the issue's compression test",
                "Same packing for both; single thread; see the module docstring of "
                "benchmarks/dem_yade.py for the model differences.")


if __name__ == "__main__":
    main()
