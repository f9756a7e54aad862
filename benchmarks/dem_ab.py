"""A DEM kernel change against an earlier revision, interleaved in one run: the compression test's
loading phase (the same packing), the drum and a drop-weight test that breaks an agglomerate
(``--drop``, energies J/kg; most of its steps after the damage), each by this checkout's
benchmarks/dem_parallel_worker.py on this checkout's dem/ (B) and on that of a temporary git
worktree of ``--base`` (A), alternating A, B, B, A, ... in fresh processes (each loads its own
tree's cached kernels). Reports the median over pairs of A's wall time over B's and of A's CPU
time over B's (above 1: this checkout is faster) at 1 and 2 threads. On one thread the CPU time is
the steadier measure on a shared machine (time the hypervisor gives to others is not counted); on
two it includes OpenMP's spinning at barriers.

Writes benchmarks/results/dem_ab.md and .csv (``--tag T``: dem_abT.md, .csv). Needs git; the
worktree is made in a temporary folder and removed afterwards.

    python benchmarks/dem_ab.py --base REV [--sizes 500,2000,8000] [--drop 300,5000] [--repeats 9] [--tag T]
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from dem_common import LOADING_STEPS, TAG, base_worktree, git_short, load_average, write_pack, write_table  # noqa: E402

DRUM = {504: (0.025, 0.1, 20000), 1512: (0.025, 0.3, 12000), 8064: (0.0125, 0.2, 3000)}
DROP_SPHERES = 150  # the DEM calibration step's agglomerate (twin.calibration.dem_link.SPHERES)


def run(tree: Path, args: list[str], threads: int) -> tuple[float, float]:
    """Wall and CPU time [s] (all threads) of the timed steps of one process of this checkout's
    worker on ``tree``'s dem/ (the same driver on both sides; it says which dem/ it ran)."""
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS="1", DEM_TREE=str(tree))
    out = subprocess.run([sys.executable, str(HERE / "dem_parallel_worker.py"), *args], env=env,
                         check=True, capture_output=True, text=True).stdout
    res = json.loads(out.strip().splitlines()[-1])
    if Path(res["dem"]).resolve() != (tree / "dem").resolve():
        raise RuntimeError(f"the worker ran {res['dem']}, not {tree / 'dem'}: the comparison would be void")
    return float(res["wall_s"]), float(res["cpu_s"])


def compare(base: Path, args: list[str], threads: int, repeats: int) -> dict:
    """A (base) and B (this checkout) alternated, one warm-up each (compiles or loads the cache)."""
    run(base, args, threads), run(ROOT, args, threads)
    ta, tb = [], []
    for r in range(repeats):
        order = (base, ROOT) if r % 2 == 0 else (ROOT, base)
        t = {tree: run(tree, args, threads) for tree in order}
        ta.append(t[base])
        tb.append(t[ROOT])
    ta, tb = np.array(ta), np.array(tb)  # columns: wall, CPU
    r = ta / tb
    return {"threads": threads, "base_wall_s_median": float(np.median(ta[:, 0])),
            "this_wall_s_median": float(np.median(tb[:, 0])), "wall_ratio_median": float(np.median(r[:, 0])),
            "wall_ratio_min": float(np.min(r[:, 0])), "wall_ratio_max": float(np.max(r[:, 0])),
            "cpu_ratio_median": float(np.median(r[:, 1])), "cpu_ratio_min": float(np.min(r[:, 1])),
            "cpu_ratio_max": float(np.max(r[:, 1])), "load_after": load_average()}


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="git revision to compare against (A)")
    ap.add_argument("--sizes", default="500,2000,8000", help="sphere counts of the compression test")
    ap.add_argument("--drum", default="1512,8064", help=f"ball counts of the drum ({', '.join(map(str, DRUM))})")
    ap.add_argument("--drop", default="", help=f"specific energies, J/kg, of drop-weight tests on a "
                    f"{DROP_SPHERES}-sphere agglomerate")
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--tag", type=TAG, default="", help="suffix of the result files (dem_ab{TAG}.md, .csv)")
    args = ap.parse_args(argv)
    sizes = [int(v) for v in args.sizes.split(",") if v]
    drums = [int(v) for v in args.drum.split(",") if v]
    try:
        drops = [float(v) for v in args.drop.split(",") if v]
    except ValueError:
        ap.error(f"--drop {args.drop!r}: not a comma-separated list of numbers (J/kg). Nothing written.")
    bad = [f"--sizes {n} (choose from {sorted(LOADING_STEPS)})" for n in sizes if n not in LOADING_STEPS]
    bad += [f"--drum {n} (choose from {sorted(DRUM)})" for n in drums if n not in DRUM]
    if args.repeats < 1:
        bad.append(f"--repeats {args.repeats} (at least 1)")
    bad += [f"--drop {e:g} (a specific energy, J/kg, above 0)" for e in drops if not e > 0.0]
    if not sizes + drums + drops:
        bad.append("--sizes, --drum and --drop all empty (nothing to compare)")
    if bad:
        ap.error("; ".join(bad) + ". Nothing written.")
    head = git_short(ROOT, "HEAD")
    rows = []
    with base_worktree(ROOT, args.base) as (base, rev), tempfile.TemporaryDirectory() as tmp:
        base = Path(base)
        cases = [(f"compression {n} spheres", [pack, repr(dt), str(LOADING_STEPS[n])])
                 for n in sizes for _, pack, dt in [write_pack(n, 0, tmp)]]
        cases += [(f"drum {n} balls", ["drum", repr(DRUM[n][0]), repr(DRUM[n][1]), str(DRUM[n][2])])
                  for n in drums]
        cases += [(f"drop weight {DROP_SPHERES} spheres {e:g} J/kg", ["drop", str(DROP_SPHERES), repr(e)])
                  for e in drops]
        for name, worker_args in cases:
            for threads in (1, 2):
                rows.append({"case": name, **compare(base, worker_args, threads, args.repeats)})
                print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    note = (f"Command: `python benchmarks/dem_ab.py {shlex.join(argv if argv is not None else sys.argv[1:])}`. "
            f"A = {rev} (a worktree), B = this checkout ({head}, plus any uncommitted change); {args.repeats} pairs "
            f"per row, alternated in fresh processes; ratios = A's wall (CPU) time over B's (above 1: B faster). Machine: "
            f"2 cores; load average (1/5/15 min) after each row.")
    write_table(table, f"dem_ab{args.tag}", f"DEM kernels: this checkout against {rev}, interleaved", note)
    return table


if __name__ == "__main__":
    main()
