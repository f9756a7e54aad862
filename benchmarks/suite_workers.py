"""How long the test suite takes on its two pytest-xdist workers (pyproject's addopts) against one
process (``-n 0``), the two interleaved: two-worker run, one-process run, two-worker run, ...

Each run is the README's test command from this checkout, ``python -m pytest -q -p no:cacheprovider``
(pytest's own cache left alone), with ``-n 0`` on the one-process side; wall time, and the CPU time
(user + system) of the run and every process it waited for. The kernels and compiled controllers
should be in the cache already (any earlier run of the suite): the first run would otherwise pay
their compilation alone (``--warmup 1`` runs one untimed two-worker run first). A run whose tests do
not all pass stops the benchmark with its output's tail, and nothing is written.

Writes ``benchmarks/results/suite_workers{TAG}.md`` and ``.csv`` (medians; the ratio is the median
of the within-round ratios) and ``suite_workers{TAG}_runs.csv`` (every run).

    python benchmarks/suite_workers.py [--rounds 2] [--warmup 0] [--tag TAG]
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import time

import numpy as np
import pandas as pd

from dem_common import COUNT, TAG, cpu_model, load_average, write_table

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SUITE = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"]
SIDES = {"two workers": SUITE, "one process": [*SUITE, "-n", "0"]}


def options(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=COUNT, default=2, help="interleaved rounds (each runs both sides)")
    ap.add_argument("--warmup", type=int, choices=(0, 1), default=0, help="an untimed two-worker run first")
    ap.add_argument("--tag", type=TAG, default="", help="suffix of the results' file names")
    return ap.parse_args(argv)


def children_cpu_s() -> float:
    """User + system seconds of every child process reaped so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run(side: str) -> dict:
    """One run of the suite: wall and CPU seconds, and the tests it passed."""
    cpu0, t0 = children_cpu_s(), time.perf_counter()
    done = subprocess.run(SIDES[side], cwd=ROOT, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, children_cpu_s() - cpu0
    passed = re.search(r"(\d+) passed", done.stdout)
    if done.returncode != 0 or passed is None:
        tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-15:])
        raise SystemExit(f"the suite ({side}) exited {done.returncode}; nothing written. Its output ends:\n{tail}")
    return {"side": side, "wall_s": wall, "cpu_s": cpu, "passed": int(passed.group(1)), "load_after": load_average()}


def main(argv=None):
    o = options(argv)
    note = (f"Command: `python benchmarks/suite_workers.py {' '.join(sys.argv[1:])}`. Machine: {cpu_model()}, "
            f"shared with other jobs; load average (1/5/15 min) at the start {load_average()}. Each run is "
            f"`python {' '.join(SUITE[1:])}` from the checkout, `-n 0` on the one-process side; CPU s = user + system "
            "of the run and its workers. Caches warm (kernels, compiled controllers). Rounds interleave the "
            "sides (two workers first); times are medians, the ratio the median of the rounds' ratios.")
    if o.warmup:
        run("two workers")
    runs = []
    for rnd in range(o.rounds):
        for side in SIDES:
            runs.append({"round": rnd, **run(side)})
            print(runs[-1], flush=True)
    raw = pd.DataFrame(runs)
    wall = raw.pivot(index="round", columns="side", values="wall_s")
    ratios = (wall["one process"] / wall["two workers"]).to_numpy()
    table = raw.groupby("side", sort=False).agg(runs=("wall_s", "size"), wall_s=("wall_s", "median"),
                                                cpu_s=("cpu_s", "median"), passed=("passed", "max")).reset_index()
    table["one_process_wall_over_this"] = [float(np.median(ratios)), 1.0]
    table["ratio_range"] = [f"{ratios.min():.2f}-{ratios.max():.2f}", ""]
    write_table(table, f"suite_workers{o.tag}", "The test suite on two pytest-xdist workers against one process",
                note)
    raw.to_csv(os.path.join(ROOT, "benchmarks", "results", f"suite_workers{o.tag}_runs.csv"), index=False)


if __name__ == "__main__":
    main()
