"""What control accuracy costs in time: linear MPC on the le Roux (2013) circuit.

For each QP solver and horizon, run the linear MPC (model: the circuit linearised at survey 3,
ZOH at 3 min) in closed loop on the *nonlinear* le Roux plant through a P80 set-point step of
-4 um, and record the per-step solve time (median, 95th percentile), QP iterations and the
closed-loop IAE of P80 from the set point (um h). Writes
``benchmarks/results/mpc_linear_horizon.csv`` and prints the table.

Run: ``python benchmarks/mpc_linear_horizon.py [--quick]``.
"""

from __future__ import annotations

import argparse
import pathlib
import platform
import time

import casadi as ca
import numpy as np
import pandas as pd

from mpc.plants.leroux import LeRouxCircuit
from mpc.linear import LinearMPC, discretize, linearize, steady_target

DT_H = 0.05
RESULTS = pathlib.Path(__file__).resolve().parent / "results"


def run(solver: str, horizon: int, n_steps: int) -> dict:
    plant = LeRouxCircuit(dt_h=DT_H)
    xs = plant.steady_state()
    sysc, op = linearize(plant.f, plant.outputs, xs, plant.u_nominal, plant.d_nominal,
                         ["p80_um"])
    sysd = discretize(sysc, DT_H)
    xt, ut = steady_target(sysd, {"p80_um": -4.0}, u_weight=np.diag([1.0, 1e4]))
    cp = np.asarray(sysd.C)[0]
    q = np.outer(cp, cp) + 1e-6 * np.eye(sysd.nstates)
    mpc = LinearMPC(sysd, q, np.diag([1e-3, 1e3]), horizon=horizon,
                    u_min=np.array([30.0, 0.6]) - plant.u_nominal,
                    u_max=np.array([90.0, 0.8]) - plant.u_nominal,
                    du_max=[1.0, 0.005], solver=solver)
    plant.reset(xs)
    times, iters, iae, fails = [], [], 0.0, 0
    for _ in range(n_steps):
        res = mpc.make_step(plant.x - xs, x_ref=xt, u_ref=ut)
        times.append(res.solve_time_s)
        iters.append(res.iterations)
        fails += int(not res.success)
        y = plant.make_step(plant.u_nominal + res.u_applied)
        iae += abs(y["p80_um"] - (op.y_ss[0] - 4.0)) * DT_H
    t = np.array(times) * 1e3
    return {"solver": solver, "horizon": horizon, "steps": n_steps,
            "median_ms": float(np.median(t)), "p95_ms": float(np.percentile(t, 95)),
            "mean_iterations": float(np.mean(iters)), "failures": fails,
            "iae_p80_um_h": iae}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two horizons, fewer steps")
    args = ap.parse_args()
    horizons = (10, 30) if args.quick else (10, 20, 40, 60)
    n_steps = 30 if args.quick else 80
    solvers = [s for s in ("qpoases", "daqp", "osqp") if ca.has_conic(s)]
    rows = [run(s, n, n_steps) for s in solvers for n in horizons]
    df = pd.DataFrame(rows)
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = RESULTS / "mpc_linear_horizon.csv"
    df.to_csv(out, index=False)
    print(f"# {time.strftime('%Y-%m-%d %H:%M:%S')} {platform.processor() or platform.machine()}"
          f" casadi {ca.__version__}")
    print(df.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print(f"written {out}")


if __name__ == "__main__":
    main()
