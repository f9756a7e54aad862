"""The compiled RTI step on the condensed QP (mpc/c/gt_cond.c + gt_qp.c) built with several sets
of C compiler flags, stepped interleaved (A, B, C, A, B, C...) at the same points, on the
reference scene's controller model (45 states).

Points: the controller's start at the scene's steady state with every variable perturbed by 2 %
(one seed per point), so each QP has gaps to close and active constraints. Per flag set: the QP
data's wall time (timed inside the C call), the step's thread CPU time (QP data + QP + ctypes),
the build time of the library (generation + compilation, empty cache folder), and the largest
relative difference of the step against the first flag set's (the same arithmetic up to
rounding). The load average is read at every point.

Writes benchmarks/results/mpc_condense_flags{tag}.csv and .md.

    PYTHONPATH=. python benchmarks/mpc_condense_flags.py [--horizon 40] [--points 60]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from mpc_compiled import settings  # noqa: E402
from mpc_reference_case import reference_sensors, reference_setup, schedule  # noqa: E402

from mpc import Controller  # noqa: E402
from mpc.codegen import CACHE_ENV, c_library  # noqa: E402
from mpc.condense import RTI_C_SOURCES, RtiLibrary, stage_functions  # noqa: E402
from dem_common import TAG  # noqa: E402

OUT = Path(__file__).parent / "results"


def interleaved_steps(libs: dict, ctrl, css, horizon: int, points: int) -> pd.DataFrame:
    """Every library's step at each perturbed point in turn; one row per point and library."""
    D = np.array([np.r_[schedule(0.0), 1.0] for _ in range(horizon)]).T
    p = np.concatenate([css.x, D.ravel(order="F"), css.u, ctrl._wpass])
    w0 = ctrl._initial_guess(css.x / ctrl.x_scale, css.u)[0]
    rows = []
    for seed in range(points):
        w = w0 * (1 + 0.02 * np.random.default_rng(seed).standard_normal(w0.size))
        ref = None
        for fl, lib in libs.items():
            cpu0 = time.thread_time()
            w_next, st, it = lib.step(w, p)
            cpu = time.thread_time() - cpu0
            data_s, qp_s = lib.last_seconds()
            ref = w_next - w if ref is None else ref
            rows.append({"flags": fl, "point": seed, "status": st, "qp_iterations": it, "data_s": data_s,
                         "qp_s": qp_s, "step_cpu_s": cpu, "load_1min": os.getloadavg()[0],
                         "step_rel_diff": np.max(np.abs(w_next - w - ref)) / np.max(np.abs(ref))})
    return pd.DataFrame(rows)


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--horizon", type=int, default=40)
    ap.add_argument("--points", type=int, default=60)
    ap.add_argument("--flags", default="-O2;-O3;-O3 -march=native", help="flag sets separated by ';'")
    ap.add_argument("--tag", default="", type=TAG)
    args = ap.parse_args(argv)
    _, _, ctw, css = reference_setup(reference_sensors())
    ctrl = Controller(ctw.model, settings(args.horizon, "off", "condensed"))
    fns = stage_functions(ctrl)
    libs, builds = {}, {}
    folder = tempfile.mkdtemp(prefix="grindtwin-flags-")
    os.environ[CACHE_ENV] = folder
    try:
        for fl in args.flags.split(";"):
            t0 = time.perf_counter()
            path, _ = c_library("gt_rti", fns, list(RTI_C_SOURCES), "on", tuple(fl.split()))
            builds[fl] = time.perf_counter() - t0
            libs[fl] = RtiLibrary(path)
        fr = interleaved_steps(libs, ctrl, css, args.horizon, args.points)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    table = fr.groupby("flags", sort=False).agg(
        data_median_s=("data_s", "median"), data_p95_s=("data_s", lambda v: v.quantile(0.95)),
        qp_median_s=("qp_s", "median"), step_cpu_median_s=("step_cpu_s", "median"),
        step_cpu_p95_s=("step_cpu_s", lambda v: v.quantile(0.95)), qp_iterations_median=("qp_iterations", "median"),
        failed=("status", lambda v: int((~v.isin(RtiLibrary.SOLVED)).sum())),
        step_rel_diff_max=("step_rel_diff", "max"), load_1min_median=("load_1min", "median")).reset_index()
    table.insert(1, "build_cold_s", table["flags"].map(builds))
    base = fr[fr["flags"] == table["flags"].iloc[0]].step_cpu_s.to_numpy()
    table["cpu_first_over_this"] = [float(np.median(base / fr[fr["flags"] == f].step_cpu_s.to_numpy())) for f in table["flags"]]
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / f"mpc_condense_flags{args.tag}.csv", index=False)
    load = os.getloadavg()
    md = [f"# The compiled condensed RTI step by C compiler flags (reference scene's controller model, horizon {args.horizon})", "",
          f"{args.points} points (the steady-state start perturbed by 2 %, one seed each), the flag sets stepped interleaved at "
          "each point; medians over the points. `data`: the QP data (condensing loop, mpc/c/gt_cond.c), wall time inside the "
          "C call; `step_cpu`: the thread's CPU time of the whole step (data + QP + expansion); `cpu_first_over_this`: "
          "median per-point ratio of the first flag set's step CPU time to this one's; `step_rel_diff_max`: largest "
          "difference of the step against the first flag set's, relative to its largest entry; `build_cold_s`: generation "
          f"+ compilation in an empty cache folder. Load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} "
          "(1/5/15 min) on 2 cores shared with other jobs.", "",
          table.to_markdown(index=False, floatfmt=".4g"), "",
          f"Reproduce: `PYTHONPATH=. python benchmarks/mpc_condense_flags.py --horizon {args.horizon} --points {args.points}"
          + (f" --tag {args.tag}`." if args.tag else "`.")]
    (OUT / f"mpc_condense_flags{args.tag}.md").write_text("\n".join(md) + "\n")
    print(table.to_string())
    return table


if __name__ == "__main__":
    main()
