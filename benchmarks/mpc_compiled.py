"""Compiled against interpreted QP data of the real-time iteration (RTI + HPIPM), on the reference
scene's controller model (7 classes x 3 mixers + analyser lag, 45 states), in one run.

For each horizon, two controllers with the same settings, one whose QP data and cost run as
compiled C (``codegen="on"``, :mod:`mpc.codegen`) and one in CasADi's virtual machine
(``codegen="off"``), are stepped in lock-step on the same closed loop (the reference transition:
plant twin 25 classes x 3 mixers, EKF, sensors; the compiled controller's moves drive the plant).
Their steps alternate (A, B, A, B, ...), and their moves are compared at every sample (the same
moves are the same closed loop). The compiled controller's step is split into QP data, QP
(HPIPM) and the rest (Python). Build times: cold in an empty cache folder, then cached.

Writes benchmarks/results/mpc_compiled.csv and .md.

    PYTHONPATH=. python benchmarks/mpc_compiled.py [--horizons 10,40] [--duration-h 8]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from mpc_reference_case import LEAD_H, TARGET_UM, reference_ekf, reference_sensors, reference_setup, schedule  # noqa: E402

from mpc import Controller, NmpcSettings, Sensors, SensorState  # noqa: E402
from mpc.codegen import CACHE_ENV  # noqa: E402
from mpc.plants import as_plant  # noqa: E402

OUT = Path(__file__).parent / "results"


def settings(horizon: int, codegen: str, hpipm_mode: str = "robust") -> NmpcSettings:
    """The reference scene's NMPC (scenarios/reference_transition.toml) at ``horizon``."""
    return NmpcSettings(horizon_steps=horizon, dt_h=0.05, target_p80_um=TARGET_UM, rk4_substeps=2,
                        weight_du_feed=1.0, weight_du_speed=1.0, weight_energy=0.01, solver="rti",
                        codegen=codegen, hpipm_mode=hpipm_mode)


class Timed:
    """A callable that adds its wall time to ``total``."""

    def __init__(self, fn):
        self.fn, self.total = fn, 0.0

    def __call__(self, *a, **k):
        t0 = time.perf_counter()
        out = self.fn(*a, **k)
        self.total += time.perf_counter() - t0
        return out

    def stats(self):
        return self.fn.stats()


def build_times(model, horizon: int) -> dict:
    """Build time of the compiled controller in an empty cache (cold) and again (cached)."""
    old = os.environ.get(CACHE_ENV)
    with tempfile.TemporaryDirectory() as tmp:
        os.environ[CACHE_ENV] = tmp
        try:
            t0 = time.perf_counter()
            c = Controller(model, settings(horizon, "on"))
            cold = time.perf_counter() - t0
            t0 = time.perf_counter()
            Controller(model, settings(horizon, "on"))
            cached = time.perf_counter() - t0
        finally:
            if old is None:
                os.environ.pop(CACHE_ENV)
            else:
                os.environ[CACHE_ENV] = old
    return {"build_cold_s": cold, "compile_s": c.build_report["qp_data"].seconds + c.build_report["cost"].seconds,
            "build_cached_s": cached}


def lockstep(plant_model, ctw, css, ss, ctrls: dict, duration_h: float, dt: float, seed: int):
    """Drive the plant with the first controller's moves; step the others on the same inputs in
    turn (A, B, C, A, B, C...). One row per sample and controller."""
    plant = as_plant(plant_model)
    sensors: Sensors = reference_sensors()
    rng = np.random.default_rng(seed)
    est = reference_ekf(ctw, css, dt, 0.03)
    sens = SensorState(sensors, rng)
    timers = {}
    for name, c in ctrls.items():
        timers[name] = (Timed(c._qp_data), Timed(c._qp))
        c._qp_data, c._qp = timers[name]
    x, u_prev, rows = ss.x.copy(), ss.u.copy(), []
    lead = next(iter(ctrls))
    for k in range(int(round(duration_h / dt))):
        t = k * dt
        d_plant = plant.disturbance(t, schedule(t), 1.0)
        m = plant.measure(x, u_prev, d_plant)
        p80_new, _, pw, ld = sens.make_step(t, m["p80_um"], m["power_kw"], m["load_frac"])
        if k > 0:
            est.make_step([p80_new, pw, ld], u_prev, schedule(t - dt))
        times = t + dt * np.arange(ctrls[lead].settings.horizon_steps)
        preview = np.array([np.r_[schedule(min(tt, t + LEAD_H)), est.hardness_est] for tt in times]).T
        res = {}
        for name, c in ctrls.items():
            qd, qp = timers[name]
            qd.total = qp.total = 0.0
            r = res[name] = c.make_step(est.x_est, preview, u_prev)
            rows.append({"time_h": t, "controller": name, "step_s": r.solve_time_s, "qp_data_s": qd.total,
                         "qp_s": qp.total, "iterations": c._qp.stats().get("iter_count", np.nan),
                         "success": r.success, "u_feed": r.u_applied[0], "u_speed": r.u_applied[1]})
        x, _, _ = plant.step(x, res[lead].u_applied, d_plant, dt)
        u_prev = res[lead].u_applied
    return pd.DataFrame(rows)


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--horizons", default="10,40")
    ap.add_argument("--duration-h", type=float, default=8.0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    plant, ss, ctw, css = reference_setup(reference_sensors())
    rows = []
    for n in (int(v) for v in args.horizons.split(",")):
        b = build_times(ctw.model, n)
        ctrls = {"compiled": Controller(ctw.model, settings(n, "on")),
                 "interpreted": Controller(ctw.model, settings(n, "off")),
                 "compiled_hpipm_speed": Controller(ctw.model, settings(n, "on", "speed"))}
        fr = lockstep(plant.model, ctw, css, ss, ctrls, args.duration_h, 0.05, args.seed)
        ref = fr[fr.controller == "interpreted"].set_index("time_h")
        for name, g in fr.groupby("controller", sort=False):
            g = g.set_index("time_h")
            du = np.max(np.abs(g[["u_feed", "u_speed"]].to_numpy() / ref[["u_feed", "u_speed"]].to_numpy() - 1))
            row = {"horizon": n, "controller": name, **(b if name == "compiled" else {}), "steps": len(g),
                   "step_median_s": g.step_s.median(), "step_p95_s": g.step_s.quantile(0.95),
                   "interpreted_over_this": (ref.step_s / g.step_s).median(),
                   "qp_data_median_s": g.qp_data_s.median(), "hpipm_median_s": g.qp_s.median(),
                   "rest_median_s": (g.step_s - g.qp_data_s - g.qp_s).median(),
                   "hpipm_iterations_median": g.iterations.median(),
                   "move_rel_diff_max_vs_interpreted": du, "failed_steps": int((~g.success.astype(bool)).sum())}
            print(row, flush=True)
            rows.append(row)
    table = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / "mpc_compiled.csv", index=False)
    load = os.getloadavg()
    md = ["# Compiled against interpreted RTI QP data (reference scene's controller model, 45 states)", "",
          f"Lock-step on the reference transition ({args.duration_h} h, 3-min samples, seed {args.seed}); the two "
          "controllers' steps alternate (A, B, C, A, B, C...; the compiled one drives the plant); medians over the "
          "steps. gcc -O2; HPIPM in OCP form (N, nx, nu, ng given), robust mode unless named. `move_rel_diff_max`: largest relative difference of the applied moves. Build: "
          "cold = empty cache folder (generation + compilation), cached = a second build. "
          f"Load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on 2 cores (shared).", "",
          table.to_markdown(index=False, floatfmt=".4g"), "",
          "Reproduce: `PYTHONPATH=. python benchmarks/mpc_compiled.py`."]
    (OUT / "mpc_compiled.md").write_text("\n".join(md) + "\n")
    return table


if __name__ == "__main__":
    main()
