"""What the hardness estimate costs on the le Roux case (benchmarks/mpc_leroux_case.py): the same
NMPC with the EKF's hardness replaced by the truth (the twin's survey-3 hardness scale times the
circuit's phi_f step, its value from ``delay`` h after the step; the EKF still estimates the mill
contents), against the EKF's own estimate, each over the PI's IAE on the same seeds. An ablation
that bounds what a better hardness estimator could buy, not a controller: no plant tells its
controller the ore's hardness.

Also, per seed, when the EKF's hardness estimate first reaches 50 % and 90 % of its final move
(the mean over the last hour) after the step: how long the P80 analyser (3 um noise, 0.1 h dead
time) takes to reveal the step through the closed loop.

Writes benchmarks/results/mpc_leroux_oracle.csv and .md.

    PYTHONPATH=. python benchmarks/mpc_leroux_oracle.py [--delays 0,0.1,0.2,0.3] [--seeds 1,...,10]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
import mpc_leroux_case as case_mod  # noqa: E402
from mpc_leroux_case import OUT, PHI_F_STEP, T_STEP_H, build_case, make_nmpc, make_pi, parser, run_one  # noqa: E402


def oracle_estimator(args, case, delay_h: float):
    """The case's EKF whose hardness is set to the truth after each update (its variance to ~0, so
    the filter does not pull it back): the survey-3 value until ``T_STEP_H + delay_h``, then times
    ``PHI_F_STEP``. The EKF also runs the warm-up, so its sample count starts at minus the warm-up."""
    est = case_mod.make_estimator(args, case)
    if not est.has_hardness:
        raise SystemExit("--disturbance-model must estimate the hardness for this ablation")
    k = [-int(round(args.warmup_h / args.dt_h))]
    step, h0, j = est.make_step, est.hardness_est, est.nx

    def make_step(y, u, d):
        step(y, u, d)
        est.z[j] = h0 * (PHI_F_STEP if k[0] * args.dt_h >= T_STEP_H + delay_h - 1e-9 else 1.0)
        est.P[j, :] = 0.0
        est.P[:, j] = 0.0
        est.P[j, j] = 1e-12
        k[0] += 1
        return est.x_est, np.r_[np.asarray(d, float)[: est.nd - 1], est.hardness_est]

    est.make_step = make_step
    return est


def reveal_times(frame: pd.DataFrame) -> tuple[float, float, float]:
    """Hours after the step at which the hardness estimate first covers 50 % and 90 % of its move
    to the last hour's mean, and its standard deviation over the last 4 h over that move."""
    before = frame.hardness_est[frame.time_h < T_STEP_H].iloc[-1]
    final = frame.hardness_est[frame.time_h >= frame.time_h.iloc[-1] - 1.0 - 1e-9].mean()
    after = frame[frame.time_h >= T_STEP_H]
    share = (after.hardness_est - before) / (final - before)
    late = frame.hardness_est[frame.time_h >= frame.time_h.iloc[-1] - 4.0 - 1e-9]
    return (*(float(after.time_h[share >= s].iloc[0] - T_STEP_H) if (share >= s).any() else np.nan
              for s in (0.5, 0.9)), float(late.std() / abs(final - before)))


def main(argv=None) -> pd.DataFrame:
    ap = parser()
    ap.add_argument("--delays", default="0,0.1,0.2,0.3", help="hours after the step the oracle's hardness moves")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    delays = [float(v) for v in args.delays.split(",")]
    case = build_case(args)
    ctrl = make_nmpc(args, case)
    rows = []
    for seed in (int(v) for v in args.seeds.split(",")):
        args.seed = seed
        pi_ctrl, _ = make_pi(args, case)
        pi = run_one(args, case, "pi", pi_ctrl, None)[0]["p80_iae_um_h"]
        for delay in [None, *delays]:
            ctrl.reset(case.u3)
            est = case_mod.make_estimator(args, case) if delay is None else oracle_estimator(args, case, delay)
            k, f = run_one(args, case, "nmpc", ctrl, est)
            t50, t90, wander = reveal_times(f) if delay is None else (np.nan,) * 3
            rows.append(dict(seed=seed, hardness="EKF" if delay is None else f"truth after {delay:g} h",
                             nmpc_iae_um_h=k["p80_iae_um_h"], pi_iae_um_h=pi, ratio=k["p80_iae_um_h"] / pi,
                             final_offset_um=k["final_offset_um"], ekf_50pct_after_h=t50, ekf_90pct_after_h=t90,
                             ekf_late_std_over_step=wander))
            print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / "mpc_leroux_oracle.csv", index=False)
    summary = table.groupby("hardness", sort=False).agg(
        ratio_median=("ratio", "median"), ratio_min=("ratio", "min"), ratio_max=("ratio", "max"),
        nmpc_iae_median_um_h=("nmpc_iae_um_h", "median"),
        final_offset_max_abs_um=("final_offset_um", lambda s: s.abs().max()))
    ekf = table[table.hardness == "EKF"]
    md = ["# le Roux case: what the hardness estimate costs", "",
          f"The case's NMPC (defaults of benchmarks/mpc_leroux_case.py) with its EKF's hardness, and with the "
          f"hardness set to the truth from a delay after the step (phi_f x {PHI_F_STEP} at {T_STEP_H} h); "
          f"ratio = NMPC IAE / PI IAE on the same seed ({args.seeds}).", "",
          summary.reset_index().to_markdown(index=False, floatfmt=".3g"), "",
          f"The EKF's hardness estimate reaches 50 % of its move after the step in "
          f"{ekf.ekf_50pct_after_h.median():.2f} h (median; {ekf.ekf_50pct_after_h.min():.2f}-"
          f"{ekf.ekf_50pct_after_h.max():.2f}) and 90 % in {ekf.ekf_90pct_after_h.median():.2f} h "
          f"({ekf.ekf_90pct_after_h.min():.2f}-{ekf.ekf_90pct_after_h.max():.2f}); over the last 4 h its standard "
          f"deviation is {ekf.ekf_late_std_over_step.median():.2f} of the step's size (median over the seeds).", "",
          "Reproduce: `" + " ".join(["PYTHONPATH=. python benchmarks/mpc_leroux_oracle.py",
                                      *(sys.argv[1:] if argv is None else argv)]) + "`."]
    (OUT / "mpc_leroux_oracle.md").write_text("\n".join(md) + "\n")
    return table


if __name__ == "__main__":
    main()
