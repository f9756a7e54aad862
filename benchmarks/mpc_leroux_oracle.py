"""What the hardness estimate costs on the le Roux case (benchmarks/mpc_leroux_case.py): the same
NMPC with the EKF's hardness replaced by the truth (the twin's survey-3 hardness scale times the
circuit's phi_f step, its value from ``delay`` h after the step; the EKF still estimates the mill
contents), against the EKF's own estimate, each over the PI's IAE on the same seeds. An ablation
that bounds what a better hardness estimator could buy, not a controller: no plant tells its
controller the ore's hardness.

And a change detector in front of the EKF (``EKF + change detector``): ore hardness drifts slowly
within a pit and jumps at an ore change, so the hardness walks at the estimator's default
intensity (:data:`mpc.estimator.HARDNESS_NOISE_PER_SQRT_H`) and a two-sided CUSUM of the
analyser's innovation signals a jump (:class:`mpc.ChangeDetector`).

Where the IAE is spent: each run's IAE split into three windows, before the step (0-1 h), the
transient (1-3 h) and the settled hours (3 h to the end), for the PI and every NMPC variant.

Also, per seed, when the EKF's hardness estimate first reaches 50 % and 90 % of its final move
(the mean over the last hour) after the step: how long the P80 analyser (3 um noise, 0.1 h dead
time) takes to reveal the step through the closed loop.

Writes benchmarks/results/mpc_leroux_oracle.csv and .md (``--tag T``: mpc_leroux_oracleT.csv, .md).

    PYTHONPATH=. python benchmarks/mpc_leroux_oracle.py [--delays 0,0.1,0.2,0.3] [--seeds 1,...,10] [--tag T]
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
import mpc_leroux_case as case_mod  # noqa: E402
from mpc_leroux_case import OUT, PHI_F_STEP, T_STEP_H, build_case, make_nmpc, make_pi, parser, run_one  # noqa: E402

from mpc.estimator import HARDNESS_NOISE_PER_SQRT_H  # noqa: E402
from mpc.kpis import p80_iae_um_h  # noqa: E402

#: the transient window's length after the step [h]: the circuit's mean response time to a feed step is 1.37 h
TRANSIENT_H = 2.0


def detecting_estimator(args, case):
    """The case's EKF with the hardness walking at the default intensity and the change detector
    (:class:`mpc.ChangeDetector`, its defaults) in front of it: ``mpc_leroux_case.py --hardness-noise 0.03
    --change-detector``."""
    return case_mod.make_estimator(SimpleNamespace(**{**vars(args), "hardness_noise": HARDNESS_NOISE_PER_SQRT_H,
                                                      "change_detector": True}), case)


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


def window_iae(frame: pd.DataFrame) -> dict:
    """The run's P80 IAE [um h] before the step, over the transient (``TRANSIENT_H`` after it) and
    over the settled hours after that (the run's trapezoid IAE, :func:`mpc.kpis.p80_iae_um_h`,
    over each window's samples; the three add up to the run's IAE)."""
    t = frame.time_h.to_numpy(float)
    edges = [t[0], T_STEP_H, T_STEP_H + TRANSIENT_H, t[-1]]
    out = {}
    for name, a, b in zip(("iae_before_um_h", "iae_transient_um_h", "iae_settled_um_h"), edges[:-1], edges[1:]):
        m = (t >= a - 1e-9) & (t <= b + 1e-9)
        out[name] = p80_iae_um_h(t[m], frame.p80_um.to_numpy(float)[m], frame.p80_target_um.to_numpy(float)[m])
    return out


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
        k_pi, f_pi = run_one(args, case, "pi", pi_ctrl, None)
        pi = k_pi["p80_iae_um_h"]
        rows.append(dict(seed=seed, hardness="PI (no model)", nmpc_iae_um_h=np.nan, pi_iae_um_h=pi, ratio=1.0,
                         final_offset_um=k_pi["final_offset_um"], **window_iae(f_pi)))
        for delay in ["EKF", "EKF + change detector", *delays]:
            ctrl.reset(case.u3)
            est = (case_mod.make_estimator(args, case) if delay == "EKF" else detecting_estimator(args, case)
                   if isinstance(delay, str) else oracle_estimator(args, case, delay))
            k, f = run_one(args, case, "nmpc", ctrl, est)
            t50, t90, wander = reveal_times(f) if delay == "EKF" else (np.nan,) * 3
            rows.append(dict(seed=seed, hardness=delay if isinstance(delay, str) else f"truth after {delay:g} h",
                             nmpc_iae_um_h=k["p80_iae_um_h"], pi_iae_um_h=pi, ratio=k["p80_iae_um_h"] / pi,
                             final_offset_um=k["final_offset_um"], ekf_50pct_after_h=t50, ekf_90pct_after_h=t90,
                             ekf_late_std_over_step=wander, **window_iae(f)))
            print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / f"mpc_leroux_oracle{args.tag}.csv", index=False)
    summary = table.groupby("hardness", sort=False).agg(
        ratio_median=("ratio", "median"), ratio_min=("ratio", "min"), ratio_max=("ratio", "max"),
        nmpc_iae_median_um_h=("nmpc_iae_um_h", "median"),
        final_offset_max_abs_um=("final_offset_um", lambda s: s.abs().max()),
        iae_before_median_um_h=("iae_before_um_h", "median"),
        iae_transient_median_um_h=("iae_transient_um_h", "median"),
        iae_settled_median_um_h=("iae_settled_um_h", "median"))
    ekf = table[table.hardness == "EKF"]
    md = ["# le Roux case: what the hardness estimate costs", "",
          f"The case's NMPC (defaults of benchmarks/mpc_leroux_case.py) with its EKF's hardness, and with the "
          f"hardness set to the truth from a delay after the step (phi_f x {PHI_F_STEP} at {T_STEP_H} h); "
          f"ratio = NMPC IAE / PI IAE on the same seed ({args.seeds}).", "",
          summary.reset_index().to_markdown(index=False, floatfmt=".3g"), "",
          f"The IAE's windows: before the step (0-{T_STEP_H:g} h), the transient ({T_STEP_H:g}-"
          f"{T_STEP_H + TRANSIENT_H:g} h) and the settled hours ({T_STEP_H + TRANSIENT_H:g} h to the end), medians "
          "over the seeds; the PI's row is the PI itself (its IAE in nmpc_iae is empty).", "",
          f"The EKF's hardness estimate reaches 50 % of its move after the step in "
          f"{ekf.ekf_50pct_after_h.median():.2f} h (median; {ekf.ekf_50pct_after_h.min():.2f}-"
          f"{ekf.ekf_50pct_after_h.max():.2f}) and 90 % in {ekf.ekf_90pct_after_h.median():.2f} h "
          f"({ekf.ekf_90pct_after_h.min():.2f}-{ekf.ekf_90pct_after_h.max():.2f}); over the last 4 h its standard "
          f"deviation is {ekf.ekf_late_std_over_step.median():.2f} of the step's size (median over the seeds).", "",
          "Reproduce: `" + " ".join(["PYTHONPATH=. python benchmarks/mpc_leroux_oracle.py",
                                      *(sys.argv[1:] if argv is None else argv)]) + "`."]
    (OUT / f"mpc_leroux_oracle{args.tag}.md").write_text("\n".join(md) + "\n")
    return table


if __name__ == "__main__":
    main()
