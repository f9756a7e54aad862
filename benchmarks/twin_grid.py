"""What the size grid costs and buys: P80 error against a fine reference, and time, per grid and
per discretisation (twin.breakage: the second-order cell average, the default, and Austin's
classical first-order form).

Writes benchmarks/results/twin_grid.md and .csv. Two cases with the default effects and the
shipped calibration: Type B in the laboratory mill at its nominal feed, and Type B in the
industrial mill at 30 t/h (the reference scene's plant). Grids span the same sizes (6700 um down
to 6700/4096 um) and halve the class width from one to the next; the reference has 193 classes
(cell average). The controller's grid of the reference scene (7 classes of ratio 2.5 from 6700 um)
is timed and scored too. Times: build (CasADi model) and steady state, medians of REPEAT runs with
the two schemes interleaved (A, B, A, B) on this 2-core shared machine. Observed order:
log2(e_k / e_k+1) between successive grids.

Run: python benchmarks/twin_grid.py [--quick]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from twin import SizeGrid, Twin

RESULTS = Path(__file__).parent / "results"
TOP_UM, BOTTOM_UM = 6700.0, 6700.0 / 4096.0
REPEAT = 3
CASES = {"lab B": dict(ores="B", mill="lab", feed_tph=None),
         "industrial B, 30 t/h": dict(ores=["B", "D"], mill="industrial", feed_tph=30.0)}
SCHEMES = ("cell_average", "austin")


def steady(case: dict, grid: SizeGrid):
    """(build seconds, steady seconds, P80 um, load: hold-up over nominal) of the case on the grid."""
    t0 = time.perf_counter()
    tw = Twin(case["ores"], mill=case["mill"], grid=grid)
    t1 = time.perf_counter()
    kw = {} if case["feed_tph"] is None else {"feed_tph": case["feed_tph"], "blend": [1.0, 0.0]}
    ss = tw.steady(**kw)
    return t1 - t0, time.perf_counter() - t1, ss.p80_um, ss.outputs["load_frac"]


def grids(quick: bool) -> dict:
    counts = (7, 13, 25, 49) if quick else (7, 13, 25, 49, 97)
    out = {f"{n} classes (ratio {SizeGrid.spanning(TOP_UM, BOTTOM_UM, n).ratio:.3f})":
           (lambda s, n=n: SizeGrid.spanning(TOP_UM, BOTTOM_UM, n, s)) for n in counts}
    out["controller grid: 7 classes of ratio 2.5"] = lambda s: SizeGrid(TOP_UM, 2.5, 7, s)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="coarser reference (97 classes), fewer grids")
    args = ap.parse_args(argv)
    ref_count = 97 if args.quick else 193
    rows = []
    for case_name, case in CASES.items():
        ref, ref_load = steady(case, SizeGrid.spanning(TOP_UM, BOTTOM_UM, ref_count))[2:]
        for grid_name, make in grids(args.quick).items():
            samples = {s: [] for s in SCHEMES}
            for _ in range(REPEAT):
                for scheme in SCHEMES:  # interleaved
                    samples[scheme].append(steady(case, make(scheme)))
            for scheme in SCHEMES:
                build, solve, p80, load = (float(np.median(v)) for v in zip(*samples[scheme]))
                rows.append({"case": case_name, "grid": grid_name, "scheme": scheme, "p80_um": p80,
                             "error_pct": 100.0 * (p80 / ref - 1.0), "load": load,
                             "load_error_pct": 100.0 * (load / ref_load - 1.0), "build_s": build, "steady_s": solve})
        rows.append({"case": case_name, "grid": f"reference: {ref_count} classes", "scheme": "cell_average",
                     "p80_um": ref, "error_pct": 0.0, "load": ref_load, "load_error_pct": 0.0})
    df = pd.DataFrame(rows)
    for (case, scheme), part in df[~df["grid"].str.startswith(("controller", "reference"))].groupby(["case", "scheme"]):
        err = part["error_pct"].abs().to_numpy()
        orders = [math.log2(err[k] / err[k + 1]) if err[k + 1] > 0 else math.nan for k in range(len(err) - 1)]
        df.loc[part.index[1:], "observed_order"] = orders
    RESULTS.mkdir(exist_ok=True)
    df.to_csv(RESULTS / "twin_grid.csv", index=False)
    lines = ["# Twin: size grid against error and time", "",
             f"`python benchmarks/twin_grid.py{' --quick' if args.quick else ''}`. P80 and load (hold-up over "
             f"nominal) errors against the {ref_count}-class cell-average reference of the same case; build "
             f"and steady-state times are medians of {REPEAT}, schemes interleaved, 2-core shared machine. "
             "Default calibration (fitted on the cell-average scheme, 25 classes of ratio sqrt 2).", ""]
    for case in CASES:
        lines += [f"## {case}", "", df[df["case"] == case].drop(columns="case").to_markdown(
            index=False, floatfmt=".4g"), ""]
    (RESULTS / "twin_grid.md").write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
