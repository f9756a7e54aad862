"""grindtwin's parallel DEM against Yade, interleaved in one run: CPU per particle-step and the
second core's speed-up, peak force over several packings, and the scale table.

Physics on both sides: Yade's JCFpm model (benchmarks/dem_yade.py; grindtwin's mirror
``BondParams.yade_jcfpm``, ``contact_law="linear_yade"``, ``damping_velocity="at_force"``), the
issue's 22 mm particle, E = 30 GPa, ks/kn 0.4, tensile 10 MPa, cohesion 20 MPa, friction 30 deg,
platen 0.1 m/s, local damping 0.7. Each size: one packing (make_agglomerate, seed 0) written for
Yade, the same time step on both sides (0.5 of grindtwin's critical step).

1. speed: the loading phase, ``LOADING_STEPS[n]`` steps (benchmarks/dem_common.py), nothing
   recorded on either side (grindtwin records its platen force per step in memory, Yade
   nothing); each repeat runs grindtwin with NUMBA_NUM_THREADS=1 and 2, ``yade -j1`` and
   ``-j2``, and independent arithmetic on 1 and 2 threads (the worker's ``arith``: what the
   machine gives a second thread of register-only work in the same minutes) one after the other (A, B,
   C, D, E, F, then F, E, D, C, B, A), each in its own process; ratios pair by pair within a
   repeat, then medians. CPU = user + system time of the stepping (all threads).
2. peak force: full compression tests at 500 and 2000 spheres on packings seeds 0-2, grindtwin
   against Yade (one thread each: the physics, not the speed; grindtwin's result does not depend
   on the thread count; Yade records every 20 steps to catch its peak), same dt.
3. scale: grindtwin alone at 500-32000 spheres, 1 and 2 threads interleaved.
4. drum: the lab drum's ball charge at about 500 to 24,000 balls, 1 and 2 threads interleaved.

``python benchmarks/dem_parallel.py [--fast] [--parts speed,peak,scale,drum] [--sizes 500,2000] [--repeats 3]
[--tag T]`` writes benchmarks/results/dem_parallel_speed.*, dem_parallel_peak.*, dem_parallel_scale.* and
dem_parallel_drum.* (md + csv; with ``--tag T`` dem_parallel_speedT.* and so on, beside them) and
dem_parallel_speed_repeats.csv (every repeat's times, to pool runs)
for the parts asked (default all; ``--sizes`` limits every part to those sphere counts). The
speed and peak parts need ``yade`` on PATH (Debian package ``yade``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import LOADING_STEPS, OUT, TAG, cpu_model, load_average, write_pack, write_table

HERE = os.path.dirname(os.path.abspath(__file__))
WORKER = os.path.join(HERE, "dem_parallel_worker.py")
YADE_SCRIPT = os.path.join(HERE, "dem_yade_compression.py")
STEPS_FAST = {500: 500, 2000: 150}
PEAK_SEEDS = (0, 1, 2)
SCALE = {500: 2000, 1000: 1000, 2000: 600, 4000: 300, 8000: 150, 32000: 50}
SCALE_FAST = {500: 300, 2000: 80}
#: drum cases: (ball diameter m, slice length m, timed steps)
DRUM = ((0.025, 0.1, 3000), (0.025, 0.3, 2000), (0.0125, 0.2, 500), (0.01, 0.3, 200))
DRUM_FAST = ((0.025, 0.1, 1000),)
PARTS = ("speed", "peak", "scale", "drum")
#: iterations of each chain of the worker's ``arith`` (about a second on one thread)
ARITH_ITERS = 5_000_000


def options(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fast", action="store_true", help="fewer steps and sizes (a smoke run)")
    ap.add_argument("--parts", default=",".join(PARTS))
    ap.add_argument("--sizes", default="", help="sphere counts to keep in every part, e.g. 500,2000")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tag", type=TAG, default="",
                    help="suffix of the result files (dem_parallel_speed{TAG}.md, ...), beside the committed ones")
    o = ap.parse_args(argv)
    o.parts = o.parts.split(",")
    unknown = sorted(set(o.parts) - set(PARTS))
    if unknown:
        ap.error(f"--parts {','.join(unknown)}: not a part; choose from {','.join(PARTS)}. Nothing written.")
    if o.repeats < 1:
        ap.error(f"--repeats {o.repeats}: must be at least 1. Nothing written.")
    o.steps = dict(STEPS_FAST if o.fast else LOADING_STEPS)
    o.scale = dict(SCALE_FAST if o.fast else SCALE)
    o.peak_sizes = (500,) if o.fast else (500, 2000)
    o.drum = DRUM_FAST if o.fast else DRUM
    if o.sizes:
        keep = {int(x) for x in o.sizes.split(",")}
        offered = {"speed": sorted(o.steps), "peak": list(o.peak_sizes), "scale": sorted(o.scale)}
        empty = [p for p in o.parts if p in offered and not keep & set(offered[p])]
        if empty:
            ap.error(f"--sizes {o.sizes}: no size of " + "; ".join(
                f"part {p} ({','.join(map(str, offered[p]))})" for p in empty) + ". Nothing written.")
        o.steps = {n: v for n, v in o.steps.items() if n in keep}
        o.scale = {n: v for n, v in o.scale.items() if n in keep}
        o.peak_sizes = tuple(n for n in o.peak_sizes if n in keep)
    return o


def _worker(args, threads):
    """The JSON line of one worker process on ``threads`` numba threads (BLAS on one thread in
    every part: OpenBLAS's threads spin for a while after each call of the set-up)."""
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, WORKER, *args], env=env, check=True, capture_output=True,
                         text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def grindtwin(pack, dt, steps, threads):
    return _worker([pack, repr(dt), str(steps)], threads)


def arith(threads):
    """The worker's independent arithmetic on ``threads`` threads (wall and CPU time)."""
    return _worker(["arith", str(ARITH_ITERS)], threads)


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


def speed(folder, o):
    """Each repeat runs the four sides in fresh processes, in the order gt1, gt2, yade1, yade2 and
    reversed on the next repeat; the ratios are taken pair by pair within a repeat (both sides
    seconds apart), then their median and range over the repeats. Returns (the table, one row per
    repeat and side: its times, so runs can be pooled later)."""
    rows, raw = [], []
    for n, steps in o.steps.items():
        agg, pack, dt = write_pack(n, 0, folder)
        grindtwin(pack, dt, 10, 1)            # compile once into the cache
        sides = {"gt1": lambda: grindtwin(pack, dt, steps, 1), "gt2": lambda: grindtwin(pack, dt, steps, 2),
                 "yade1": lambda: yade(pack, dt, steps, 1, folder), "yade2": lambda: yade(pack, dt, steps, 2, folder),
                 "arith1": lambda: arith(1), "arith2": lambda: arith(2)}
        runs = {k: [] for k in sides}
        for rep in range(o.repeats):
            for k in (list(sides) if rep % 2 == 0 else list(sides)[::-1]):
                runs[k].append(sides[k]())
            print(n, rep, {k: (round(v[-1]["wall_s"], 3), round(v[-1]["cpu_s"], 3)) for k, v in runs.items()},
                  "load", load_average(), flush=True)
        ps = n * steps
        raw += [{"n_spheres": n, "steps": r["steps"], "repeat": i, "side": k, "wall_s": r["wall_s"],
                 "cpu_s": r["cpu_s"]} for k, v in runs.items() for i, r in enumerate(v)]
        cpu = {k: np.array([r["cpu_s"] for r in v]) for k, v in runs.items()}
        wall = {k: np.array([r["wall_s"] for r in v]) for k, v in runs.items()}
        per_core = cpu["yade1"] / cpu["gt1"]
        second = wall["gt1"] / wall["gt2"]
        rows.append({"n_spheres": n, "n_bonds": agg.n_bonds, "steps": steps, "repeats": o.repeats, "dt_s": dt,
                     **{f"{k}_cpu_us": float(np.median(cpu[k])) / ps * 1e6 for k in ("gt1", "gt2", "yade1", "yade2")},
                     **{f"{k}_wall_us": float(np.median(wall[k])) / ps * 1e6 for k in ("gt1", "gt2", "yade1", "yade2")},
                     "per_core_x_yade": float(np.median(per_core)),
                     "per_core_range": f"{per_core.min():.2f}-{per_core.max():.2f}",
                     "gt_2nd_core_speedup": float(np.median(second)),
                     "gt_2nd_core_range": f"{second.min():.2f}-{second.max():.2f}",
                     "yade_2nd_core_speedup": float(np.median(wall["yade1"] / wall["yade2"])),
                     "arith_2nd_core_speedup": float(np.median(wall["arith1"] / wall["arith2"])),
                     "gt_threading_layer": runs["gt2"][0]["threading_layer"], "load_after": load_average()})
    return pd.DataFrame(rows), pd.DataFrame(raw)


def peaks(folder, o):
    rows = []
    for n in o.peak_sizes:
        for seed in PEAK_SEEDS:
            agg, pack, dt = write_pack(n, seed, folder)
            g = _worker([pack, repr(dt), "full"], 1)
            y = yade(pack, dt, "full", 1, folder)
            rows.append({"n_spheres": n, "seed": seed, "dt_s": dt, "gt_peak_N": g["peak_force_N"],
                         "yade_peak_N": y["peak_force_N"], "peak_ratio": g["peak_force_N"] / y["peak_force_N"],
                         "gt_energy_J": g["fracture_energy_J"], "yade_energy_J": y["fracture_energy_J"],
                         "energy_ratio": g["fracture_energy_J"] / y["fracture_energy_J"]})
            print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def _speedup(w1, w2) -> dict:
    """The second thread's speed-up: median and range of the within-repeat ratios of wall times."""
    r = np.asarray(w1) / np.asarray(w2)
    return {"speedup_2t": float(np.median(r)), "speedup_2t_range": f"{r.min():.2f}-{r.max():.2f}"}


def scale(folder, o):
    rows = []
    for n, steps in o.scale.items():
        agg, pack, dt = write_pack(n, 0, folder)
        grindtwin(pack, dt, 10, 1)
        t1, t2 = [], []
        for rep in range(o.repeats):
            t1.append(grindtwin(pack, dt, steps, 1))
            t2.append(grindtwin(pack, dt, steps, 2))
        w1 = np.array([r["wall_s"] for r in t1])
        w2 = np.array([r["wall_s"] for r in t2])
        rows.append({"n_spheres": n, "n_bonds": agg.n_bonds, "steps": steps,
                     "particle_steps_per_s_1t": n * steps / float(np.median(w1)),
                     "particle_steps_per_s_2t": n * steps / float(np.median(w2)),
                     "cpu_us_per_particle_step_1t": float(np.median([r["cpu_s"] for r in t1])) / (n * steps) * 1e6,
                     **_speedup(w1, w2), "load_after": load_average()})
        print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def drum_scale(o):
    """The drum's ball charge on 1 and 2 threads, interleaved: ball counts set by the ball size
    and the slice length of the 0.5 m x 0.3 m lab drum."""
    rows = []
    for ball_d, section, steps in o.drum:
        args = ["drum", repr(ball_d), repr(section), str(steps)]
        runs = {1: [], 2: []}
        for rep in range(o.repeats):
            for t in (1, 2):
                runs[t].append(_worker(args, t))
        n = runs[1][0]["n_spheres"]
        w = {t: np.array([r["wall_s"] for r in v]) for t, v in runs.items()}
        rows.append({"n_balls": n, "ball_d_m": ball_d, "section_m": section, "n_pairs": runs[1][0]["n_pairs"],
                     "steps": steps, "particle_steps_per_s_1t": n * steps / float(np.median(w[1])),
                     "particle_steps_per_s_2t": n * steps / float(np.median(w[2])),
                     "cpu_us_per_particle_step_1t": float(np.median([r["cpu_s"] for r in runs[1]])) / (n * steps) * 1e6,
                     **_speedup(w[1], w[2]), "threading_layer": runs[2][0]["threading_layer"],
                     "load_after": load_average()})
        print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def main(argv=None):
    o = options(argv)
    note = (f"Command: `python benchmarks/dem_parallel.py {' '.join(sys.argv[1:])}`. Machine: {cpu_model()}, "
            f"shared with other jobs; load average (1/5/15 min) at the start {load_average()}, "
            "after each size in the table. Times are medians of interleaved repeats; ratios are medians "
            "of the ratios taken within each repeat (ranges: over the repeats).")
    if {"speed", "peak"} & set(o.parts) and shutil.which("yade") is None:
        raise SystemExit("yade not on PATH (Debian package 'yade'), needed by the speed and peak parts; "
                         "nothing written")
    with tempfile.TemporaryDirectory() as folder:
        if "speed" in o.parts:
            table, raw = speed(folder, o)
            write_table(table, f"dem_parallel_speed{o.tag}",
                        "grindtwin (1 and 2 threads) against Yade -j1/-j2, Yade-JCFpm physics",
                        note + " us = microseconds of CPU (user + system, all threads) or wall time per "
                        "particle-step; gt1/gt2 = grindtwin on 1/2 threads, yade1/yade2 = yade -j1/-j2; "
                        "per_core_x_yade = Yade -j1 CPU / grindtwin 1-thread CPU; second core: 1-thread "
                        "wall / 2-thread wall; arith = independent arithmetic in one parallel loop, what "
                        "the machine gives a second thread of register-only work in the same minutes (no "
                        "memory traffic: memory-bound work may gain more or less; in the repeats "
                        "file, steps = iterations of each of its chains). Every repeat's times: dem_parallel_speed"
                        f"{o.tag}_repeats.csv.")
            raw.to_csv(os.path.join(OUT, f"dem_parallel_speed{o.tag}_repeats.csv"), index=False)
        if "peak" in o.parts:
            pk = peaks(folder, o)
            write_table(pk, f"dem_parallel_peak{o.tag}",
                        "Peak force: grindtwin against Yade, same packings and time step",
                        note + f" Peak ratio over the packings: mean {pk.peak_ratio.mean():.4f}, "
                        f"range {pk.peak_ratio.min():.4f}-{pk.peak_ratio.max():.4f}.")
        if "drum" in o.parts:
            write_table(drum_scale(o), f"dem_parallel_drum{o.tag}",
                        "grindtwin drum (ball charge) scale table (1 and 2 threads)", note)
        if "scale" in o.parts:
            write_table(scale(folder, o), f"dem_parallel_scale{o.tag}",
                        "grindtwin compression-test scale table (1 and 2 threads)", note)


if __name__ == "__main__":
    main()
