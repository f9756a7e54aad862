"""What time-varying inputs cost an open-loop run, measured interleaved (A, B, A, B, ...; medians).

1. The 8-hour transition of twin_accuracy.py (2 ores x 25 classes x 3 mixers, one-minute
   samples, industrial mill from steady Type B): the blend as a step at 2 h, as a 30-minute
   ramp (linear between samples: one integrator call over the ramp), and as that ramp held per
   sample (a staircase: the integrator restarts at each of its 30 steps, which is how every
   changing input was integrated before). The ramp's P80 against the same ramp on a 16x finer
   grid says what the staircase's restarts also cost in accuracy.
2. IDAS's linear solver on replay_day.toml's plant (4 ores x 25 classes x 3 mixers = 300
   states), one hour of its recorded history held sample to sample: dense LU against sparse LU
   (CSparse, the default now).
3. The one-day open-loop replay: replay_day.toml with controller "none" over its whole history
   (``grindtwin replay``'s work after the imports), wall and CPU time; goal: under 30 s.

Writes benchmarks/results/twin_open_loop.md and .csv. Run: python benchmarks/twin_open_loop.py [--quick]
"""

from __future__ import annotations

import argparse
import importlib
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from scenarios.run import replay_scene
from scenarios.run.feed import component_blend, feed_schedule
from scenarios.run.models import build_models, component_ores
from scenarios.run.open_loop import sampled_input, step_samples
from scenarios.scene import load_scene, scene_from_dict
from twin import Twin

#: The integrator module (its name is shadowed by the function twin.solve.simulate).
sim = importlib.import_module("twin.solve.simulate")
ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results"
DT_H = 1 / 60


def interleaved(sides: dict, repeat: int) -> dict:
    """Median wall time of each side, timed A, B, C, A, B, C, ...; every side run once first."""
    for fn in sides.values():
        fn()
    times = {name: [] for name in sides}
    for _ in range(repeat):
        for name, fn in sides.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return {name: float(np.median(t)) for name, t in times.items()}


def transition_rows(repeat: int) -> list[dict]:
    tw = Twin(["B", "D"], mill="industrial")
    x0 = tw.steady(feed_tph=30.0, blend=[1.0, 0.0]).x

    def ramp(t):
        w = min(max((t - 2.0) / 0.5, 0.0), 1.0)
        return [1.0 - 0.4 * w, 0.4 * w]

    def staircase(t):
        return ramp(math.floor(t / DT_H + 1e-9) * DT_H)

    def step(t):
        return [1.0, 0.0] if t < 2.0 - 1e-12 else [0.6, 0.4]

    def run(blend, dt=DT_H):
        return tw.simulate(8.0, dt, feed_tph=30.0, blend=blend, x0=x0, exact_p80=False)

    t = interleaved({"step": lambda: run(step), "ramp": lambda: run(ramp), "staircase": lambda: run(staircase)},
                    repeat)
    fine = run(ramp, DT_H / 16).frame["p80_smooth_um"].to_numpy()[::16]
    rows = []
    for name, blend in (("step", step), ("ramp", ramp), ("staircase", staircase)):
        p80 = run(blend).frame["p80_smooth_um"].to_numpy()
        err = float(np.max(np.abs(p80 / fine - 1))) * 100 if name != "step" else math.nan
        rows.append({"table": "transition", "setting": f"blend as a {name}", "time_s": t[name],
                     "ratio_to_step": t[name] / t["step"], "p80_max_error_pct_vs_ramp_dt_16": err})
    return rows


def _replay_scene(duration_h: float | None = None):
    scene = load_scene(ROOT / "scenarios" / "replay_day.toml")
    data = scene.model_dump(exclude_none=True)
    data["controller"] = {"kind": "none", "target_p80_um": scene.controller.target_p80_um}  # its start: the target's
    if duration_h is not None:
        data["scene"]["duration_h"] = duration_h
    return scene_from_dict(data, scene.source_path)


def _with_idas_options(options: dict, run) -> float:
    """Wall time of ``run()`` with IDAS built with ``options`` (built first, untimed)."""
    sim.IDAS_OPTIONS.clear()
    sim.IDAS_OPTIONS.update(options)
    sim.stretch_integrator.cache_clear()
    run()
    t0 = time.perf_counter()
    run()
    return time.perf_counter() - t0


def linear_solver_rows(repeat: int) -> list[dict]:
    """Dense against sparse LU, interleaved, on the transition's model and on the replay's plant."""
    scene = _replay_scene(1.0)
    models = build_models(scene)
    plant = models.plant
    feed, _ = feed_schedule(scene, models.components, scene.time_grid_h(), component_ores(scene))
    blend = component_blend(feed, models.components)
    jumps = step_samples(scene, len(blend))
    dt = scene.scene.sample_period_h
    x_plant = plant.steady(feed_tph=30.0, speed_frac_critical=0.72, blend=list(blend[0])).x
    tw = Twin(["B", "D"], mill="industrial")
    x_tw = tw.steady(feed_tph=30.0, blend=[1.0, 0.0]).x
    cases = {
        f"the transition's model ({tw.model.n_x} states), 8 h step run": lambda: tw.simulate(
            8.0, DT_H, feed_tph=30.0, blend=lambda t: [1.0, 0.0] if t < 2.0 - 1e-12 else [0.6, 0.4], x0=x_tw,
            exact_p80=False),
        f"replay_day's plant ({plant.model.n_x} states), 1 h of the recorded day": lambda: plant.simulate(
            1.0, dt, feed_tph=30.0, speed_frac_critical=0.72, blend=sampled_input(blend, jumps, dt), x0=x_plant,
            exact_p80=False)}
    sparse = dict(sim.IDAS_OPTIONS)
    dense = {k: v for k, v in sparse.items() if k != "linear_solver"}
    rows = []
    try:
        for label, run in cases.items():
            times = {"dense LU": [], "sparse LU (CSparse)": []}
            for _ in range(repeat):
                times["dense LU"].append(_with_idas_options(dense, run))
                times["sparse LU (CSparse)"].append(_with_idas_options(sparse, run))
            med = {k: float(np.median(v)) for k, v in times.items()}
            rows += [{"table": "linear_solver", "setting": f"{name}: {label}", "time_s": v,
                      "ratio_to_dense": v / med["dense LU"]} for name, v in med.items()]
    finally:
        sim.IDAS_OPTIONS.clear()
        sim.IDAS_OPTIONS.update(sparse)
        sim.stretch_integrator.cache_clear()
    return rows


def replay_rows(repeat: int) -> list[dict]:
    scene = _replay_scene()
    history = scene.history_path()
    rows = []
    for i in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        res = replay_scene(scene, history, progress=False)
        rows.append({"table": "replay_day", "setting": f"open loop, {res.kpis['duration_h']:.3g} h, run {i + 1}",
                     "time_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0,
                     "mass_balance_error": res.kpis["mass_balance_error"]})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    args = ap.parse_args(argv)
    repeat = 3 if args.quick else 7
    rows = transition_rows(repeat) + linear_solver_rows(2 if args.quick else 3) + replay_rows(1 if args.quick else 3)
    table = pd.DataFrame(rows)
    name = "twin_open_loop_quick" if args.quick else "twin_open_loop"
    RESULTS.mkdir(exist_ok=True)
    table.to_csv(RESULTS / f"{name}.csv", index=False)
    lines = ["# Open-loop runs with time-varying inputs", "",
             "Medians of interleaved runs (A, B, A, B, ...) on a 2-core machine shared with other jobs; "
             "`python benchmarks/twin_open_loop.py`.", ""]
    for key, part in table.groupby("table", sort=False):
        lines += [f"## {key}", "", part.drop(columns="table").dropna(axis=1, how="all").to_markdown(index=False,
                                                                                                 floatfmt=".4g"), ""]
    (RESULTS / f"{name}.md").write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
