"""What control accuracy costs in time: NMPC per-step solve time (median, 95th percentile) and
iterations against the horizon and the controller model's size classes, beside the closed-loop
IAE of P80, on a short version of the reference transition (Type B at 210 um, ramp to 60 % B /
40 % D from 0.5 h to 1.0 h, preview 0.5 h; 2.5 h at 0.05 h samples; plant 25 classes x 3
mixers; P80 noise 3 um, dead time 0.1 h).

Writes benchmarks/results/mpc_nmpc_horizon.csv and .md.

    PYTHONPATH=. python benchmarks/mpc_nmpc_horizon.py [--horizons 10,20,40,60] [--grids 10x2.0x1,...]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from mpc_reference_case import controller_model  # same directory (run as a script)
from mpc.closed_loop import Sensors, run_closed_loop
from mpc.estimator import Ekf
from mpc.nmpc import Controller, NmpcSettings
from mpc.optimize import feed_for_target
from twin.twin import DEFAULT_EFFECTS, Twin

OUT = Path(__file__).parent / "results"


def schedule(t_h):
    a = float(np.clip((t_h - 0.5) / 0.5, 0.0, 1.0))
    return np.array([1.0 - 0.4 * a, 0.4 * a])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--horizons", default="10,20,40")
    ap.add_argument("--grids", default="10x2.0x1", help="count x ratio x mixers, comma separated")
    ap.add_argument("--duration-h", type=float, default=2.5)
    args = ap.parse_args(argv)
    dt = 0.05
    sensors = Sensors()
    plant = Twin(["B", "D"], mill="industrial", effects=list(DEFAULT_EFFECTS))
    feed0 = feed_for_target(plant, [1.0, 0.0], 210.0, 0.70)
    ss = plant.steady(feed_tph=feed0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    rows = []
    for grid in args.grids.split(","):
        count, ratio, mixers = grid.split("x")
        ctw = controller_model(sensors.p80_dead_time_h, int(count), float(ratio), int(mixers))
        css = ctw.steady(feed_tph=feed0, speed_frac_critical=0.70, blend=[1.0, 0.0])
        for n in (int(v) for v in args.horizons.split(",")):
            t0 = time.perf_counter()
            ctrl = Controller(ctw.model, NmpcSettings(horizon_steps=n, dt_h=dt, weight_du_feed=1.0,
                                                      weight_du_speed=1.0))
            build = time.perf_counter() - t0
            res = run_closed_loop(plant.model, ctrl, Ekf(ctw.model, dt, css.x), schedule, sensors,
                                  args.duration_h, dt, ss.x, ss.u, seed=1, preview_lead_h=0.5)
            k = res.kpis
            row = {"size_classes": int(count), "ratio": float(ratio), "mixers": int(mixers),
                   "n_states": ctw.model.n_x, "horizon_steps": n, "horizon_h": n * dt,
                   "build_s": build, "solve_time_median_s": k["solve_time_median_s"],
                   "solve_time_p95_s": k["solve_time_p95_s"],
                   "iterations_median": float(res.frame.iterations.median()),
                   "p80_iae_um_h": k["p80_iae_um_h"], "p80_within_10um_frac": k["p80_within_10um_frac"],
                   "fallback_steps": k["fallback_steps"]}
            print(row, flush=True)
            rows.append(row)
    t = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    t.to_csv(OUT / "mpc_nmpc_horizon.csv", index=False)
    (OUT / "mpc_nmpc_horizon.md").write_text(
        "# NMPC solve time against horizon and size classes (IPOPT, exact Hessian, warm start)\n\n"
        f"{args.duration_h} h closed loop, transition at 0.5-1.0 h, preview 0.5 h, dt {dt} h.\n\n"
        + t.to_markdown(index=False, floatfmt=".4g") + "\n")
    return t


if __name__ == "__main__":
    main()
