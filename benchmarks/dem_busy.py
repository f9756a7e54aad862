"""The DEM's second thread on a busy machine: OpenMP's wait policy against other jobs on the cores.

numba's OpenMP threads spin at a barrier before they sleep (GNU libgomp: ``GOMP_SPINCOUNT``
iterations, ``OMP_WAIT_POLICY``). On an idle machine spinning makes the three barriers of a
step cheap; when other jobs hold the cores, a spinning thread takes the time slice that the
thread it waits for needs, and two threads can run many times slower than one. This measures it:
the 2,000-sphere Yade-JCFpm loading (benchmarks/dem_parallel_worker.py) on 1 and 2 threads
under each wait setting, with 0, 1 and 2 busy processes (a pure-Python loop each) started by
this script beside it; per setting and load, wall time of 2 threads over 1 thread (below 1: the
second thread pays), medians of interleaved repeats (1 thread, 2 threads, next setting, ...).

    python benchmarks/dem_busy.py [--repeats 5] [--steps 300]

writes benchmarks/results/dem_busy.md and .csv.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import COUNT, load_average, write_pack, write_table

HERE = os.path.dirname(os.path.abspath(__file__))
WORKER = os.path.join(HERE, "dem_parallel_worker.py")
#: wait settings compared: libgomp's defaults, a short spin then sleep, sleep at once
SETTINGS = {"default": {}, "spin_10k": {"GOMP_SPINCOUNT": "10000"}, "passive": {"OMP_WAIT_POLICY": "PASSIVE"}}
BUSY = (0, 1, 2)
N_SPHERES = 2000


def run(pack: str, dt: float, steps: int, threads: int, extra: dict) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")}
    env.update(extra, NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, WORKER, pack, repr(dt), str(steps)], env=env, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=COUNT, default=5)
    ap.add_argument("--steps", type=COUNT, default=300, help="timed steps per run")
    o = ap.parse_args(argv)
    repeats, steps = o.repeats, o.steps
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        _, pack, dt = write_pack(N_SPHERES, 0, folder)
        run(pack, dt, 10, 2, {})                          # kernels into numba's cache
        for busy in BUSY:
            hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(busy)]
            try:
                walls = {(s, t): [] for s in SETTINGS for t in (1, 2)}
                for _ in range(repeats):
                    for s, extra in SETTINGS.items():
                        for t in (1, 2):
                            walls[s, t].append(run(pack, dt, steps, t, extra)["wall_s"])
            finally:
                for h in hogs:
                    h.kill()
                    h.wait()
            for s in SETTINGS:
                w1, w2 = float(np.median(walls[s, 1])), float(np.median(walls[s, 2]))
                rows.append({"busy_processes": busy, "setting": s, "steps": steps, "repeats": repeats,
                             "wall_1t_s": w1, "wall_2t_s": w2, "speedup_2t": w1 / w2,
                             "us_per_particle_step_2t": w2 / (N_SPHERES * steps) * 1e6,
                             "load_after": load_average()})
                print(rows[-1], flush=True)
    write_table(pd.DataFrame(rows), "dem_busy", "The DEM's second thread with other jobs on the cores",
                f"Command: `python benchmarks/dem_busy.py {' '.join(sys.argv[1:])}`. {N_SPHERES} spheres, "
                "Yade-JCFpm loading, 2 cores; busy_processes = pure-Python loops this script runs beside "
                "(other jobs on the machine add to them: see load_after). Settings: " + ", ".join(
                    f"{k} {v or '(libgomp defaults)'}" for k, v in SETTINGS.items())
                + ". speedup_2t = wall time on 1 thread / on 2 threads, medians of interleaved repeats.")


if __name__ == "__main__":
    main()
