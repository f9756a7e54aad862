"""What accuracy costs in time, for the twin (PBM).

Writes benchmarks/results/twin_accuracy.md and .csv:
1. size classes (same size range, finer ratio) -> steady P80 error against a 120-class
   reference, build and steady-state time;
2. integrator tolerance -> P80 error over an 8-hour ore transition against a tight-tolerance
   run, and wall time;
3. mixers in series -> P80 and time (a model choice, not a convergence knob: reported as
   sensitivity);
4. each effect on and off -> states, RHS operations, steady and 8-hour run times;
5. the targets: an 8-hour run (2 components x 25 classes x 3 mixers) <= 0.1 s after the build,
   a steady state <= 10 ms.
Times are medians of REPEAT runs on this (2-core, shared) machine.

Run: python benchmarks/twin_accuracy.py [--quick]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from twin.sizes import SizeGrid
from twin.effects.registry import EFFECTS
from twin.twin import DEFAULT_EFFECTS, Twin

RESULTS = Path(__file__).parent / "results"
REPEAT = 5
TOP_UM, BOTTOM_UM = 6700.0, 6700.0 / 4096.0


def grid(count: int) -> SizeGrid:
    return SizeGrid(top_um=TOP_UM, ratio=(TOP_UM / BOTTOM_UM) ** (1.0 / (count - 1)), count=count)


def median_time(fn, repeat=REPEAT):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def transition(tw: Twin, exact_p80: bool = False):
    """8 h, industrial scale: Type B, then a 30-min ramp to 60 % B / 40 % D at 2 h. The timed runs leave out
    the exact P80 (an interpolation in Python at every sample, not the integration being timed)."""
    def blend(t):
        w = min(max((t - 2.0) / 0.5, 0.0), 1.0)
        return [1.0 - 0.4 * w, 0.4 * w]
    return dict(duration_h=8.0, dt_h=1 / 60, feed_tph=30.0, blend=blend, exact_p80=exact_p80)


def timed_transition(tw: Twin, x0, **kw):
    """The transition once with the exact P80 (``p80_um``; this run also builds the integrators), then the
    median time of runs without it: (time [s], the exact run)."""
    run = tw.simulate(x0=x0, **transition(tw, exact_p80=True), **kw)
    t, _ = median_time(lambda: tw.simulate(x0=x0, **transition(tw), **kw))
    return t, run


def size_classes(counts):
    rows = []
    ref = Twin("B", grid=grid(120)).steady().p80_um
    for n in counts:
        t_build, tw = median_time(lambda: Twin("B", grid=grid(n)), 3)
        tw.steady()  # builds the Jacobian once
        t_ss, ss = median_time(lambda: tw.steady())
        rows.append({"table": "size_classes", "setting": f"{n} classes (ratio {grid(n).ratio:.3f})",
                     "p80_um": ss.p80_um, "error_pct": 100 * (ss.p80_um / ref - 1),
                     "build_s": t_build, "time_s": t_ss})
    return rows, ref


def tolerances(rtols):
    tw = Twin(["B", "D"], mill="industrial")
    x0 = tw.steady(feed_tph=30.0, blend=[1.0, 0.0]).x
    ref = tw.simulate(x0=x0, rtol=1e-11, atol_rel=1e-13, **transition(tw, exact_p80=True)).frame["p80_um"].to_numpy()
    rows = []
    for rtol in rtols:
        t, run = timed_transition(tw, x0, rtol=rtol, atol_rel=rtol * 1e-2)
        p80 = run.frame["p80_um"].to_numpy()
        rows.append({"table": "tolerance", "setting": f"rtol {rtol:.0e}", "p80_um": p80[-1],
                     "error_pct": 100 * float(np.max(np.abs(p80 / ref - 1))), "time_s": t,
                     "mass_balance_rel": run.mass_balance_error()})
    return rows


def mixers(ns):
    rows = []
    for n in ns:
        tw = Twin(["B", "D"], mill="industrial", n_mixers=n)
        x0 = tw.steady(feed_tph=30.0, blend=[1.0, 0.0]).x
        t, run = timed_transition(tw, x0)
        rows.append({"table": "mixers", "setting": f"{n} mixer(s)", "p80_um": run.frame["p80_um"].iloc[-1],
                     "states": tw.model.n_x, "time_s": t})
    return rows


def effects():
    rows = []
    base = ["breakage", "transport"]
    full = [*DEFAULT_EFFECTS, "slowing_down", "sensor_delay"]
    variants = {"breakage+transport": base, "all": full}
    for e in full:
        if e in base:
            continue
        needs_e = [x for x in full if e in EFFECTS[x].requires]  # leave with the effect they need
        name = f"all - {e}" + "".join(f" - {x}" for x in needs_e)
        variants[name] = [x for x in full if x != e and x not in needs_e]
    for name, effs in variants.items():
        tw = Twin(["B", "D"], mill="industrial", effects=effs)
        tw.steady(feed_tph=30.0)
        t_ss, ss = median_time(lambda: tw.steady(feed_tph=30.0))
        x0 = ss.x
        t_run, _ = timed_transition(tw, x0)
        rows.append({"table": "effects", "setting": name, "states": tw.model.n_x,
                     "rhs_ops": tw.model.n_instructions, "p80_um": ss.p80_um,
                     "steady_s": t_ss, "time_s": t_run})
    return rows


def targets():
    tw = Twin(["B", "D"], mill="industrial")
    x0 = tw.steady(feed_tph=30.0, blend=[1.0, 0.0]).x
    step = dict(transition(tw), blend=lambda t: [1.0, 0.0] if t < 2.0 else [0.6, 0.4])
    rows = []
    for name, kw in (("30-min ramp (one integrator restart per sample)", transition(tw)),
                     ("step at 2 h", step)):
        tw.simulate(x0=x0, **kw)
        t_run, _ = median_time(lambda: tw.simulate(x0=x0, **kw))
        rows.append({"table": "targets", "setting": f"8-h run, 2 x 25 x 3, {name} (goal <= 0.1 s)",
                     "time_s": t_run})
    t_ss, _ = median_time(lambda: tw.steady(feed_tph=30.0), 11)
    return rows + [{"table": "targets", "setting": "steady state, 2 x 25 x 3 (goal <= 0.01 s)", "time_s": t_ss}]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer settings")
    ap.add_argument("--targets-only", action="store_true", help="print the speed targets only (no table written)")
    args = ap.parse_args(argv)
    if args.targets_only:
        print(pd.DataFrame(targets()).to_markdown(index=False, floatfmt=".4g"))
        return
    counts = (10, 25, 60) if args.quick else (10, 15, 25, 40, 60)
    rtols = (1e-4, 1e-8) if args.quick else (1e-4, 1e-6, 1e-8, 1e-10)
    rows, ref = size_classes(counts)
    rows += tolerances(rtols) + mixers((1, 3) if args.quick else (1, 2, 3, 5)) + effects() + targets()
    df = pd.DataFrame(rows)
    RESULTS.mkdir(exist_ok=True)
    df.to_csv(RESULTS / "twin_accuracy.csv", index=False)
    with open(RESULTS / "twin_accuracy.md", "w") as fh:
        fh.write(f"# Twin: accuracy against time\n\nMedian of {REPEAT} runs, 2-core shared machine, "
                 f"{time.strftime('%Y-%m-%d')}. Size-class reference: 120 classes, P80 {ref:.2f} um. Made by "
                 f"`PYTHONPATH=. python benchmarks/twin_accuracy.py{' --quick' if args.quick else ''}`.\n\n")
        for table, part in df.groupby("table", sort=False):
            fh.write(f"## {table}\n\n" + part.dropna(axis=1, how="all").drop(columns="table")
                     .to_markdown(index=False, floatfmt=".4g") + "\n\n")
    print(open(RESULTS / "twin_accuracy.md").read())


if __name__ == "__main__":
    main()
