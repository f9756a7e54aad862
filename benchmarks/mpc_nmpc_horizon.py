"""What control accuracy costs in time: NMPC per-step solve time (median, 95th percentile) and
iterations against the solver, the horizon, the controller model's size classes and the
discretisation (RK4 sub-steps per sample; raised to the fewest stable ones of the model,
:func:`mpc.discretize.stable_rk4_substeps`), beside the closed-loop IAE of P80, on a short
version of the reference transition (Type B at 210 um, ramp to 60 % B / 40 % D from 0.5 h to
1.0 h, preview 0.5 h; 2.5 h at 0.05 h samples; plant 25 classes x 3 mixers; P80 noise 3 um,
dead time 0.1 h).

Writes benchmarks/results/mpc_nmpc_horizon.csv and .md.

    PYTHONPATH=. python benchmarks/mpc_nmpc_horizon.py [--solvers rti,ipopt] [--horizons 10,15,20,40]
        [--grids 7x2.5x3,...] [--substeps 2,3,6]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from mpc_reference_case import controller_model  # same directory (run as a script)
from mpc import LoopSettings, Sensors, run_closed_loop
from mpc.discretize import stable_rk4_substeps
from mpc.estimator import Ekf
from mpc.nmpc import Controller, NmpcSettings
from mpc.optimize import feed_for_target
from twin.twin import DEFAULT_EFFECTS, Twin

OUT = Path(__file__).parent / "results"


def schedule(t_h):
    a = float(np.clip((t_h - 0.5) / 0.5, 0.0, 1.0))
    return np.array([1.0 - 0.4 * a, 0.4 * a])


def write(rows, args, dt) -> pd.DataFrame:
    t = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    t.to_csv(OUT / "mpc_nmpc_horizon.csv", index=False)
    (OUT / "mpc_nmpc_horizon.md").write_text(
        "# NMPC solve time against solver, horizon, size classes and discretisation\n\n"
        f"{args.duration_h} h closed loop, transition at 0.5-1.0 h, preview 0.5 h, dt {dt} h; "
        "rti: one Gauss-Newton QP per sample by HPIPM; ipopt: exact Hessian, warm start. "
        "Solve time is the solver call (median and 95th percentile over the run's samples), "
        "measured on a 2-core machine shared with other jobs.\n\n"
        + t.to_markdown(index=False, floatfmt=".4g") + "\n")
    return t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--solvers", default="rti,ipopt,fatrop",
                    help="fatrop runs on the first grid at horizons <= 20 only (~0.8 s a step)")
    ap.add_argument("--horizons", default="10,15,20,40")
    ap.add_argument("--ipopt-max-horizon", type=int, default=20,
                    help="IPOPT's exact-Hessian build grows fast with the horizon (~50 s at 40)")
    ap.add_argument("--ipopt-max-classes", type=int, default=15,
                    help="and with the classes (~55 s at 15 classes and horizon 20)")
    ap.add_argument("--grids", default="7x2.5x3,7x2.5x2,10x2.0x1,10x2.0x3,15x1.5x1",
                    help="count x ratio x mixers, comma separated (the first is the scene's)")
    ap.add_argument("--substeps", default="2,3,6", help="RK4 sub-steps per sample (the "
                    "non-default values run on the first grid at horizon 15 only)")
    ap.add_argument("--duration-h", type=float, default=2.5)
    args = ap.parse_args(argv)
    dt = 0.05
    sensors = Sensors()
    plant = Twin(["B", "D"], mill="industrial", effects=list(DEFAULT_EFFECTS))
    feed0 = feed_for_target(plant, [1.0, 0.0], 210.0, 0.70)
    ss = plant.steady(feed_tph=feed0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    rows = []
    substeps = [int(v) for v in args.substeps.split(",")]
    grids = args.grids.split(",")

    def run_one(solver, ctw, css, n, sub, warm_start=True) -> dict:
        t0 = time.perf_counter()
        ctrl = Controller(ctw.model, NmpcSettings(
            horizon_steps=n, dt_h=dt, weight_du_feed=1.0, weight_du_speed=1.0,
            rk4_substeps=sub, solver=solver, warm_start=warm_start))
        build = time.perf_counter() - t0
        res = run_closed_loop(plant.model, ctrl, Ekf(ctw.model, dt, css.x), schedule, sensors, ss.x, ss.u,
                              LoopSettings(args.duration_h, dt, seed=1, preview_lead_h=0.5))
        k = res.kpis
        return {"solver": solver, "size_classes": ctw.model.spec.grid.count,
                "ratio": ctw.model.spec.grid.ratio, "mixers": ctw.model.spec.n_mixers,
                "n_states": ctw.model.n_x,
                "rk4_substeps": sub, "warm_start": warm_start, "horizon_steps": n,
                "horizon_h": n * dt, "build_s": build,
                "solve_time_median_s": k["solve_time_median_s"],
                "solve_time_p95_s": k["solve_time_p95_s"],
                "iterations_median": float(res.frame.iterations.median()),
                "p80_iae_um_h": k["p80_iae_um_h"], "p80_within_10um_frac": k["p80_within_10um_frac"],
                "fallback_steps": k["fallback_steps"]}

    for solver in args.solvers.split(","):
        for gi, grid in enumerate(grids):
            count, ratio, mixers = grid.split("x")
            ctw = controller_model(sensors.p80_dead_time_h, int(count), float(ratio), int(mixers))
            css = ctw.steady(feed_tph=feed0, speed_frac_critical=0.70, blend=[1.0, 0.0])
            stable = stable_rk4_substeps(ctw.model.f, css.x, css.u, css.d, dt)
            for n in (int(v) for v in args.horizons.split(",")):
                if solver == "ipopt" and (n > args.ipopt_max_horizon
                                          or int(count) > args.ipopt_max_classes):
                    continue
                if solver == "fatrop" and (gi > 0 or n > 15):
                    continue
                for j, sub in enumerate(substeps):
                    if j > 0 and (gi > 0 or n != 15):
                        continue
                    cases = [True]
                    if solver == "ipopt" and gi == 0 and n == 15 and j == 0:
                        cases.append(False)  # interior-point warm starts gain little: measure it
                    for warm in cases:
                        rows.append(run_one(solver, ctw, css, n, max(sub, stable), warm))
                        print(rows[-1], flush=True)
                        write(rows, args, dt)  # a partial table survives an interrupted run
    t = write(rows, args, dt)
    return t


if __name__ == "__main__":
    main()
