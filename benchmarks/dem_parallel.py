"""grindtwin's parallel DEM against Yade, interleaved in one run: CPU per particle-step and the
second core's speed-up, peak force over several packings, and the scale table.

Physics on both sides: Yade's JCFpm model (benchmarks/dem_yade.py; grindtwin's mirror
``BondParams.yade_jcfpm``, ``contact_law="linear_yade"``, ``damping_velocity="at_force"``), the
issue's 22 mm particle, E = 30 GPa, ks/kn 0.4, tensile 10 MPa, cohesion 20 MPa, friction 30 deg,
platen 0.1 m/s, local damping 0.7. Each size: one packing (make_agglomerate, seed 0) written for
Yade, the same time step on both sides (0.5 of grindtwin's critical step).

1. speed: the loading phase, ``STEPS[n]`` steps, nothing recorded on either side (grindtwin
   records its platen force per step in memory, Yade nothing); each repeat runs grindtwin with
   NUMBA_NUM_THREADS=1 and 2 and ``yade -j1`` and ``-j2`` one after the other (A, B, C, D, A, ...),
   each in its own process; medians. CPU = user + system time of the stepping (all threads).
2. peak force: full compression tests at 500 and 2000 spheres on packings seeds 0-2, grindtwin
   against Yade (one thread each: the physics, not the speed; grindtwin's result does not depend
   on the thread count; Yade records every 20 steps to catch its peak), same dt.
3. scale: grindtwin alone at 500-32000 spheres, 1 and 2 threads interleaved.
4. drum: the lab drum's ball charge at about 500 to 24,000 balls, 1 and 2 threads interleaved.

``python benchmarks/dem_parallel.py [--fast] [--parts speed,peak,scale,drum] [--sizes 500,2000] [--repeats 3]``
writes benchmarks/results/dem_parallel_speed.*, dem_parallel_peak.*, dem_parallel_scale.* and
dem_parallel_drum.* (md + csv)
for the parts asked (default all; ``--sizes`` limits every part to those sphere counts). Needs
``yade`` on PATH (Debian package).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import write_table
from dem.agglomerate import make_agglomerate

FAST = "--fast" in sys.argv


def _arg(name, default):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


PARTS = _arg("--parts", "speed,peak,scale,drum").split(",")
SIZES = [int(x) for x in _arg("--sizes", "0").split(",")]
HERE = os.path.dirname(os.path.abspath(__file__))
WORKER = os.path.join(HERE, "dem_parallel_worker.py")
YADE_SCRIPT = os.path.join(HERE, "dem_yade_compression.py")
STEPS = {500: 1000, 2000: 600, 8000: 200} if not FAST else {500: 500, 2000: 150}
REPEATS = int(_arg("--repeats", "3"))
PEAK_SIZES = (500, 2000) if not FAST else (500,)
PEAK_SEEDS = (0, 1, 2)
SCALE = {500: 2000, 1000: 1000, 2000: 600, 4000: 300, 8000: 150, 32000: 50} if not FAST else {500: 300, 2000: 80}
#: drum cases: (ball diameter m, slice length m, timed steps)
DRUM = ((0.025, 0.1, 3000), (0.025, 0.3, 2000), (0.0125, 0.2, 500), (0.01, 0.3, 200)) if not FAST else \
    ((0.025, 0.1, 1000),)
if SIZES != [0]:
    STEPS = {n: v for n, v in STEPS.items() if n in SIZES}
    SCALE = {n: v for n, v in SCALE.items() if n in SIZES}
    PEAK_SIZES = tuple(n for n in PEAK_SIZES if n in SIZES)


def load_average() -> str:
    return " / ".join(f"{x:.1f}" for x in os.getloadavg())


def write_pack(n: int, seed: int, folder: str):
    agg = make_agglomerate(0.022, n, random_state=seed)
    path = os.path.join(folder, f"pack_{n}_{seed}.txt")
    with open(path, "w") as fh:
        fh.write(f"# x_m y_m z_m r_m solid_fraction {agg.solid_fraction}\n")
        for p, r in zip(agg.pos_m, agg.radius_m):
            fh.write(f"{p[0]:.17g} {p[1]:.17g} {p[2]:.17g} {r:.17g}\n")
    return agg, path, _dt(agg)


def _dt(agg) -> float:
    from dem_parallel_worker import BONDS, PLATEN, ROCK
    from dem.bonds import BondSet
    from dem.system import PlaneWall, System
    s = System(agg.pos_m, agg.radius_m, ROCK, density_kg_m3=2700.0 / agg.solid_fraction,
               bonds=BondSet(agg.bond_pairs, agg.pos_m, agg.radius_m, BONDS), wall_material=PLATEN,
               walls=[PlaneWall((0, 0, -1.0), (0, 0, 1))], contact_law="linear_yade",
               time_step_factor=0.5)
    return s.dt_s


def grindtwin(pack, dt, steps, threads):
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, WORKER, pack, repr(dt), str(steps)], env=env,
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def yade(pack, dt, steps, threads, folder):
    out = os.path.join(folder, "yade_out.txt")
    args = [shutil.which("yade"), "-n", "-j", str(threads), "-x", YADE_SCRIPT, pack, out, f"dt={dt!r}"]
    if steps == "full":
        args.append("every=20")
    else:
        args.append(f"steps={steps}")
    subprocess.run(args, check=True, capture_output=True, env=dict(os.environ, OMP_NUM_THREADS=str(threads)))
    if steps != "full":
        return json.loads(open(out).read())
    c = pd.read_csv(out, comment="#")
    kp = int(np.argmax(c["force_top_N"]))
    e = float(np.trapezoid(np.r_[0, c["force_top_N"][:kp + 1]], np.r_[0, c["displacement_m"][:kp + 1]]))
    return {"peak_force_N": float(c["force_top_N"].max()), "fracture_energy_J": e}


def speed(folder):
    rows = []
    for n, steps in STEPS.items():
        agg, pack, dt = write_pack(n, 0, folder)
        grindtwin(pack, dt, 10, 1)            # compile once into the cache
        runs = {k: [] for k in ("gt1", "gt2", "yade1", "yade2")}
        for rep in range(REPEATS):
            runs["gt1"].append(grindtwin(pack, dt, steps, 1))
            runs["gt2"].append(grindtwin(pack, dt, steps, 2))
            runs["yade1"].append(yade(pack, dt, steps, 1, folder))
            runs["yade2"].append(yade(pack, dt, steps, 2, folder))
            print(n, rep, {k: (round(v[-1]["wall_s"], 3), round(v[-1]["cpu_s"], 3)) for k, v in runs.items()},
                  "load", load_average(), flush=True)
        ps = n * steps
        med = {k: (float(np.median([r["cpu_s"] for r in v])) / ps * 1e6,
                   float(np.median([r["wall_s"] for r in v])) / ps * 1e6) for k, v in runs.items()}
        rows.append({"n_spheres": n, "n_bonds": agg.n_bonds, "steps": steps, "repeats": REPEATS, "dt_s": dt,
                     "gt_1t_cpu_us": med["gt1"][0], "gt_2t_cpu_us": med["gt2"][0],
                     "yade_j1_cpu_us": med["yade1"][0], "yade_j2_cpu_us": med["yade2"][0],
                     "gt_1t_wall_us": med["gt1"][1], "gt_2t_wall_us": med["gt2"][1],
                     "yade_j1_wall_us": med["yade1"][1], "yade_j2_wall_us": med["yade2"][1],
                     "per_core_x_yade": med["yade1"][0] / med["gt1"][0],
                     "gt_2nd_core_speedup": med["gt1"][1] / med["gt2"][1],
                     "yade_2nd_core_speedup": med["yade1"][1] / med["yade2"][1],
                     "load_after": load_average()})
    return pd.DataFrame(rows)


def peaks(folder):
    rows = []
    for n in PEAK_SIZES:
        for seed in PEAK_SEEDS:
            agg, pack, dt = write_pack(n, seed, folder)
            g = json.loads(subprocess.run([sys.executable, WORKER, pack, repr(dt), "full"],
                                          env=dict(os.environ, NUMBA_NUM_THREADS="1"), check=True,
                                          capture_output=True, text=True).stdout.strip().splitlines()[-1])
            y = yade(pack, dt, "full", 1, folder)
            rows.append({"n_spheres": n, "seed": seed, "dt_s": dt, "gt_peak_N": g["peak_force_N"],
                         "yade_peak_N": y["peak_force_N"], "peak_ratio": g["peak_force_N"] / y["peak_force_N"],
                         "gt_energy_J": g["fracture_energy_J"], "yade_energy_J": y["fracture_energy_J"],
                         "energy_ratio": g["fracture_energy_J"] / y["fracture_energy_J"]})
            print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def scale(folder):
    rows = []
    for n, steps in SCALE.items():
        agg, pack, dt = write_pack(n, 0, folder)
        grindtwin(pack, dt, 10, 1)
        t1, t2 = [], []
        for rep in range(REPEATS):
            t1.append(grindtwin(pack, dt, steps, 1))
            t2.append(grindtwin(pack, dt, steps, 2))
        w1 = float(np.median([r["wall_s"] for r in t1]))
        w2 = float(np.median([r["wall_s"] for r in t2]))
        rows.append({"n_spheres": n, "n_bonds": agg.n_bonds, "steps": steps,
                     "particle_steps_per_s_1t": n * steps / w1, "particle_steps_per_s_2t": n * steps / w2,
                     "cpu_us_per_particle_step_1t": float(np.median([r["cpu_s"] for r in t1])) / (n * steps) * 1e6,
                     "speedup_2t": w1 / w2, "load_after": load_average()})
        print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def drum_scale():
    """The drum's ball charge on 1 and 2 threads, interleaved: ball counts set by the ball size
    and the slice length of the 0.5 m x 0.3 m lab drum."""
    rows = []
    for ball_d, section, steps in DRUM:
        args = [sys.executable, WORKER, "drum", repr(ball_d), repr(section), str(steps)]
        runs = {1: [], 2: []}
        for rep in range(REPEATS):
            for t in (1, 2):
                out = subprocess.run(args, env=dict(os.environ, NUMBA_NUM_THREADS=str(t)), check=True,
                                     capture_output=True, text=True).stdout
                runs[t].append(json.loads(out.strip().splitlines()[-1]))
        n = runs[1][0]["n_spheres"]
        w = {t: float(np.median([r["wall_s"] for r in v])) for t, v in runs.items()}
        rows.append({"n_balls": n, "ball_d_m": ball_d, "section_m": section, "n_pairs": runs[1][0]["n_pairs"],
                     "steps": steps, "particle_steps_per_s_1t": n * steps / w[1],
                     "particle_steps_per_s_2t": n * steps / w[2],
                     "cpu_us_per_particle_step_1t": float(np.median([r["cpu_s"] for r in runs[1]])) / (n * steps) * 1e6,
                     "speedup_2t": w[1] / w[2], "threading_layer": runs[2][0]["threading_layer"],
                     "load_after": load_average()})
        print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def main():
    note = (f"Command: `python benchmarks/dem_parallel.py {' '.join(sys.argv[1:])}`. Machine: 2 cores "
            f"shared with other jobs; load average (1/5/15 min) at the start {load_average()}, "
            "after each size in the table. Times are medians of interleaved repeats.")
    with tempfile.TemporaryDirectory() as folder:
        if {"speed", "peak"} & set(PARTS) and shutil.which("yade") is None:
            raise SystemExit("yade not on PATH (Debian package 'yade'), needed by the speed and peak parts; "
                             "nothing written")
        if "speed" in PARTS:
            write_table(speed(folder), "dem_parallel_speed",
                        "grindtwin (1 and 2 threads) against Yade -j1/-j2, Yade-JCFpm physics",
                        note + " us = microseconds of CPU (user + system, all threads) or wall time per "
                        "particle-step; per_core_x_yade = Yade -j1 CPU / grindtwin 1-thread CPU.")
        if "peak" in PARTS:
            pk = peaks(folder)
            write_table(pk, "dem_parallel_peak", "Peak force: grindtwin against Yade, same packings and time step",
                        note + f" Peak ratio over the packings: mean {pk.peak_ratio.mean():.4f}, "
                        f"range {pk.peak_ratio.min():.4f}-{pk.peak_ratio.max():.4f}.")
        if "drum" in PARTS:
            write_table(drum_scale(), "dem_parallel_drum",
                        "grindtwin drum (ball charge) scale table (1 and 2 threads)", note)
        if "scale" in PARTS:
            write_table(scale(folder), "dem_parallel_scale",
                        "grindtwin compression-test scale table (1 and 2 threads)", note)


if __name__ == "__main__":
    main()
