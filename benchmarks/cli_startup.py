"""How fast the command line answers: whole ``grindtwin`` processes, wall time, this checkout
against an earlier revision, interleaved.

Commands (each a fresh Python process; ``--commands`` chooses, default the start-up set):
- ``help``: ``grindtwin --help``;
- ``surrogate``: ``grindtwin steady --surrogate --ore B --feed-tph 0.031 --speed 0.70``;
- ``twin``: ``grindtwin steady --ore B --feed-tph 0.031 --speed 0.70`` (builds the CasADi twin);
- ``check``: ``grindtwin check scenarios/reference_transition.toml`` (this checkout's scene on both
  sides: a revision too old to read it fails, and says so);
- ``optimize``: ``grindtwin optimize --ore A --target-p80-um 134 --json`` (some 2,000 steady
  states: the steady-state Newton's cost), not in the default set;
- ``size-mill``: ``grindtwin size-mill`` of the industrial preset (``--ore B --feed-tph 31
  --target-p80-um 210 --speed 0.7``: some 40 twins built and solved), not in the default set;
- ``size-mill-molycop``: ``grindtwin size-mill`` at Moly-Cop BallSim's base case (``--feed-tph 504
  --target-p80-um 169.4 --cyclone-pressure-kpa 53.09``, its 7.7 psi: six cyclone counts tried), likewise;
- floors: ``python -c pass`` (the interpreter) and ``python -c "import numpy"``.
Each runs from this checkout ("now") and from ``--before REV``
(default: the commit before the fast start, 757bf8f), exported by ``git archive``. Both sides
run the same way: ``python -c "from scenarios.cli import main; ..."`` with the tree first on
``sys.path`` (a ``.pth`` file in a throwaway venv that also sees this venv's libraries), so the
two differ only in their code. Every round runs every command once, in a fixed interleaved
order (now, before, now, before, ...); the table gives medians over ``--rounds`` rounds and the
median of the rounds' ratios. The machine is 2 cores shared with other jobs: times are upper bounds.

Writes ``benchmarks/results/cli_startup{TAG}.csv`` (every timing) and ``.md``.

Run: ``python benchmarks/cli_startup.py [--rounds 15] [--before REV] [--commands a,b] [--tag TAG]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from dem_common import TAG

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
DEFAULT_BEFORE = "757bf8f"
STEADY = ["steady", "--ore", "B", "--feed-tph", "0.031", "--speed", "0.70"]
COMMANDS = {"help": ["--help"], "surrogate": [*STEADY, "--surrogate"], "twin": STEADY,
            "check": ["check", str(ROOT / "scenarios" / "reference_transition.toml")],
            "optimize": ["optimize", "--ore", "A", "--target-p80-um", "134", "--json"],
            "size-mill": ["size-mill", "--ore", "B", "--feed-tph", "31", "--target-p80-um", "210", "--speed", "0.7"],
            "size-mill-molycop": ["size-mill", "--ore", "B", "--feed-tph", "504", "--target-p80-um", "169.4",
                                  "--speed", "0.7", "--cyclone-pressure-kpa", "53.09"]}
#: The commands run without --commands: the start-up set.
STARTUP = ("help", "surrogate", "twin", "check")
MAIN = "import sys; from scenarios.cli import main; sys.exit(main(sys.argv[1:]))"
FLOORS = {"python -c pass": "pass", "python -c 'import numpy'": "import numpy"}


def tree_python(tree: Path, venvs: Path, name: str) -> Path:
    """A venv's python that imports grindtwin from ``tree`` and every library from this venv."""
    env = venvs / name
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env)], check=True)
    site = Path(sysconfig.get_paths(vars={"base": str(env), "platbase": str(env)})["purelib"])
    (site / "grindtwin_tree.pth").write_text(f"{tree}\n{sysconfig.get_paths()['purelib']}\n")
    return env / "bin" / "python"


def export(rev: str, where: Path) -> Path:
    where.mkdir(parents=True)
    archive = subprocess.run(["git", "archive", rev, "dem", "twin", "mpc", "scenarios"], cwd=ROOT,
                             check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(where)], input=archive, check=True)
    return where


def wall(cmd: list[str], cwd: Path) -> float:
    """Seconds of one process, run in ``cwd`` (not a tree: ``python -c`` puts the folder first on
    sys.path)."""
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, cwd=cwd)
    dt = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {res.stderr.decode()[-400:]}")
    return dt


def _commands(text: str) -> tuple:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in COMMANDS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown command(s) {', '.join(unknown) or '(none)'}; "
                                         f"known: {', '.join(COMMANDS)}")
    return names


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--before", default=DEFAULT_BEFORE, help="the revision to compare with")
    ap.add_argument("--commands", default=",".join(STARTUP), type=_commands,
                    help=f"comma-separated, of {', '.join(COMMANDS)}")
    ap.add_argument("--tag", default="", type=TAG, help="suffix of the result files")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="cli-startup-") as tmp:
        tmp = Path(tmp)
        sides = {"now": tree_python(ROOT, tmp, "now"),
                 "before": tree_python(export(args.before, tmp / "before"), tmp, "before")}
        runs = [(name, side, [str(py), "-c", MAIN, *COMMANDS[name]]) for name in args.commands
                for side, py in sides.items()]
        runs += [(name, "floor", [sys.executable, "-c", code]) for name, code in FLOORS.items()]
        for _, _, cmd in runs:  # warm the file cache and the bytecode of both trees
            wall(cmd, tmp)
        rows = [{"round": r, "command": name, "side": side, "wall_s": wall(cmd, tmp)}
                for r in range(args.rounds) for name, side, cmd in runs]
    df = pd.DataFrame(rows)
    RESULTS.mkdir(exist_ok=True)
    df.to_csv(RESULTS / f"cli_startup{args.tag}.csv", index=False)
    (RESULTS / f"cli_startup{args.tag}.md").write_text(summary(df, args), encoding="utf-8")
    print(summary(df, args))
    return 0


def summary(df: pd.DataFrame, args) -> str:
    med = df.groupby(["command", "side"])["wall_s"].median().unstack()
    q = df.groupby(["command", "side"])["wall_s"].quantile(0.9).unstack()
    lines = ["# Command line: wall time of whole processes", "",
             f"`python benchmarks/cli_startup.py --rounds {args.rounds} --before {args.before}"
             + (f" --commands {','.join(args.commands)}" if args.commands != STARTUP else "")
             + (f" --tag {args.tag}" if args.tag else "") + "`; "
             f"{platform.python_version()}, {os.cpu_count()} cores shared with other jobs (upper bounds). "
             "Medians (90th percentile) over the rounds, every command once a round, interleaved; now / before: "
             "the median of the rounds' ratios.", "",
             "| command | now [s] | before [s] | now / before |", "|---|---|---|---|"]
    for name in [*args.commands, *FLOORS]:
        side = "now" if name in COMMANDS else "floor"
        now, qn = med.loc[name, side], q.loc[name, side]
        before, qb = med.loc[name].get("before", np.nan), q.loc[name].get("before", np.nan)
        b = f"{before:.3f} ({qb:.3f})" if np.isfinite(before) else "-"
        pairs = df[df.command == name].pivot_table(index="round", columns="side", values="wall_s")
        ratio = f"{(pairs['now'] / pairs['before']).median():.2f}" if np.isfinite(before) else "-"
        lines.append(f"| `{name}` | {now:.3f} ({qn:.3f}) | {b} | {ratio} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
