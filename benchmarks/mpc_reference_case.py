"""The reference case of issue 5 (scenarios/reference_transition.toml numbers): industrial mill,
Type B steady at 210 um, then a 0.5 h ramp to 60 % B / 40 % D at t = 3 h, mineralogy known
0.5 h ahead. Four controllers on the same plant twin (25 classes, 3 mixers), sensors and seed:
no control, PI feedback (SIMC from the linearised plant), NMPC without preview, NMPC with
preview. The NMPC and the EKF use the scene's controller model (7 classes of ratio 2.5 and the
plant's 3 mixers, plus the analyser lag chain; ``--count/--ratio/--mixers`` change it): the
plant/model mismatch is absorbed by the estimated hardness. ``--seeds 1,2,3`` repeats the
case over sensor-noise seeds and writes the per-seed IAE and its ratio to PI.

Writes benchmarks/results/mpc_reference_case.csv (KPIs), .md (table) and
mpc_reference_case_runs.csv (all runs, one row per sample); with ``--seeds``,
mpc_reference_case_seeds.csv and .md.

    PYTHONPATH=. python benchmarks/mpc_reference_case.py [--duration-h 8] [--dt-h 0.05]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from mpc import FixedInputs, LoopSettings, Sensors, pi_baseline, run_closed_loop
from mpc.estimator import HARDNESS_NOISE_PER_SQRT_H, Ekf
from mpc.nmpc import Controller, NmpcSettings
from mpc.optimize import feed_for_target
from twin.sizes import SizeGrid
from twin.twin import DEFAULT_EFFECTS, Twin
from dem_common import TAG, command_note

OUT = Path(__file__).parent / "results"
TARGET_UM = 210.0
T_SWITCH_H, RAMP_H, LEAD_H = 3.0, 0.5, 0.5


def schedule(t_h: float) -> np.ndarray:
    a = float(np.clip((t_h - T_SWITCH_H) / RAMP_H, 0.0, 1.0))
    return np.array([1.0 - 0.4 * a, 0.4 * a])


#: The controller's model of scenarios/reference_transition.toml: 7 classes of ratio 2.5, 3 mixers.
CONTROLLER_GRID = {"count": 7, "ratio": 2.5, "n_mixers": 3}


def controller_model(dead_time_h: float, count: int = CONTROLLER_GRID["count"],
                     ratio: float = CONTROLLER_GRID["ratio"], n_mixers: int = CONTROLLER_GRID["n_mixers"]):
    return Twin(["B", "D"], mill="industrial", effects=list(DEFAULT_EFFECTS) + ["sensor_delay"],
                effect_options={"sensor_delay": {"dead_time_h": dead_time_h}},
                grid=SizeGrid(top_um=6700.0, ratio=ratio, count=count), n_mixers=n_mixers)


def add_case_arguments(ap: argparse.ArgumentParser) -> None:
    """The command-line options of the reference case shared by its benchmarks."""
    ap.add_argument("--duration-h", type=float, default=8.0)
    ap.add_argument("--dt-h", type=float, default=0.05)
    ap.add_argument("--horizon", type=int, default=10)
    ap.add_argument("--rk4-substeps", type=int, default=3, help="RK4 steps per sample of the NMPC model (the scene's)")
    ap.add_argument("--count", type=int, default=CONTROLLER_GRID["count"], help="size classes of the controller model")
    ap.add_argument("--ratio", type=float, default=CONTROLLER_GRID["ratio"], help="sieve ratio of the controller model")
    ap.add_argument("--mixers", type=int, default=CONTROLLER_GRID["n_mixers"],
                    help="mixers in series of the controller model")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--weight-du-feed", type=float, default=1.0)
    ap.add_argument("--weight-du-speed", type=float, default=1.0)
    ap.add_argument("--weight-p80", type=float, default=1.0)
    ap.add_argument("--weight-energy", type=float, default=0.01)
    ap.add_argument("--solver", default="rti", help="NmpcSettings.solver of the NMPC runs")
    ap.add_argument("--hardness-noise", type=float, default=HARDNESS_NOISE_PER_SQRT_H,
                    help="EKF random-walk intensity of the hardness scale [1/sqrt(h)]")
    ap.add_argument("--disturbance-model", default="hardness", help="EKF disturbance model (mpc.DISTURBANCE_MODELS)")
    ap.add_argument("--warmup-h", type=float, default=2.0,
                    help="estimator warm-up on the steady plant before t = 0 [h]")


def reference_sensors() -> Sensors:
    """P80 analyser (noise 3 um, dead time 0.1 h, sampling 0.05 h), power and load sensors."""
    return Sensors(p80_noise_um=3.0, p80_dead_time_h=0.1, p80_sample_period_h=0.05,
                   power_noise_kw=5.0, load_noise_frac=0.01)


def reference_setup(sensors: Sensors, args=None):
    """Plant twin (25 classes x 3 mixers) with its steady state at the target on Type B, and the
    controller model (``args.count/ratio/mixers``, else the defaults) with its steady state at
    the same inputs: ``(plant, ss, ctw, css)``."""
    plant = Twin(["B", "D"], mill="industrial", effects=list(DEFAULT_EFFECTS))
    feed0 = feed_for_target(plant, [1.0, 0.0], TARGET_UM, 0.70)
    ss = plant.steady(feed_tph=feed0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    grid = {} if args is None else {"count": args.count, "ratio": args.ratio, "n_mixers": args.mixers}
    ctw = controller_model(sensors.p80_dead_time_h, **grid)
    css = ctw.steady(feed_tph=feed0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    return plant, ss, ctw, css


def reference_ekf(ctw, css, dt_h: float, hardness_noise: float, disturbance_model: str = "hardness") -> Ekf:
    """The EKF of the case on the controller model, started at its steady state."""
    return Ekf(ctw.model, dt_h, css.x, hardness_noise_per_sqrt_h=hardness_noise, disturbance_model=disturbance_model)


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_case_arguments(ap)
    ap.add_argument("--only", default="none,pi,nmpc,nmpc_preview")
    ap.add_argument("--tag", default="", type=TAG, help="suffix of the result files")
    ap.add_argument("--seeds", default="", help="comma-separated sensor-noise seeds to repeat over")
    args = ap.parse_args(argv)
    if args.seeds:
        return run_seeds(args)
    return run_case(args)


def run_seeds(args) -> pd.DataFrame:
    """The case once per seed of ``args.seeds``; IAE per controller and its ratio to PI's."""
    rows = []
    for seed in (int(v) for v in args.seeds.split(",")):
        args.seed = seed
        t = run_case(args, write=False).set_index("controller")
        for kind, r in t.iterrows():
            rows.append({"seed": seed, "controller": kind, "p80_iae_um_h": r.p80_iae_um_h,
                         "iae_over_pi": r.p80_iae_um_h / t.loc["pi", "p80_iae_um_h"] if "pi" in t.index else np.nan,
                         "solve_time_median_s": r.solve_time_median_s})
    table = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / f"mpc_reference_case_seeds{args.tag}.csv", index=False)
    summary = table.groupby("controller")[["p80_iae_um_h", "iae_over_pi", "solve_time_median_s"]].agg(
        ["median", "min", "max"])
    summary.columns = [f"{a}_{b}" for a, b in summary.columns]
    md = [f"# Reference case over seeds {args.seeds}: P80 IAE and its ratio to PI", "", command_note(), "",
          f"{model_line(args)}; one run per seed (sensor noise differs), median / min / max.", "",
          summary.reset_index().to_markdown(index=False, floatfmt=".3g")]
    (OUT / f"mpc_reference_case_seeds{args.tag}.md").write_text("\n".join(md) + "\n")
    print(summary, flush=True)
    return table


def model_line(args) -> str:
    return (f"NMPC horizon {args.horizon}, RK4 sub-steps {args.rk4_substeps}; plant 25 classes x 3 "
            f"mixers; controller/EKF model {args.count} classes (ratio {args.ratio:g}) x {args.mixers} "
            "mixers + analyser lag")


def run_case(args, plant_hardness=1.0, write: bool = True) -> pd.DataFrame:
    """The controllers of ``args.only`` on the case; ``plant_hardness`` (float or callable of
    t_h) is the plant's true hardness scale, unknown to the controllers."""
    dt = args.dt_h
    sensors = reference_sensors()
    plant, ss, ctw, css = reference_setup(sensors, args)
    rows, runs = [], []
    for kind in args.only.split(","):
        est = reference_ekf(ctw, css, dt, args.hardness_noise, args.disturbance_model)
        t0 = time.perf_counter()
        if kind == "none":
            ctrl = FixedInputs(ss.u)
        elif kind == "pi":
            ctrl, fop = pi_baseline(plant.model, ss, sensors, dt, TARGET_UM)
            print(f"PI from {fop}: kc={ctrl.pi.kc:.4g} (t/h)/um, ti={ctrl.pi.ti_h:.4g} h")
        else:
            ctrl = Controller(ctw.model, NmpcSettings(
                horizon_steps=args.horizon, dt_h=dt, target_p80_um=TARGET_UM,
                rk4_substeps=args.rk4_substeps,
                weight_du_feed=args.weight_du_feed, weight_du_speed=args.weight_du_speed,
                weight_p80=args.weight_p80, weight_energy=args.weight_energy, solver=args.solver,
                preview=kind == "nmpc_preview"))
        build_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = run_closed_loop(plant.model, ctrl, est, schedule, sensors, ss.x, ss.u,
                              LoopSettings(args.duration_h, dt, seed=args.seed,
                                           preview_lead_h=LEAD_H if kind == "nmpc_preview" else 0.0,
                                           target_p80_um=TARGET_UM, estimator_warmup_h=args.warmup_h),
                              plant_hardness=plant_hardness)
        run_s = time.perf_counter() - t0
        k = dict(controller=kind, build_s=build_s, run_s=run_s, **res.kpis)
        k["p80_after_switch_max_abs_err_um"] = float(
            (res.frame.loc[res.frame.time_h >= T_SWITCH_H, "p80_um"] - TARGET_UM).abs().max())
        k["iterations_median"] = float(res.frame["iterations"].median())
        print(k, flush=True)
        rows.append(k)
        runs.append(res.frame.assign(controller=kind))
    table = pd.DataFrame(rows)
    if not write:
        return table
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / f"mpc_reference_case{args.tag}.csv", index=False)
    pd.concat(runs).to_csv(OUT / f"mpc_reference_case{args.tag}_runs.csv", index=False)
    cols = ["controller", "p80_iae_um_h", "p80_within_10um_frac", "p80_max_abs_err_um",
            "specific_energy_kwh_t", "throughput_t", "load_outside_band_frac",
            "solve_time_median_s", "solve_time_p95_s", "iterations_median", "fallback_steps"]
    md = [f"# Reference case: Type B -> 60 % B / 40 % D at {T_SWITCH_H} h (ramp {RAMP_H} h), "
          f"target {TARGET_UM} um, lead {LEAD_H} h",
          "", command_note(), "",
          f"duration {args.duration_h} h, sample {dt} h, seed {args.seed}; solver {args.solver}; "
          f"weights p80 {args.weight_p80}, du_feed {args.weight_du_feed}, du_speed "
          f"{args.weight_du_speed}, energy {args.weight_energy}; EKF hardness noise "
          f"{args.hardness_noise}/sqrt(h), disturbance model {args.disturbance_model}, warm-up {args.warmup_h} h before t = 0; "
          f"{model_line(args)}; sensors: P80 noise 3 um, dead time 0.1 h, sampling 0.05 h.",
          "", table[cols].to_markdown(index=False, floatfmt=".4g")]
    md += ["", estimates_line(runs[-1], f"mpc_reference_case{args.tag}_runs.csv")]
    (OUT / f"mpc_reference_case{args.tag}.md").write_text("\n".join(md) + "\n")
    return table


def estimates_line(frame: pd.DataFrame, runs_file: str) -> str:
    """What the EKF's estimates read against the plant's truth over one run (its controller's)."""
    h, bias = frame["hardness_est"], frame["p80_bias_est_um"]
    err = (frame["p80_est_um"] - frame["p80_um"]).abs()
    return (f"{frame['controller'].iloc[0]}: estimates beside the truth (columns of {runs_file}: "
            "`hardness_est` against `hardness_scale`, `p80_est_um` = `p80_model_um` + `p80_bias_est_um` against the plant's "
            f"`p80_um`): hardness_est median {h.median():.3f} (range {h.min():.3f}-{h.max():.3f}; truth "
            f"{frame['hardness_scale'].median():.3f}), P80 bias median {bias.median():.1f} um, "
            f"|p80_est_um - p80_um| median {err.median():.2f} um (max {err.max():.2f}).")


if __name__ == "__main__":
    main()
