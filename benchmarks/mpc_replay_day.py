"""The shipped one-day replay with the NMPC in the loop, as a user runs it: wall time, CPU time and
peak memory of the whole command (imports, model and controller builds, 480 closed-loop samples,
writing the results). Goal (issue 14): under 5 minutes and 4 GB on this 2-core machine.

    grindtwin replay scenarios/replay_day.toml --history scenarios/data/sample_history.csv --out DIR

The command runs in a subprocess; CPU time and peak RSS are the child's (getrusage). The machine
is shared, so the load average at the start and the end is recorded beside the wall time: the
CPU time is what the replay itself needs.

Writes benchmarks/results/mpc_replay_day.md and .csv. Run: python benchmarks/mpc_replay_day.py
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results"
COMMAND = [sys.executable, "-c", "import sys; from scenarios.cli import main; sys.exit(main())", "replay",
           "scenarios/replay_day.toml", "--history", "scenarios/data/sample_history.csv", "--quiet"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "replay_day"
        load0 = os.getloadavg()[0]
        t0 = time.perf_counter()
        proc = subprocess.run([*COMMAND, "--out", str(out)], cwd=ROOT, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        load1 = os.getloadavg()[0]
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode != 0:
            raise SystemExit(f"the replay failed:\n{proc.stderr[-3000:]}")
        summary = json.loads((out / "summary.json").read_text())
    k = summary["kpis"]
    row = {"wall_s": round(wall, 1), "cpu_s": round(usage.ru_utime + usage.ru_stime, 1),
           "peak_rss_mb": round(usage.ru_maxrss / 1024), "load_avg_start": load0, "load_avg_end": load1,
           "samples": summary["controller_health"]["steps"], "p80_iae_um_h": round(k["p80_iae_um_h"], 3),
           "p80_within_10um_frac": k["p80_within_10um_frac"], "solve_time_median_s": k["solve_time_median_s"],
           "controller_failed_steps": k["controller_failed_steps"], "mass_balance_error": k["mass_balance_error"]}
    table = pd.DataFrame([row])
    RESULTS.mkdir(exist_ok=True)
    table.to_csv(RESULTS / "mpc_replay_day.csv", index=False)
    lines = ["# replay_day.toml with the NMPC: the whole command", "",
             "`python benchmarks/mpc_replay_day.py` (runs `grindtwin replay scenarios/replay_day.toml --history "
             "scenarios/data/sample_history.csv --out DIR`). CPU time and peak RSS are the command's; the "
             "wall time depends on the machine's load (its 1-min load average on 2 cores is given).", "",
             table.to_markdown(index=False, floatfmt=".4g"), ""]
    (RESULTS / "mpc_replay_day.md").write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
