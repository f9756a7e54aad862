"""The measured stability bound of the DEM time step, against the critical step System computes.

System's critical step (``System.critical_dt_s``) is the smaller of the contact step and the
bond-spring step ``sqrt(m / sum k)`` per sphere (dem.system); velocity Verlet on one harmonic
spring is stable up to 2/omega, and a sphere coupled to many bonds lowers that, so the true
bound lies somewhere between. This benchmark finds it: the Yade-JCFpm compression test's
loading phase (benchmarks/dem_parallel_worker.py, platen 0.1 m/s) run to the same simulated
time at time steps ``factor x critical`` (set past System's allowed range, which stops at 1, by
assigning ``dt_s`` after construction), on several packings. A run is *stable* when it
raises no instability, breaks no bond that the reference (factor 0.25) does not, and its
platen force at the end is within ``STABLE_TOL`` of the reference's. The accuracy cost of the
allowed factors on whole compression tests is in benchmarks/results/dem_accuracy.md.

``python benchmarks/dem_time_step.py [--sizes 500,2000] [--seeds 0,1,2]`` writes
benchmarks/results/dem_time_step.md and .csv.
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np
import pandas as pd

from dem_common import write_table
from dem_parallel_worker import loading_system
from dem.agglomerate import make_agglomerate
from dem.errors import DemInstabilityError

#: simulated loading time (s): 30 um of platen travel, elastic for the intact particle
T_END_S = 3e-4
#: relative difference of the final platen force from the reference's that still counts as stable
STABLE_TOL = 0.01
REFERENCE_FACTOR = 0.25
FACTORS = (0.5, 1.0, 1.25, 1.5, 1.75, 2.0, 2.5)


def _arg(name, default):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def loading(agg, factor: float) -> dict:
    s = loading_system(agg, 1e-12)          # any valid step; the factor's is set next
    s.dt_s = factor * s.critical_dt_s
    steps = int(round(T_END_S / s.dt_s))
    try:
        s.run(steps)
    except DemInstabilityError:
        return {"steps": steps, "unstable": True, "force_end_N": np.nan, "broken": -1,
                "critical_dt_s": s.critical_dt_s}
    return {"steps": steps, "unstable": False,
            "force_end_N": float(s.record_arrays()["wall_force_N"][-1, 1]),
            "broken": int(np.sum(s.bonds.state != 0)), "critical_dt_s": s.critical_dt_s}


def scan(n: int, seed: int) -> list[dict]:
    agg = make_agglomerate(0.022, n, random_state=seed)
    ref = loading(agg, REFERENCE_FACTOR)
    rows = []
    for f in FACTORS:
        r = loading(agg, f)
        err = r["force_end_N"] / ref["force_end_N"] - 1.0
        stable = (not r["unstable"]) and r["broken"] <= ref["broken"] and abs(err) <= STABLE_TOL
        rows.append({"n_spheres": n, "seed": seed, "factor": f, "dt_s": f * r["critical_dt_s"],
                     "steps": r["steps"], "force_err_pct": 100 * err, "broken": r["broken"],
                     "broken_reference": ref["broken"], "stable": stable})
        print(rows[-1], flush=True)
    return rows


def main():
    sizes = [int(x) for x in _arg("--sizes", "500,2000").split(",")]
    seeds = [int(x) for x in _arg("--seeds", "0,1,2").split(",")]
    t = pd.DataFrame([r for n in sizes for s in seeds for r in scan(n, s)])
    bound = {n: float(g.groupby("factor").stable.all().loc[lambda x: x].index.max())
             for n, g in t.groupby("n_spheres")}
    first_bad = {n: g.loc[~g.stable, "factor"].min() for n, g in t.groupby("n_spheres")}
    note = (f"Command: `python benchmarks/dem_time_step.py {' '.join(sys.argv[1:])}`. Loading phase of the "
            f"Yade-JCFpm compression test to t = {T_END_S:g} s at factor x System.critical_dt_s; reference "
            f"factor {REFERENCE_FACTOR}; stable = no instability, no bond broken that the reference keeps, final "
            f"platen force within {100 * STABLE_TOL:g} % of the reference's. Largest factor stable on every "
            f"packing: " + ", ".join(f"{n} spheres {bound[n]:g} (first unstable {first_bad[n]:g})" for n in bound)
            + ". System allows factors up to 1 (default 0.5).")
    write_table(t, "dem_time_step", "Measured stability bound of the DEM time step", note)


if __name__ == "__main__":
    main()
