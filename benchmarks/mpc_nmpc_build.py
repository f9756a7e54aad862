"""What building the NMPC costs in memory and time, against the size of its model.

IPOPT, SQP and fatrop: the whole horizon's shooting constraints are expanded to scalar
expressions and differentiated twice (an exact Hessian), so the build's memory grows with
(operations of the model's right-hand side) x (states) x (RK4 steps per sample) x (horizon
stages), the "units" below; bytes per unit = the build's peak RSS above the RSS before it, over
its units. RTI: one stage's Gauss-Newton QP data is built (and compiled, mpc.codegen) and
mapped over the horizon, so its memory is a part for the stage, per (operations x states x RK4
steps), plus a part per stage for the QP's matrices, per (states^2 x stages): both from pairs
of builds of one model at two horizons. Each build runs in a subprocess of its own (peak RSS by
getrusage, the address space capped so that a build too large fails instead of exhausting the
machine). The largest ratios, with a margin, are the constants of
``scenarios.run.preflight`` that refuse a controller model too large to build before it is built.

Writes benchmarks/results/mpc_nmpc_build.md and .csv.

Run: python benchmarks/mpc_nmpc_build.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pandas as pd

RESULTS = Path(__file__).parent / "results"
#: Address-space cap of each build's process [GB].
CAP_GB = 12.0
#: (size classes, mixers, horizon, RK4 steps, solver): the scene's controller models and a few
#: around them (2 ores, the effects of hard_to_soft.toml).
CONFIGS = [(7, 3, 10, 2, "rti"), (7, 3, 20, 2, "rti"), (25, 3, 10, 2, "rti"), (25, 3, 30, 2, "rti"),
           (7, 3, 5, 2, "ipopt"), (7, 2, 10, 2, "ipopt"), (7, 2, 5, 2, "sqpmethod"), (7, 2, 5, 2, "fatrop")]
QUICK = [(7, 2, 5, 2, "rti"), (7, 2, 10, 2, "rti"), (7, 2, 5, 2, "ipopt")]

BUILD = r"""
import json, resource, sys, time
cap = int(float(sys.argv[6]) * 2**30)
resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
from mpc import Controller, NmpcSettings
from twin import SizeGrid, Twin
count, mixers, horizon, substeps, solver = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
effects = ["breakage", "transport", "holdup", "speed", "cushioning", "power", "sensor_delay"]
twin = Twin(["A", "D"], mill="industrial", effects=effects, grid=SizeGrid(6700.0, 2.5 ** (6 / (count - 1)), count),
            n_mixers=mixers)
m = twin.model
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
t0 = time.perf_counter()
ok = "built"
try:
    Controller(m, NmpcSettings(horizon_steps=horizon, dt_h=0.05, move_block=1, rk4_substeps=substeps, solver=solver,
                               target_p80_um=210.0, feed_tph_min=15.0, feed_tph_max=50.0))
except Exception as exc:
    ok = f"{type(exc).__name__}: {str(exc)[-120:]}"
build_s = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
units = m.n_instructions * m.n_x * substeps * horizon
print(json.dumps({"classes": count, "mixers": mixers, "horizon": horizon, "rk4_substeps": substeps,
                  "solver": solver, "states": m.n_x, "operations": m.n_instructions, "units": units,
                  "result": ok, "build_s": round(build_s, 1), "build_mb": round((peak - before) / 2**20),
                  "bytes_per_unit": round((peak - before) / units)}))
"""


def measure(configs) -> pd.DataFrame:
    rows = []
    for cfg in configs:
        proc = subprocess.run([sys.executable, "-c", BUILD, *map(str, cfg), str(CAP_GB)], capture_output=True,
                              text=True, timeout=3600)
        if proc.returncode != 0:
            raise RuntimeError(f"build {cfg} failed: {proc.stderr[-2000:]}")
        rows.append(json.loads(proc.stdout.strip().splitlines()[-1]))
        print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def rti_parts(table: pd.DataFrame) -> pd.DataFrame:
    """RTI's two parts from each model built at two horizons: the slope per stage over states^2,
    and the intercept (the stage's part) over operations x states x RK4 steps."""
    rows = []
    rti = table[(table["solver"] == "rti") & (table["result"] == "built")]
    for key, g in rti.groupby(["classes", "mixers", "rk4_substeps"]):
        if len(g) < 2:
            continue
        a, b = g.sort_values("horizon").iloc[[0, -1]].to_dict("records")
        per_stage = (b["build_mb"] - a["build_mb"]) * 2**20 / (b["horizon"] - a["horizon"])
        stage_part = a["build_mb"] * 2**20 - per_stage * a["horizon"]
        rows.append({"classes": key[0], "mixers": key[1], "rk4_substeps": key[2], "states": a["states"],
                     "bytes_per_state2_stage": round(per_stage / a["states"] ** 2),
                     "stage_bytes_per_unit": round(stage_part / (a["operations"] * a["states"] * key[2]))})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="two small builds only")
    args = ap.parse_args(argv)
    table = measure(QUICK if args.quick else CONFIGS)
    name = "mpc_nmpc_build_quick" if args.quick else "mpc_nmpc_build"
    RESULTS.mkdir(exist_ok=True)
    table.to_csv(RESULTS / f"{name}.csv", index=False)
    nlp = table[(table["result"] == "built") & (table["solver"] != "rti")]
    worst = nlp.groupby("solver")["bytes_per_unit"].max()
    parts = rti_parts(table)
    lines = ["# NMPC build: memory and time against the model's size", "",
             "Units = operations of the model's right-hand side x states x RK4 steps x horizon; bytes per "
             "unit = the build's peak RSS above the RSS before it, over its units. Machine: 2 cores shared "
             "with other jobs (times are upper bounds; RTI's include compiling its QP data). Command: "
             "`python benchmarks/mpc_nmpc_build.py`.", "",
             table.to_markdown(index=False), "", "Largest bytes per unit of the exact-Hessian solvers: "
             + ", ".join(f"{s} {v}" for s, v in worst.items()) + ".", "",
             "RTI, from each model at two horizons (the QP's matrices per stage, and the stage's part):", "",
             parts.to_markdown(index=False) if len(parts) else "(no pair)"]
    (RESULTS / f"{name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
