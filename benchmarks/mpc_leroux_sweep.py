"""The sweep that chooses the NMPC's weights and the EKF's hardness walk on the le Roux case
(benchmarks/mpc_leroux_case.py): every combination of the grids below, the NMPC + EKF on the
tuning seeds only (default 1-10; the held-out seeds 11-20 are the benchmark's own check,
``--seeds 11,...,20 --tag _heldout``), scored by the median over the seeds of the NMPC's IAE over
the PI's (the PI's runs do not depend on the grid: one per seed). Everything else is the case's
default (``python benchmarks/mpc_leroux_case.py --help``), the matched twin identified once.

Writes benchmarks/results/mpc_leroux_sweep.csv (one row per combination: median, mean and worst
ratio, per-seed ratios, largest last-hour offset) and .md (the best 15, and where the case's
defaults rank: a combination that leads on the tuning seeds by less than their spread is not
adopted unless it also leads on the held-out seeds). ``--from-csv`` rewrites the .md from the
.csv of an earlier sweep (the PI's runs and the identification redone: seconds).

    PYTHONPATH=. python benchmarks/mpc_leroux_sweep.py [--seeds 1,...,10] [--weight-p80 10,20,40]
        [--hardness-noise 0.1,0.15,0.2,0.3] [--weight-du-feed 0.3,1,3] [--weight-du-speed 3,10,30]
        [--from-csv]
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from mpc_leroux_case import OUT, build_case, make_estimator, make_nmpc, make_pi, parser, run_one  # noqa: E402

GRID = {"weight_p80": "10,20,40", "hardness_noise": "0.1,0.15,0.2,0.3", "weight_du_feed": "0.3,1,3",
        "weight_du_speed": "3,10,30"}


def pi_iae(args, case, seeds) -> dict[int, float]:
    """The PI's IAE per seed."""
    out = {}
    for seed in seeds:
        args.seed = seed
        ctrl, _ = make_pi(args, case)
        out[seed] = run_one(args, case, "pi", ctrl, None)[0]["p80_iae_um_h"]
    return out


def score(args, case, seeds, pi: dict[int, float]) -> dict:
    """The NMPC + EKF at ``args`` over ``seeds``: ratios to the PI's IAE and the worst offset."""
    ctrl = make_nmpc(args, case)
    ratios, offsets = [], []
    for seed in seeds:
        args.seed = seed
        ctrl.reset(case.u3)
        k, _ = run_one(args, case, "nmpc", ctrl, make_estimator(args, case))
        ratios.append(k["p80_iae_um_h"] / pi[seed])
        offsets.append(abs(k["final_offset_um"]))
    r = pd.Series(ratios)
    return {"ratio_median": r.median(), "ratio_mean": r.mean(), "ratio_max": r.max(),
            "final_offset_max_abs_um": max(offsets), "ratios": " ".join(f"{v:.3f}" for v in ratios)}


def main(argv=None) -> pd.DataFrame:
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1,2,3,4,5,6,7,8,9,10", help="tuning seeds")
    for name, grid in GRID.items():
        ap.add_argument(f"--{name.replace('_', '-')}", default=grid, help=f"grid of the case's --{name}")
    ap.add_argument("--from-csv", action="store_true", help="rewrite the .md from the .csv of an earlier sweep")
    sweep = ap.parse_args(argv)
    args = parser().parse_args([])
    seeds = [int(v) for v in sweep.seeds.split(",")]
    grids = {name: [float(v) for v in getattr(sweep, name).split(",")] for name in GRID}
    case = build_case(args)
    pi = pi_iae(args, case, seeds)
    if sweep.from_csv:
        table = pd.read_csv(OUT / "mpc_leroux_sweep.csv")
    else:
        rows = []
        t0 = time.perf_counter()
        for values in itertools.product(*grids.values()):
            for name, v in zip(grids, values):
                setattr(args, name, v)
            rows.append(dict(zip(grids, values)) | score(args, case, seeds, pi))
            print(rows[-1], f"({time.perf_counter() - t0:.0f} s)", flush=True)
        table = pd.DataFrame(rows).sort_values(["ratio_median", "ratio_mean"], ignore_index=True)
        OUT.mkdir(exist_ok=True)
        table.to_csv(OUT / "mpc_leroux_sweep.csv", index=False)
    (OUT / "mpc_leroux_sweep.md").write_text(markdown(table, grids, sweep.seeds, seeds, pi, case.notes, argv))
    return table


def defaults_line(table: pd.DataFrame, grids: dict) -> str:
    """Where the case's defaults (``mpc_leroux_case.py --help``) rank in ``table``."""
    d = parser().parse_args([])
    flags = ", ".join(f"--{n.replace('_', '-')} {getattr(d, n):g}" for n in grids)
    hit = (table[list(grids)] == [getattr(d, n) for n in grids]).all(axis=1)
    if not hit.any():
        return f"The case's defaults ({flags}) are not on this grid."
    k = int(hit.idxmax())
    return (f"The case's defaults ({flags}): rank {k + 1} of {len(table)}, median "
            f"{table.loc[k, 'ratio_median']:.4g}, mean {table.loc[k, 'ratio_mean']:.4g}.")


def markdown(table, grids, seeds_arg, seeds, pi, notes, argv) -> str:
    best = table.iloc[0]
    md = ["# le Roux case: the NMPC's weights and the EKF's hardness walk, swept on the tuning seeds", "",
          f"Seeds {seeds_arg}; NMPC IAE over the PI's per seed (PI IAE "
          f"{', '.join(f'{pi[s]:.3g}' for s in seeds)} um*h); {len(table)} combinations, sorted by the median "
          "ratio (then the mean). Everything else at the case's defaults; the matched twin as identified:", "",
          *[f"- {n}" for n in notes], "",
          "Best on these seeds (first row): " + ", ".join(f"--{n.replace('_', '-')} {best[n]:g}" for n in grids)
          + ". " + defaults_line(table, grids), "",
          table.head(15).to_markdown(index=False, floatfmt=".4g"), "",
          f"Reproduce: `{' '.join(['PYTHONPATH=. python benchmarks/mpc_leroux_sweep.py', *(a for a in argv if a != '--from-csv')])}`."]
    return "\n".join(md) + "\n"


if __name__ == "__main__":
    main()
