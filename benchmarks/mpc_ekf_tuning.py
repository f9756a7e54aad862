"""How fast the EKF's hardness estimate should move: analyser noise against disturbance rejection.

The EKF's hardness random walk (``hardness_noise_per_sqrt_h``) is its disturbance model; larger
values follow an unmeasured hardness change faster but pass more of the P80 analyser's noise
(3 um) to the NMPC's inputs. Two cases on the reference plant (benchmarks/mpc_reference_case.py):

- ``transition``: the reference case (the ore change is measured by the belt analyser);
- ``hardness_step``: the same, plus an *unmeasured* +10 % hardness step of the plant at 5 h.

For each intensity: NMPC with preview (RTI) IAE, max error and the error after the step; the PI
baseline of the case beside it (it has no estimator). Writes
benchmarks/results/mpc_ekf_tuning.csv and .md.

    PYTHONPATH=. python benchmarks/mpc_ekf_tuning.py [--noises 0.01,0.02,0.03,0.05,0.1]
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

import pandas as pd

from mpc_reference_case import OUT, add_case_arguments, run_case

STEP_AT_H, STEP_FACTOR = 5.0, 1.10


def plant_step(t_h: float) -> float:
    return STEP_FACTOR if t_h >= STEP_AT_H else 1.0


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_case_arguments(ap)
    ap.add_argument("--noises", default="0.01,0.02,0.03,0.05,0.1")
    args = ap.parse_args(argv)
    rows = []
    for case, hardness in (("transition", 1.0), ("hardness_step", plant_step)):
        args.only = "pi"
        pi = run_case(args, plant_hardness=hardness, write=False).iloc[0]
        rows.append({"case": case, "controller": "pi", "hardness_noise_per_sqrt_h": float("nan"),
                     "p80_iae_um_h": pi.p80_iae_um_h, "p80_max_abs_err_um": pi.p80_max_abs_err_um})
        for noise in (float(v) for v in args.noises.split(",")):
            args.only, args.hardness_noise = "nmpc_preview", noise
            k = run_case(args, plant_hardness=hardness, write=False).iloc[0]
            rows.append({"case": case, "controller": "nmpc_preview",
                         "hardness_noise_per_sqrt_h": noise, "p80_iae_um_h": k.p80_iae_um_h,
                         "p80_max_abs_err_um": k.p80_max_abs_err_um,
                         "iae_ratio_to_pi": k.p80_iae_um_h / pi.p80_iae_um_h})
            print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / "mpc_ekf_tuning.csv", index=False)
    md = ["# EKF hardness random walk: analyser noise against disturbance rejection", "",
          f"Reference case ({args.duration_h} h, seed {args.seed}, solver {args.solver}); "
          f"'hardness_step' adds an unmeasured x{STEP_FACTOR} plant hardness at {STEP_AT_H} h.",
          "", table.to_markdown(index=False, floatfmt=".4g")]
    (OUT / "mpc_ekf_tuning.md").write_text("\n".join(md) + "\n")
    return table


if __name__ == "__main__":
    main()
