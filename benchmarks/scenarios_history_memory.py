"""Peak memory of reading a recorded plant history (scenarios.scene.history.read_history): this checkout against an
earlier revision, interleaved.

The history is SYNTHETIC (nothing measured): ``--rows`` records every 10 s from a ``timestamp`` column, three
mineral wt% columns summing to 100 and ``feed_tph``, written as pandas writes a CSV, under a comment line as
scenarios/data/make_sample_history.py writes one. Each read is a fresh process of a venv that imports grindtwin from
its tree ("now": this checkout; "before": ``--before REV`` exported by ``git archive``, as benchmarks/cli_startup.py
does), in the order now, before, now, before, ... Each process reads the history twice: once for the rise of its peak
resident memory (Linux's ``VmHWM``: ``ru_maxrss`` carried the parent's over the fork) over its peak after the
imports (libraries' own allocations included; memory the imports freed is reused, so this is the least the read
added), once under tracemalloc for the peak of Python's and numpy's allocations. Both as multiples of the file's
size; the table gives medians over ``--repeats`` and the median of the repeats' ratios now / before. Both sides
must return the same frame, report and SHA-256: the script stops if they differ.

Writes ``benchmarks/results/scenarios_history_memory{TAG}.md`` and ``.csv`` (the table) and ``..._reads.csv``
(every read).

Run: ``PYTHONPATH=. python benchmarks/scenarios_history_memory.py [--rows 500000] [--repeats 5] [--before REV]``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
#: Record interval [s] of the synthetic history: a year of these is some 3 million rows.
RECORD_S = 10


def write_history(path: Path, rows: int, seed: int = 1) -> None:
    """A synthetic mineralogy history of ``rows`` records (see the module docstring)."""
    rng = np.random.default_rng(seed)
    quartz = np.round(60 + rng.standard_normal(rows), 3)
    kaolinite = np.round(25 + rng.standard_normal(rows), 3)
    out = pd.DataFrame({
        "timestamp": pd.date_range("2026-01-01", periods=rows, freq=f"{RECORD_S}s").strftime("%Y-%m-%dT%H:%M:%S"),
        "quartz_wt_pct": quartz, "kaolinite_wt_pct": kaolinite, "calcite_wt_pct": np.round(100 - quartz - kaolinite, 3),
        "feed_tph": np.round(30 + rng.standard_normal(rows), 2)})
    path.write_text("# SYNTHETIC history for a memory benchmark, not measured\n"
                    + out.to_csv(index=False, lineterminator="\n"), encoding="utf-8")


def worker(path: str) -> None:
    """One process's reads (run by a tree's python): prints a JSON line of its peaks and what it read."""
    import tracemalloc

    import scenarios
    from scenarios.scene.history import read_history

    def read():
        return read_history(path, sample_period_h=1 / 60, feed_nominal_tph=30.0)

    def peak_rss() -> int:
        status = Path("/proc/self/status").read_text()
        return int(next(line.split()[1] for line in status.splitlines() if line.startswith("VmHWM:"))) * 1024

    base = peak_rss()
    history = read()
    rss = peak_rss() - base
    del history
    tracemalloc.start()
    history = read()
    traced = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    digest = hashlib.sha256(history.frame.to_numpy().tobytes() + json.dumps(
        [history.report, list(history.frame.columns), history.sha256, str(history.start)]).encode()).hexdigest()
    print(json.dumps({"rss": rss, "traced": traced, "digest": digest, "module": scenarios.__file__}))


def main(argv: list[str] | None = None) -> None:
    from cli_startup import export, tree_python
    from dem_common import TAG, write_table

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=500_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--before", default="origin/main", help="the revision to compare with")
    ap.add_argument("--tag", type=TAG, default="")
    args = ap.parse_args(argv)
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        history = tmp / "history.csv"
        write_history(history, args.rows)
        size = history.stat().st_size
        trees = {"now": ROOT, "before": export(args.before, tmp / "before")}
        pythons = {side: tree_python(tree, tmp / "venvs", side) for side, tree in trees.items()}
        for k in range(args.repeats):
            for side in ("now", "before"):
                res = subprocess.run([str(pythons[side]), __file__, "--worker", str(history)], capture_output=True,
                                     text=True, env={**os.environ, "PYTHONPATH": ""}, cwd=tmp)
                if res.returncode != 0:
                    raise SystemExit(f"{side}: the read failed: {res.stderr[-600:]}")
                got = json.loads(res.stdout.strip().splitlines()[-1])
                if not Path(got["module"]).resolve().is_relative_to(trees[side].resolve()):
                    raise SystemExit(f"{side}: imported {got['module']}, not {trees[side]}'s")
                records.append({"repeat": k, "side": side, "file_MB": size / 1e6, "rss_peak_MB": got["rss"] / 1e6,
                                "traced_peak_MB": got["traced"] / 1e6, "digest": got["digest"]})
    df = pd.DataFrame(records)
    if df["digest"].nunique() != 1:
        raise SystemExit(f"the two sides read different histories: {df[['side', 'digest']].drop_duplicates()}")
    wide = df.pivot(index="repeat", columns="side", values=["rss_peak_MB", "traced_peak_MB"])
    rows = []
    for key, what in (("rss_peak_MB", "rise of the peak resident memory (VmHWM) over the imports'"),
                      ("traced_peak_MB", "peak traced allocation (tracemalloc)")):
        now, before = wide[key]["now"], wide[key]["before"]
        rows.append({"measure": what, "now [x file]": f"{now.median() * 1e6 / size:.2f}",
                     "before [x file]": f"{before.median() * 1e6 / size:.2f}",
                     "now / before (median of repeats)": f"{(now / before).median():.2f}",
                     "range of repeats": f"{(now / before).min():.2f} to {(now / before).max():.2f}"})
    rev = subprocess.run(["git", "rev-parse", "--short", args.before], cwd=ROOT, capture_output=True,
                         text=True).stdout.strip()
    notes = (f"A synthetic history of {args.rows:,} records every {RECORD_S} s ({size / 1e6:.1f} MB), read by "
             f"read_history in a fresh process per side, {args.repeats} repeats interleaved (now, before, ...); "
             f"before: {args.before} ({rev}). Medians as multiples of the file's size; both sides returned the same "
             "frame, report and SHA-256.")
    df.drop(columns="digest").to_csv(ROOT / "benchmarks" / "results" / f"scenarios_history_memory{args.tag}_reads.csv",
                                     index=False)
    write_table(pd.DataFrame(rows), f"scenarios_history_memory{args.tag}",
                "Reading a recorded history: peak memory, now against before", notes)
    print((ROOT / "benchmarks" / "results" / f"scenarios_history_memory{args.tag}.md").read_text())


if __name__ == "__main__":
    if sys.argv[1:2] == ["--worker"]:
        worker(sys.argv[2])
    else:
        main()
