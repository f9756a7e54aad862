"""The real-time iteration's QP, condensed onto the inputs against sparse (HPIPM), both compiled,
on the reference scene's controller model (7 classes x 3 mixers + analyser lag, 45 states), in
one run.

For each horizon, controllers with the same settings but their QP (``NmpcSettings.qpsol``):
"condensed" (:mod:`mpc.condense`: the condensed QP data and the Goldfarb-Idnani solve in one
compiled C call, mpc/c) and "hpipm" (the stage-wise sparse QP data compiled, HPIPM in OCP form;
with ``--interpreted`` also its QP data in CasADi's virtual machine), are stepped in lock-step on
the same closed loop (the reference transition: plant twin 25 classes x 3 mixers, EKF, sensors;
the first controller's moves drive the plant). Their steps alternate (A, B, A, B, ...), and
their moves are compared at every sample (the same moves are the same closed loop). Each step is
split into QP data, QP and the rest (Python). Build times: cold in an empty cache folder, then
cached. The load average is read at every sample.

Writes benchmarks/results/mpc_compiled.csv and .md.

    PYTHONPATH=. python benchmarks/mpc_compiled.py [--horizons 10,40] [--duration-h 8]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
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
from dem_common import TAG  # noqa: E402

OUT = Path(__file__).parent / "results"
CACHE_FOLDERS: list[str] = []  # removed at the end of the run


def settings(horizon: int, codegen: str, qpsol: str = "condensed") -> NmpcSettings:
    """The reference scene's NMPC (scenarios/reference_transition.toml) at ``horizon``."""
    return NmpcSettings(horizon_steps=horizon, dt_h=0.05, target_p80_um=TARGET_UM, rk4_substeps=2,
                        weight_du_feed=1.0, weight_du_speed=1.0, weight_energy=0.01, solver="rti",
                        codegen=codegen, qpsol=qpsol)


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


def build_times(model, horizon: int, qpsol: str) -> tuple[dict, Controller]:
    """Build time of the compiled controller in an empty cache folder (cold) and again (cached);
    the cache folder stays set for the rest of the run, so the timed controller is the cached one."""
    os.environ[CACHE_ENV] = tempfile.mkdtemp(prefix="grindtwin-bench-")
    CACHE_FOLDERS.append(os.environ[CACHE_ENV])
    cpu0 = _cpu_s()
    t0 = time.perf_counter()
    c = Controller(model, settings(horizon, "on", qpsol))
    cold = time.perf_counter() - t0
    cold_cpu = _cpu_s() - cpu0
    t0 = time.perf_counter()
    c = Controller(model, settings(horizon, "on", qpsol))
    cached = time.perf_counter() - t0
    return {"build_cold_s": cold, "build_cold_cpu_s": cold_cpu, "build_cached_s": cached,
            "cached_hit": c.build_report["qp_data"].cache_hit}, c


def _cpu_s() -> float:
    """CPU time of this process and of its finished children (the C compiler) [s]."""
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


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
        if getattr(c, "_rti_c", False) is None:  # our RTI on the sparse QP (others: no split)
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
            if name in timers:
                qd, qp = timers[name]
                qd.total = qp.total = 0.0
            cpu0, wall0 = time.thread_time(), time.perf_counter()
            r = res[name] = c.make_step(est.x_est, preview, u_prev)
            cpu, wall = time.thread_time() - cpu0, time.perf_counter() - wall0
            if name in timers:
                data_s, qp_s = qd.total, qp.total
            elif getattr(c, "_rti_c", None) is not None:
                data_s, qp_s = c._rti_c.last_seconds()
            else:
                data_s = qp_s = np.nan
            # step: the whole make_step's wall time, on every controller alike (a controller's own solve_time_s
            # times its solver call only: ours 0.87 ms of a 1.64 ms step, do-mpc's IPOPT nearly its whole step)
            rows.append({"time_h": t, "controller": name, "step_s": wall, "solve_s": r.solve_time_s,
                         "step_cpu_s": cpu, "qp_data_s": data_s,
                         "qp_s": qp_s, "iterations": getattr(c, "qp_iterations", r.iterations), "load_1min": os.getloadavg()[0],
                         "success": r.success, "u_feed": r.u_applied[0], "u_speed": r.u_applied[1]})
        x, _, _ = plant.step(x, res[lead].u_applied, d_plant, dt)
        u_prev = res[lead].u_applied
    return pd.DataFrame(rows)


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--horizons", default="10,40")
    ap.add_argument("--duration-h", type=float, default=8.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--interpreted", action="store_true", help="also HPIPM with interpreted QP data")
    ap.add_argument("--tag", default="", type=TAG, help="suffix of the result files (e.g. _h40)")
    args = ap.parse_args(argv)
    plant, ss, ctw, css = reference_setup(reference_sensors())
    rows = []
    for n in (int(v) for v in args.horizons.split(",")):
        builds, ctrls = {}, {}
        for q in ("condensed", "hpipm"):
            builds[q], ctrls[q] = build_times(ctw.model, n, q)
        if args.interpreted:
            ctrls["hpipm_interpreted"] = Controller(ctw.model, settings(n, "off", "hpipm"))
        fr = lockstep(plant.model, ctw, css, ss, ctrls, args.duration_h, 0.05, args.seed)
        ref = fr[fr.controller == "hpipm"].set_index("time_h")
        for name, g in fr.groupby("controller", sort=False):
            g = g.set_index("time_h")
            du = np.max(np.abs(g[["u_feed", "u_speed"]].to_numpy() / ref[["u_feed", "u_speed"]].to_numpy() - 1))
            row = {"horizon": n, "controller": name, **builds.get(name, {}), "steps": len(g),
                   "step_median_s": g.step_s.median(), "step_p95_s": g.step_s.quantile(0.95),
                   "step_max_s": g.step_s.max(), "solve_median_s": g.solve_s.median(),
                   "step_cpu_median_s": g.step_cpu_s.median(),
                   "step_cpu_p95_s": g.step_cpu_s.quantile(0.95),
                   "hpipm_over_this": (ref.step_s / g.step_s).median(),
                   "qp_data_median_s": g.qp_data_s.median(), "qp_median_s": g.qp_s.median(),
                   "rest_median_s": (g.step_s - g.qp_data_s - g.qp_s).median(),
                   "qp_iterations_median": g.iterations.median(),
                   "move_rel_diff_max_vs_hpipm": du, "failed_steps": int((~g.success.astype(bool)).sum()),
                   "load_1min_median": g.load_1min.median()}
            print(row, flush=True)
            rows.append(row)
    for folder in CACHE_FOLDERS:
        shutil.rmtree(folder, ignore_errors=True)
    table = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / f"mpc_compiled{args.tag}.csv", index=False)
    load = os.getloadavg()
    md = ["# The RTI's QP condensed (Goldfarb-Idnani in C) against sparse (HPIPM), both compiled "
          "(reference scene's controller model, 45 states)", "",
          f"Lock-step on the reference transition ({args.duration_h} h, 3-min samples, seed {args.seed}); the "
          "controllers' steps alternate (A, B, A, B...; the condensed one drives the plant); medians over the "
          "steps. `step`: the wall time of the whole make_step (`solve`: the controller's own solve_time_s, its "
          "solver call; before 12-06 `step` was that); `step_cpu`: the thread's CPU time of the step, what the "
          "step costs whatever the load; "
          "`build_cold_cpu_s`: CPU time of the cold build, the C compiler included. The condensed step (the stage loop "
          "of mpc/c/gt_cond.c on generated stage functions, and the QP solver) compiled with gcc -O3, HPIPM's QP data with -O2; HPIPM in OCP form (N, nx, nu, ng given), robust mode. `hpipm_over_this`: median of the "
          "per-sample ratio of HPIPM's step to this one's. `move_rel_diff_max_vs_hpipm`: largest relative "
          "difference of the applied moves. `qp_data`/`qp`: the condensed step's are timed inside its C call. "
          "Build: cold = empty cache folder (generation + compilation), cached = a second build. "
          f"Load average (1 min) at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1/5/15 min) on 2 cores "
          "(shared with other jobs); `load_1min_median` over the run.", "",
          table.to_markdown(index=False, floatfmt=".4g"), "",
          f"Reproduce: `PYTHONPATH=. python benchmarks/mpc_compiled.py --horizons {args.horizons} "
          f"--duration-h {args.duration_h:g}" + (f" --tag {args.tag}`." if args.tag else "`.")]
    (OUT / f"mpc_compiled{args.tag}.md").write_text("\n".join(md) + "\n")
    return table


if __name__ == "__main__":
    main()
