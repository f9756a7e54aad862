"""What the DEM's first use costs: numba compiling the kernels on an empty cache, this checkout (B)
against an earlier revision ``--base`` (A, a temporary git worktree), alternated A, B, B, A, ...

Each run is a fresh interpreter with its own empty ``NUMBA_CACHE_DIR`` that does what a user's
first session does: 300 steps of a 500-sphere bonded agglomerate between platens (the
compression test's system), then the lab drum's ball charge (``dem.drum.drum_system``, 20 steps), and
prints how many signatures numba compiled of the step kernels (``run_steps``, ``compute_forces``):
each extra one is the whole step compiled again. Reports the wall time of each
run (almost all compilation), the median of A's time over B's over the pairs, and the signatures.

Writes benchmarks/results/dem_compile.md and .csv (``--tag T``: dem_compileT.md, .csv). Needs git.

    python benchmarks/dem_compile.py --base REV [--repeats 2] [--tag T]
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from dem_common import COUNT, TAG, base_worktree, cpu_model, git_short, load_average, write_table  # noqa: E402

#: the first session: a compression test, then the drum (numba compiles what each needs)
FIRST_USE = """
import json
import numpy as np
from dem import kernels as K
from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams, BondSet
from dem.drum import drum_system
from dem.materials import Material
from dem.system import PlaneWall, System
agg = make_agglomerate(0.022, 500, random_state=0)
bp = BondParams(kn_Pa_m=2e13, ks_Pa_m=8e12, tensile_strength_Pa=20e6, cohesion_Pa=40e6)
z_lo, z_hi = float(np.min(agg.pos_m[:, 2] - agg.radius_m)), float(np.max(agg.pos_m[:, 2] + agg.radius_m))
walls = [PlaneWall((0, 0, z_lo), (0, 0, 1)), PlaneWall((0, 0, z_hi), (0, 0, -1), (0, 0, -0.1))]
System(agg.pos_m.copy(), agg.radius_m, Material(), bonds=BondSet(agg.bond_pairs, agg.pos_m, agg.radius_m, bp),
       walls=walls, local_damping=0.7).run(300)
drum_system(0.7, 0.3, ball_diameter_m=0.04, section_length_m=0.1, random_state=2).system.run(20)
print(json.dumps([len(f.signatures) for f in (K.run_steps, K.compute_forces)]))
"""


def first_use(tree: str) -> tuple[float, list[int]]:
    """Wall time [s] of the first session from ``tree`` on an empty kernel cache, and the step
    kernels' signature counts."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(tree), NUMBA_NUM_THREADS="2")
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, "-c", FIRST_USE], env=env, check=True, capture_output=True,
                             text=True, cwd=cache).stdout
        wall = time.perf_counter() - t0
    return wall, json.loads(out.strip().splitlines()[-1])


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", required=True, help="git revision to compare against (A)")
    ap.add_argument("--repeats", type=COUNT, default="2", help="pairs of runs (default %(default)s)")
    ap.add_argument("--tag", type=TAG, default="", help="suffix of the result files (dem_compile{TAG}.md, .csv)")
    args = ap.parse_args(argv)
    head = git_short(ROOT, "HEAD")
    rows = []
    with base_worktree(ROOT, args.base) as (base, rev):
        for r in range(args.repeats):
            order = [("A", base), ("B", str(ROOT))]
            for side, tree in order if r % 2 == 0 else order[::-1]:
                wall, sigs = first_use(tree)
                rows.append({"pair": r, "side": side, "revision": rev if side == "A" else head, "wall_s": wall,
                             "signatures": "/".join(map(str, sigs)), "load_after": load_average()})
                print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    wall = table.pivot(index="pair", columns="side", values="wall_s")
    ratio = wall["A"] / wall["B"]
    note = (f"Command: `python benchmarks/dem_compile.py {shlex.join(sys.argv[1:] if argv is None else argv)}`. "
            f"A = {rev} (a worktree), B = this checkout ({head}, plus any uncommitted change); {cpu_model()}. "
            "Each run: a fresh interpreter, an empty NUMBA_CACHE_DIR, a 500-sphere agglomerate between platens "
            "(300 steps) "
            "then the drum (20 steps); wall time, nearly all of it numba compiling. signatures: how many numba "
            "compiled of run_steps / compute_forces. "
            f"**A's time over B's: median {np.median(ratio):.2f}x (pairs {ratio.min():.2f}-{ratio.max():.2f}); "
            f"median {wall['A'].median():.0f} s against {wall['B'].median():.0f} s.**")
    write_table(table, f"dem_compile{args.tag}",
                f"DEM kernels' first compilation: this checkout against {rev}, interleaved", note)
    return table


if __name__ == "__main__":
    main()
