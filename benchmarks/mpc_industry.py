"""What the controller buys, in industry's terms: P80 standard deviation, load variability,
throughput and specific energy for no control, PI, NMPC and NMPC with preview, each as a change
against no control and against PI, beside the industrial results reviewed by Bouffard (2015,
"Benefits of process control systems in mineral processing grinding circuits", Minerals
Engineering 79, 1-16: advanced control of grinding circuits reported 1-16 % more throughput and
40 % or more less variability of the controlled variables). Two cases (``--parts``):

- ``transition``: the reference transition (the runs of benchmarks/mpc_reference_case.py);
- ``day``: the shipped one-day replay, scenarios/replay_day.toml (24 h of recorded, synthetic
  feed mineralogy), run as a scene with ``controller.kind`` none (the feed of the target's
  steady state at the start held, the scene's ``feed.start = "target"``, and its speed), pi,
  nmpc without preview (``preview_lead_h = 0``) and nmpc with the scene's 0.5-h preview; the same KPIs from each run's frame (standard deviations over the samples, as
  :func:`mpc.kpis.loop_kpis`) and its summary.

Writes benchmarks/results/mpc_industry.csv (a ``case`` column) and .md.

    PYTHONPATH=. python benchmarks/mpc_industry.py [--parts transition,day] [--duration-h 8] [--seed 1]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from mpc_reference_case import add_case_arguments, model_line, run_case  # noqa: E402

OUT = Path(__file__).parent / "results"
COLUMNS = ("p80_std_um", "load_std_frac", "throughput_t", "specific_energy_kwh_t", "p80_iae_um_h")
DAY_SCENE = Path(__file__).resolve().parents[1] / "scenarios" / "replay_day.toml"
#: (name, controller.kind, preview_lead_h or None for the scene's own) of the day's runs
DAY_RUNS = (("none", "none", 0.0), ("pi", "pi", 0.0), ("nmpc", "nmpc", 0.0), ("nmpc_preview", "nmpc", None))


def changes(table: pd.DataFrame, base: str) -> pd.DataFrame:
    """Each KPI of every controller as a per-cent change against controller ``base``."""
    t = table.set_index("controller")[list(COLUMNS)]
    return (100.0 * (t / t.loc[base] - 1.0)).add_suffix(f"_vs_{base}_pct")


def with_changes(table: pd.DataFrame) -> pd.DataFrame:
    """The KPIs of every controller and their changes against no control and against PI."""
    return pd.concat([table.set_index("controller")[list(COLUMNS)], changes(table, "none"),
                      changes(table, "pi")], axis=1).reset_index()


def day_runs(progress: bool = False) -> pd.DataFrame:
    """The one-day replay scene under each controller of :data:`DAY_RUNS` (module docstring)."""
    from scenarios.run import run_scene
    from scenarios.scene import scene_from_dict
    from scenarios.scene.loader import read_toml

    rows = []
    for name, kind, lead in DAY_RUNS:
        data = read_toml(DAY_SCENE)
        data["controller"]["kind"] = kind
        if lead is not None:
            data["controller"]["preview_lead_h"] = lead
        t0 = time.perf_counter()
        res = run_scene(scene_from_dict(data, DAY_SCENE), progress=progress, plots=False)
        f, k = res.frame, res.kpis
        rows.append({"controller": name, "p80_std_um": float(np.std(f["p80_um"].to_numpy(float))),
                     "load_std_frac": float(np.std(f["load_frac"].to_numpy(float))),
                     **{c: float(k[c]) for c in ("throughput_t", "specific_energy_kwh_t", "p80_iae_um_h")},
                     "run_s": time.perf_counter() - t0})
        print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def main(argv=None) -> pd.DataFrame:
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_case_arguments(ap)
    ap.add_argument("--only", default="none,pi,nmpc,nmpc_preview", help="controllers of the transition")
    ap.add_argument("--parts", default="transition,day", help="transition, day (module docstring)")
    args = ap.parse_args(argv)
    parts = args.parts.split(",")
    unknown = sorted(set(parts) - {"transition", "day"})
    if unknown:
        raise SystemExit(f"--parts: unknown {unknown}; allowed transition, day")
    tables, md = [], ["# What the controller buys, in industry's terms", "",
                      "Standard deviations over all samples of the plant's P80 and load; throughput = product "
                      "over the run; changes in per cent against no control and against PI. Industrial reference "
                      "(Bouffard 2015, Minerals Engineering 79, 1-16, a review of grinding-circuit control): 1-16 % "
                      "throughput gain, 40 % or more less variability.", ""]
    if "transition" in parts:
        out = with_changes(run_case(args, write=False))
        tables.append(out.assign(case="transition"))
        md += ["## The reference transition", "",
               f"{args.duration_h} h, 3-min samples, seed {args.seed}, disturbance model {args.disturbance_model}; "
               f"{model_line(args)}.", "", out.to_markdown(index=False, floatfmt=".4g"), ""]
    if "day" in parts:
        day = day_runs()
        out = with_changes(day).merge(day[["controller", "run_s"]], on="controller")
        tables.append(out.assign(case="day"))
        md += ["## The one-day replay (scenarios/replay_day.toml)", "",
               "24 h of synthetic recorded feed mineralogy, the scene's plant, controller model, tuning, sensors "
               "and seed; none holds the feed of the target's steady state at the start and the scene's speed, nmpc "
               "runs without preview, nmpc_preview with "
               "the scene's 0.5 h. run_s: wall time of each run on a shared machine.", "",
               out.to_markdown(index=False, floatfmt=".4g"), ""]
    table = pd.concat(tables, ignore_index=True)
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / "mpc_industry.csv", index=False)
    md += [f"Reproduce: `{' '.join(['PYTHONPATH=. python benchmarks/mpc_industry.py', *argv])}`."]
    (OUT / "mpc_industry.md").write_text("\n".join(md) + "\n")
    print(table.to_string())
    return table


if __name__ == "__main__":
    main()
