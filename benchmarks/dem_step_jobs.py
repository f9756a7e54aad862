"""The calibration's DEM step on one process and on several, interleaved in one run: the wall time
of ``twin.calibration.dem_link.run_dem`` (full settings) for the ores asked, with ``jobs=1`` and
``jobs=N`` alternated (1, N, N, 1, ...) in fresh processes, each timed from the call (the kernels'
cache loaded and the workers started inside, as a user pays them). Every run's
record, less its wall times, must be the same: the file says so (and stops if not).

Writes benchmarks/results/dem_step_jobs.md and .csv (``--tag T``: dem_step_jobsT.md, .csv).

    python benchmarks/dem_step_jobs.py [--ores B] [--jobs 2] [--pairs 3] [--tag T]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from dem_common import COUNT, TAG, git_short, load_average, option_type, write_table  # noqa: E402

ROOT = HERE.parent
ORES = option_type(str, lambda o: o in ("A", "B", "C", "D"), "one of A, B, C, D", many=True)


#: the record's wall times, the only keys that may differ between runs
WALL_TIMES = ("wall_time_s", "dem_seconds")


def _untimed(record):
    """The record less its wall times (what must not depend on the number of processes)."""
    if isinstance(record, dict):
        return {k: _untimed(v) for k, v in record.items() if k not in WALL_TIMES}
    if isinstance(record, list):
        return [_untimed(v) for v in record]
    return record


def worker(ores: list[str], jobs: int) -> None:
    """One DEM step in this process: prints its wall time and the digest of its untimed record."""
    sys.path.insert(0, str(ROOT))
    from twin.calibration.dem_link import run_dem

    t0 = time.perf_counter()
    rec = run_dem(ores=tuple(ores), progress=False, workers=jobs)
    wall = time.perf_counter() - t0
    digest = hashlib.sha256(json.dumps(_untimed(rec), sort_keys=True).encode()).hexdigest()[:16]
    print(json.dumps({"wall_s": wall, "digest": digest}))


def _run(ores: list[str], jobs: int) -> dict:
    out = subprocess.run([sys.executable, __file__, "--worker", "--ores", ",".join(ores), "--jobs", str(jobs)],
                         check=True, capture_output=True, text=True, cwd=ROOT).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ores", type=ORES, default=["B"], help="reference ores of the DEM step (default B)")
    ap.add_argument("--jobs", type=COUNT, default=2, help="processes of the parallel side (default 2)")
    ap.add_argument("--pairs", type=COUNT, default=3, help="interleaved pairs (default 3)")
    ap.add_argument("--tag", type=TAG, default="", help="suffix of the result files")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker(args.ores, args.jobs)
        return pd.DataFrame()
    runs = {1: [], args.jobs: []}
    for p in range(args.pairs):
        for jobs in ((1, args.jobs) if p % 2 == 0 else (args.jobs, 1)):
            runs[jobs].append(_run(args.ores, jobs))
            print(jobs, runs[jobs][-1], flush=True)
    digests = {r["digest"] for rs in runs.values() for r in rs}
    if len(digests) != 1:
        raise SystemExit(f"the DEM step's records differ between runs (digests {sorted(digests)}): nothing written")
    one = np.array([r["wall_s"] for r in runs[1]])
    many = np.array([r["wall_s"] for r in runs[args.jobs]])
    ratio = one / many
    table = pd.DataFrame([{"ores": ",".join(args.ores), "jobs": args.jobs,
                           "one_process_s_median": float(np.median(one)),
                           f"{args.jobs}_processes_s_median": float(np.median(many)),
                           "speedup_median": float(np.median(ratio)), "speedup_min": float(ratio.min()),
                           "speedup_max": float(ratio.max()), "record_digest": digests.pop(),
                           "load_after": load_average()}])
    note = (f"Command: `python benchmarks/dem_step_jobs.py {shlex.join(argv if argv is not None else sys.argv[1:])}` "
            f"at {git_short(ROOT, 'HEAD')} (plus any uncommitted change). The DEM step (full settings) of the ores "
            f"named, on 1 process and on "
            f"{args.jobs}, {args.pairs} pairs alternated in fresh processes; speed-up = one process's wall time over "
            f"{args.jobs}'s, pair by pair. Every run gave the same record (its wall times aside). Machine: "
            f"{len(os.sched_getaffinity(0))} cores; load average (1/5/15 min) after the runs.")
    write_table(table, f"dem_step_jobs{args.tag}", "The DEM step on one process and on several, interleaved", note)
    return table


if __name__ == "__main__":
    main()
