"""The twin-based controller on a plant nobody here designed (issue 5): the run-of-mine milling
circuit of le Roux, Craig, Hulbert & Hinde (2013, Minerals Engineering 43-44, 121-134) with its
published parameters (:class:`mpc.plants.leroux.LeRouxCircuit`), P80 from its fines fraction PSE by a
Gates-Gaudin-Schuhmann assumption (modulus 0.8), ore hardness as its energy per tonne of fines
phi_f.

Case: the circuit at its survey-3 steady state (65.2 t/h, 71.2 % of critical, P80 94.0 um),
then the ore turns harder: phi_f +15 % (29.6 -> 34.04 kWh/t) at t = 1 h (with ``--rock-step``
also a rock fraction 0.465 -> 0.55 at t = 4 h); 8 h, 3-min samples. Three controllers on the
same plant, sensors and seed: no control (survey-3 inputs held), PI P80 -> feed (SIMC on a
FOPDT fit of the circuit's linearised feed -> P80 response, analyser delay added:
:func:`mpc.closed_loop.pi_baseline` on the circuit), and the NMPC + EKF on the twin matched to
the circuit (:func:`mpc.plants.leroux.matched_twin`: its survey-3 power and P80, and what step
tests on the circuit give it: from the feed step test the PI is tuned on, a feed inventory with
the circuit's mean response time and the P80 gain correction the EKF reads the analyser through;
from a speed step test, the fraction of a speed or hardness change its breakage sees at once,
the rest through the charge (effect ``charge_lag``). ``--feed-inventory-h 0``, ``--p80-gain 1``
and ``--charge-fast-frac 1`` run the twin without each). The EKF is given the P80 analyser only: the
circuit's power (a ROM-mill power surface in filling and rheology) and its filling (balls,
rocks and water included) do not mean what the twin's power and load (ore hold-up over
nominal) mean, and with one integrating disturbance (the hardness) a second measurement that
the twin cannot match would leave a P80 offset (Muske & Badgwell 2002).

KPIs as in :func:`mpc.closed_loop.kpis` (the +-10 um band of the reference case), plus a band
scaled to this target (+-5 % of 94 um = +-4.7 um), and the final offset: mean P80 minus target
over the last hour (true plant P80, not the noisy analyser).

Writes benchmarks/results/mpc_leroux_case.csv (KPIs), .md (table) and mpc_leroux_case_runs.csv
(one row per sample, all runs); ``--seeds 1,2,3`` repeats the case over sensor-noise seeds (a
``seed`` column) and states the NMPC's IAE over the PI's per seed.

    PYTHONPATH=. python benchmarks/mpc_leroux_case.py [--duration-h 8] [--dt-h 0.05] [--seeds 1]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

from mpc import ChangeDetector, Ekf, FixedInputs, LoopSettings, Sensors, pi_baseline, run_closed_loop
from mpc.plants.leroux import LeRouxCircuit, LeRouxPlant, matched_twin
from mpc.nmpc import Controller, NmpcSettings
from dem_common import TAG

OUT = Path(__file__).parent / "results"
T_STEP_H = 1.0  # hardness step
PHI_F_STEP = 1.15  # phi_f x 1.15
T_ROCK_H, ROCK_FRAC = 4.0, 0.55  # optional rock-fraction step (survey 3: 0.465)
BAND_REL = 0.05  # the scaled band: +-5 % of target (+-10 um is +-4.8 % of the 210 um reference)
# Input limits on this circuit (ours): feed 40-80 t/h around the survey-3 65.2 t/h, moves up to
# 40 t/h per hour (the reference case's 20 t/h per h on a 30 t/h mill, scaled by throughput).
FEED_MIN, FEED_MAX, FEED_RATE = 40.0, 80.0, 40.0


def hardness(t_h: float) -> float:
    return PHI_F_STEP if t_h >= T_STEP_H else 1.0


def build_case(args) -> SimpleNamespace:
    """The circuit, the twin matched to it (identified from its step tests), the plant and the
    sensors of the case, built once for every run."""
    circuit = LeRouxCircuit()
    mt = matched_twin(circuit, analyser_dead_time_h=0.1, feed_inventory_h=args.feed_inventory_h,
                      p80_gain=args.p80_gain, charge_fast_frac=args.charge_fast_frac)
    rock = (lambda t: ROCK_FRAC if t >= T_ROCK_H else circuit.params.alpha_r_frac) \
        if args.rock_step else None
    plant = LeRouxPlant(circuit, component_names=mt.twin.blend.names, rock_frac=rock)
    sensors = Sensors(p80_noise_um=args.p80_noise, p80_dead_time_h=0.1, p80_sample_period_h=0.05,
                      power_noise_kw=5.0, load_noise_frac=0.01)
    u3 = np.array([circuit.params.feed_tph, circuit.params.speed_frac_critical])
    return SimpleNamespace(circuit=circuit, mt=mt, plant=plant, sensors=sensors, u3=u3, notes=identification_notes(mt))


def identification_notes(mt) -> list[str]:
    """What the matched twin was identified from, for the result table."""
    st = mt.step_tests
    tests = "; ".join(f"{who} {inp} gain {m.gain:.4g} um per unit, mean response time {m.mean_time_h:.4g} h"
                      for (who, inp), m in st.items())
    ps, ts = mt.plant_step, mt.twin_step
    return [f"twin matched to the circuit: power factor {mt.power_factor:.4g}, hardness scale "
            f"{mt.hardness0:.4g}, target P80 {mt.target_p80_um} um",
            f"step tests (linearised, exact moments; twin: without inventory and charge lag): {tests}",
            f"identified: charge time constant {mt.charge_time_constant_h:.4g} h (feed test), feed inventory "
            f"{mt.feed_inventory_h:.4g} h, P80 gain {mt.p80_gain:.4g} (feed test), charge lag fast fraction "
            f"{mt.charge_fast_frac:.4g} (speed test)",
            f"feed step test, FOPDT fits of feed -> P80: circuit gain {ps.gain:.3g} um/(t/h), tau "
            f"{ps.tau_h:.3g} h, delay {ps.delay_h:.3g} h; twin without inventory {ts.gain:.3g}, "
            f"{ts.tau_h:.3g} h, {ts.delay_h:.3g} h"]


def make_estimator(args, case) -> Ekf:
    """The EKF on the matched twin, reading the analyser through the twin's P80 gain."""
    mt, dt = case.mt, args.dt_h
    return Ekf(mt.twin.model, dt, mt.steady.x, hardness0=mt.hardness0, rk4_substeps=mt.rk4_substeps(dt),
               p80_noise_um=case.sensors.p80_noise_um, hardness_noise_per_sqrt_h=args.hardness_noise,
               disturbance_model=args.disturbance_model, p80_bias_noise_um_per_sqrt_h=args.p80_bias_noise,
               p80_gain=mt.p80_gain, p80_reference_um=mt.target_p80_um,
               change_detector=ChangeDetector() if args.change_detector else None)


def make_nmpc(args, case) -> Controller:
    """The NMPC (RTI, no preview) on the matched twin with the case's weights and input limits."""
    mt, dt = case.mt, args.dt_h
    t0 = time.perf_counter()
    ctrl = Controller(mt.twin.model, NmpcSettings(
        horizon_steps=args.horizon, dt_h=dt, target_p80_um=mt.target_p80_um,
        weight_du_feed=args.weight_du_feed, weight_du_speed=args.weight_du_speed,
        feed_tph_min=FEED_MIN, feed_tph_max=FEED_MAX, feed_rate_max_tph_per_h=FEED_RATE,
        rk4_substeps=mt.rk4_substeps(dt), solver=args.solver, qpsol=args.qpsol,
        weight_p80=args.weight_p80, weight_energy=args.weight_energy, preview=False))
    print(f"NMPC built in {time.perf_counter() - t0:.1f} s, {mt.rk4_substeps(dt)} RK4 steps per sample")
    return ctrl


def make_pi(args, case):
    """The PI baseline on the circuit's own feed step test; ``(controller, note)``."""
    steady = SimpleNamespace(x=case.mt.plant_steady_x, u=case.u3, d=case.circuit.d_nominal)
    ctrl, fop = pi_baseline(case.circuit, steady, case.sensors, args.dt_h, case.mt.target_p80_um,
                            feed_tph_min=FEED_MIN, feed_tph_max=FEED_MAX, feed_rate_max_tph_per_h=FEED_RATE)
    return ctrl, (f"PI from FOPDT gain {fop.gain:.3g} um/(t/h), tau {fop.tau_h:.3g} h, delay {fop.delay_h:.3g} h: "
                  f"kc {ctrl.pi.kc:.3g} (t/h)/um, ti {ctrl.pi.ti_h:.3g} h")


def run_one(args, case, kind: str, ctrl, est) -> tuple[dict, pd.DataFrame]:
    """One closed-loop run at ``args.seed``: its KPI row and its frame."""
    mt, target = case.mt, case.mt.target_p80_um
    t0 = time.perf_counter()
    res = run_closed_loop(case.plant, ctrl, est, lambda t: [1.0], case.sensors, mt.plant_steady_x, case.u3,
                          LoopSettings(args.duration_h, args.dt_h, seed=args.seed, target_p80_um=target,
                                       estimator_warmup_h=args.warmup_h if est is not None else 0.0,
                                       estimator_measurements=("p80_um",)),
                          plant_hardness=hardness)
    run_s = time.perf_counter() - t0
    f = res.frame
    err = f.p80_um - target
    last = f.time_h >= f.time_h.iloc[-1] - 1.0 - 1e-9
    k = dict(controller=kind, run_s=run_s, **res.kpis)
    k["p80_within_band_frac"] = float((err.abs() <= BAND_REL * target).mean())
    k["p80_after_step_max_abs_err_um"] = float(err[f.time_h >= T_STEP_H].abs().max())
    k["final_offset_um"] = float(err[last].mean())
    k["final_max_abs_err_um"] = float(err[last].abs().max())
    k["feed_final_tph"] = float(f.feed_tph[last].mean())
    k["speed_final_frac"] = float(f.speed_frac_critical[last].mean())
    k["hardness_est_final_rel"] = (float(f.hardness_est[last].mean()) / mt.hardness0
                                   if est is not None else np.nan)
    k["mass_balance_error"] = float(
        np.abs(f.fed_t - f.produced_t - (f.holdup_t - f.holdup_t.iloc[0])).max()
        / (f.fed_t.iloc[-1] + f.holdup_t.iloc[0]))
    k["iterations_median"] = float(f["iterations"].median())
    return k, f


def run_case(args, case=None) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """Every controller of ``args.only`` at ``args.seed``."""
    case = build_case(args) if case is None else case
    rows, runs, notes = [], [], list(case.notes)
    for kind in args.only.split(","):
        est = None
        if kind == "none":
            ctrl = FixedInputs(case.u3)
        elif kind == "pi":
            ctrl, note = make_pi(args, case)
            print(note)
            notes.append(note)
        elif kind == "nmpc":
            ctrl, est = make_nmpc(args, case), make_estimator(args, case)
        else:
            raise SystemExit(f"--only: unknown controller {kind!r}; allowed none, pi, nmpc")
        k, f = run_one(args, case, kind, ctrl, est)
        print({a: (round(b, 4) if isinstance(b, float) else b) for a, b in k.items()}, flush=True)
        rows.append(k)
        runs.append(f.assign(controller=kind))
    return pd.DataFrame(rows), pd.concat(runs), notes


def run_seeds(args) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """The case once per seed of ``args.seeds`` (the sensor noise differs); a ``seed`` column."""
    tables, runs = [], []
    case = build_case(args)
    for seed in (int(v) for v in args.seeds.split(",")):
        args.seed = seed
        table, run, notes = run_case(args, case)
        tables.append(table.assign(seed=seed))
        runs.append(run.assign(seed=seed))
    return pd.concat(tables, ignore_index=True), pd.concat(runs), notes


def ratio_line(table: pd.DataFrame) -> str:
    """The NMPC's IAE over the PI's, per seed, and their median."""
    iae = table.pivot(index="seed", columns="controller", values="p80_iae_um_h")
    if not {"pi", "nmpc"} <= set(iae.columns):
        return ""
    r = iae["nmpc"] / iae["pi"]
    each = ", ".join(f"{v:.3f}" for v in r)
    return f"NMPC IAE / PI IAE per seed ({', '.join(map(str, r.index))}): {each}; median {r.median():.3f}."


def parser() -> argparse.ArgumentParser:
    """The case's options (also the defaults of benchmarks/mpc_leroux_sweep.py)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-h", type=float, default=8.0)
    ap.add_argument("--dt-h", type=float, default=0.05)
    ap.add_argument("--horizon", type=int, default=20)
    ap.add_argument("--seeds", default="1,2,3,4,5,6,7,8,9,10", help="comma-separated sensor-noise seeds, one run each")
    ap.add_argument("--only", default="none,pi,nmpc")
    ap.add_argument("--weight-du-feed", type=float, default=1.0)
    ap.add_argument("--weight-du-speed", type=float, default=10.0)
    ap.add_argument("--solver", default="rti", help="NmpcSettings.solver of the NMPC")
    ap.add_argument("--qpsol", default="condensed", help="NmpcSettings.qpsol of the NMPC")
    # P80 20, feed moves 1, speed moves 10, hardness walk 0.15 (the reference case: 1, 1, 1, 0.03):
    # chosen by benchmarks/mpc_leroux_sweep.py on seeds 1-10 and judged on held-out seeds 11-20
    # (--seeds 11,...,20). On today's model they rank 8th of 108, within 0.007 of the first row,
    # which is worse on the held-out seeds (mpc_leroux_sweep.md says where the defaults rank).
    # The P80 weight is on the twin's passing, whose deviations are 1/p80_gain of the plant's.
    # The speed-move weight pins the speed/feed trade at a held P80, on which the twin and the
    # circuit disagree (with 1, speed wandered to its 0.85 bound on some seeds).
    ap.add_argument("--weight-p80", type=float, default=20.0)
    ap.add_argument("--weight-energy", type=float, default=0.01, help="NmpcSettings.weight_energy")
    ap.add_argument("--disturbance-model", default="hardness", help="EKF disturbance model (mpc.DISTURBANCE_MODELS)")
    ap.add_argument("--p80-bias-noise", type=float, default=5.0,
                    help="EKF random-walk intensity of the P80 bias [um/sqrt(h)]")
    ap.add_argument("--hardness-noise", type=float, default=0.15,
                    help="EKF random-walk intensity of the twin's hardness scale [1/sqrt(h)]")
    ap.add_argument("--change-detector", action="store_true",
                    help="a CUSUM change detector in front of the EKF (mpc.ChangeDetector, its defaults)")
    ap.add_argument("--p80-noise", type=float, default=3.0, help="analyser noise [um]")
    ap.add_argument("--warmup-h", type=float, default=2.0,
                    help="estimator warm-up on the steady plant before t = 0 [h]")
    ap.add_argument("--rock-step", action="store_true",
                    help=f"also step the rock fraction to {ROCK_FRAC} at t = {T_ROCK_H} h")
    ap.add_argument("--tag", default="", type=TAG, help="suffix of the result files")
    ap.add_argument("--feed-inventory-h", type=float, default=None,
                    help="time constant of the matched twin's feed inventory [h]; default identified from "
                         "the circuit's feed step test, 0 for none")
    ap.add_argument("--p80-gain", type=float, default=None,
                    help="P80 gain correction the EKF reads the analyser through; default identified from the "
                         "circuit's feed step test, 1 for none")
    ap.add_argument("--charge-fast-frac", type=float, default=None,
                    help="fraction of a speed or hardness change the matched twin's breakage sees at once "
                         "(charge_lag); default identified from the circuit's speed step test, 1 for no lag")
    return ap


def main(argv=None) -> pd.DataFrame:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser().parse_args(argv)
    table, runs, notes = run_seeds(args)
    OUT.mkdir(exist_ok=True)
    name = f"mpc_leroux_case{args.tag}"
    table.to_csv(OUT / f"{name}.csv", index=False)
    runs.to_csv(OUT / f"{name}_runs.csv", index=False)
    cols = ["seed", "controller", "p80_iae_um_h", "p80_within_10um_frac", "p80_within_band_frac",
            "p80_max_abs_err_um", "p80_after_step_max_abs_err_um", "final_offset_um",
            "final_max_abs_err_um", "specific_energy_kwh_t", "throughput_t", "feed_final_tph",
            "speed_final_frac", "hardness_est_final_rel", "solve_time_median_s",
            "solve_time_p95_s", "fallback_steps", "mass_balance_error"]
    rock = f", rock fraction -> {ROCK_FRAC} at {T_ROCK_H} h" if args.rock_step else ""
    md = [f"# le Roux et al. (2013) circuit: phi_f x {PHI_F_STEP} at {T_STEP_H} h{rock}; "
          "twin-based NMPC + EKF against PI and no control",
          "",
          f"duration {args.duration_h} h, sample {args.dt_h} h, NMPC horizon {args.horizon} ({args.solver}, "
          f"qpsol {args.qpsol}, no preview), seeds {args.seeds}; weights p80 {args.weight_p80}, du_feed "
          f"{args.weight_du_feed}, du_speed {args.weight_du_speed}, energy {args.weight_energy}; EKF on the P80 analyser only, "
          f"disturbance model {args.disturbance_model}, hardness noise "
          f"{args.hardness_noise}/sqrt(h)"
          f"{', CUSUM change detector (mpc.ChangeDetector)' if args.change_detector else ''}"
          f", warm-up {args.warmup_h} h; sensors: P80 noise "
          f"{args.p80_noise} um, dead time 0.1 h, sampling 0.05 h. Band: +-{BAND_REL:.0%} of "
          "target. final_offset_um: mean (P80 - target) over the last hour; "
          "hardness_est_final_rel: the EKF's hardness over its survey-3 value (plant: "
          f"{PHI_F_STEP}).",
          "", *[f"- {n}" for n in notes], "",
          table[cols].to_markdown(index=False, floatfmt=".4g"), "", ratio_line(table), "",
          f"Reproduce: `{' '.join(['PYTHONPATH=. python benchmarks/mpc_leroux_case.py', *argv])}`."]
    (OUT / f"{name}.md").write_text("\n".join(md) + "\n")
    return table


if __name__ == "__main__":
    main()
