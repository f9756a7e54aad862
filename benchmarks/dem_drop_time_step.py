"""The drop-weight test against its time step: what the calibration's factor 0.5 costs in accuracy.

The calibration's drop tests (twin.calibration.dem_link.drop_tests: the shipped calibration's
bonds, E50 and packings of one ore, its energy multiples) rerun at time-step factors of
System's critical step (default 0.5, the calibration's, 0.25 and 0.125). Fragmentation is
chaotic: a step change is a perturbation that sends each impact to another outcome, so the
outputs do not converge test by test but as an ensemble. Each factor's numbers therefore come
with a bootstrap over the packings (resampled with replacement, the breakage function and
t10 refitted): a factor whose estimate lies outside the finest factor's interval is a time-step
bias the packings' scatter does not cover. Per energy multiple: the mean broken fraction and
the pooled fit's t10 and gamma; per factor: Narayanan & Whiten's A, b and A x b, and the wall
time of the tests (their cost; the step count scales as 1 / factor).

Writes benchmarks/results/dem_drop_time_step{TAG}.csv/.md and dem_drop_time_step{TAG}_tests.csv
(every test). Run: ``python benchmarks/dem_drop_time_step.py [--ore B] [--factors 0.5,0.25,0.125]
[--particles N] [--boot 400]`` (defaults: ore B, the calibration's 4 packings; about 9 min on 2
cores for the default factors, the finest 0.125 two thirds of it).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import POSITIVE_LIST, load_average, option_type, write_table
from dem import BondCalibrator, BondParams
from twin.calibration.dem_link import DROP_TIME_STEP_FACTOR, drop_tests, fit_t10
from twin.calibration.dem_map import fit_austin_B
from twin.calibration.files import DEM_CALIBRATION_PATH
from twin.ore.ores import load_ore

#: bootstrap interval of the table: the central 90 %
CI = (5.0, 95.0)


def options(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ore", default="B", help="a reference ore of the shipped calibration (default %(default)s)")
    ap.add_argument("--factors", type=POSITIVE_LIST, default="0.5,0.25,0.125",
                    help="time-step factors of System's critical step (default %(default)s)")
    ap.add_argument("--particles", type=option_type(int, lambda v: 1 <= v <= 64, "an integer in [1, 64]"), default=0,
                    help="packings per energy (default 0: the calibration's)")
    ap.add_argument("--boot", type=option_type(int, lambda v: 10 <= v <= 10000, "an integer in [10, 10000]"),
                    default=400, help="bootstrap resamples of the packings (default %(default)s)")
    ap.add_argument("--tag", default="", help="suffix of the results files (e.g. _fine for another set of factors)")
    ap.add_argument("--workers", type=option_type(int, lambda v: v >= 1, "an integer >= 1"), default=os.cpu_count())
    return ap.parse_args(argv)


def shipped(ore: str):
    """The shipped calibration's DEM settings, the ore's bonds (the calibrator's defaults beside the fitted
    strengths and stiffnesses) and its E50."""
    rec = json.loads(DEM_CALIBRATION_PATH.read_text())["dem"]
    if ore not in rec["ores"]:
        raise SystemExit(f"--ore {ore}: not an ore of the shipped calibration ({', '.join(rec['ores'])})")
    b, dflt = rec["ores"][ore], BondCalibrator().get_params()
    bond = BondParams(kn_Pa_m=b["bond"]["kn_GPa_m"] * 1e9, ks_Pa_m=b["bond"]["ks_GPa_m"] * 1e9,
                      tensile_strength_Pa=b["bond"]["tensile_strength_MPa"] * 1e6,
                      cohesion_Pa=b["bond"]["cohesion_MPa"] * 1e6, friction_angle_deg=dflt["friction_angle_deg"],
                      radius_multiplier=dflt["radius_multiplier"], moment_factor=dflt["moment_factor"])
    return rec, b, bond


def fitted(tests: list, multiples, particles) -> dict:
    """Per energy multiple the pooled fit of ``particles`` (with repeats: a bootstrap resample); then t10's law."""
    out, e_kwh, t10 = {}, [], []
    for m in multiples:
        rows = [t for k in particles for t in tests if t["particle"] == k and np.isclose(t["energy_multiple"], m)]
        fit = fit_austin_B(np.concatenate([t["sieve_size_rel"] for t in rows]),
                           np.concatenate([t["passing_frac"] for t in rows]))
        out[m] = fit
        e_kwh.append(rows[0]["specific_energy_J_kg"] / 3600.0)
        t10.append(fit["t10"])
    out["law"] = fit_t10(e_kwh, t10)
    return out


def main(argv=None):
    o = options(argv)
    rec, b, bond = shipped(o.ore)
    settings = dict(rec["settings"])
    if o.particles:
        settings["drop_particles"] = o.particles
    multiples = settings["drop_energy_multiples"]
    rng = np.random.default_rng(0)
    rows, tests_out = [], []
    load0 = load_average()
    for f in o.factors:
        t0 = time.perf_counter()
        d = drop_tests(load_ore(o.ore), bond, b["fracture_energy"]["e50_j_kg"], settings, settings["seed"],
                       workers=o.workers, time_step_factor=f)
        wall_s = time.perf_counter() - t0
        tests = d["tests"]
        n = settings["drop_particles"]
        if np.isclose(f, DROP_TIME_STEP_FACTOR) and n == rec["settings"]["drop_particles"]:
            same = all(np.array_equal(x["passing_frac"], y["passing_frac"])
                       for x, y in zip(tests, b["drop_weight"]["tests"]))
            print(f"factor {f:g}: the calibration's own tests reproduced: {same}", flush=True)
        base = fitted(tests, multiples, range(n))
        boot = [fitted(tests, multiples, rng.integers(0, n, n)) for _ in range(o.boot)]
        row = {"factor": f, "packings": n, "tests": len(tests), "wall_s": wall_s}
        for key in ("A_pct", "b_t_kwh", "A_times_b"):
            vals = np.array([bb["law"][key] for bb in boot])
            row[key] = base["law"][key]
            row[f"{key}_ci"] = f"{np.percentile(vals, CI[0]):.4g}-{np.percentile(vals, CI[1]):.4g}"
        for m in multiples:
            t10s = np.array([bb[m]["t10"] for bb in boot])
            row[f"t10_at_{m:g}"] = base[m]["t10"]
            row[f"t10_at_{m:g}_ci"] = f"{np.percentile(t10s, CI[0]):.3f}-{np.percentile(t10s, CI[1]):.3f}"
            row[f"gamma_at_{m:g}"] = base[m]["gamma"]
            row[f"broken_at_{m:g}"] = float(np.mean([t["broken_fraction"] for t in tests
                                                      if np.isclose(t["energy_multiple"], m)]))
        rows.append(row)
        tests_out += [{"factor": f, **{k: v for k, v in t.items() if not isinstance(v, list)}} for t in tests]
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
    table = pd.DataFrame(rows)
    pd.DataFrame(tests_out).to_csv(os.path.join(os.path.dirname(__file__), "results",
                                                f"dem_drop_time_step{o.tag}_tests.csv"), index=False)
    write_table(table, f"dem_drop_time_step{o.tag}", f"Drop-weight tests against their time step (ore {o.ore})",
                f"Command: `python benchmarks/dem_drop_time_step.py --ore {o.ore} --factors "
                f"{','.join(f'{f:g}' for f in o.factors)}{f' --particles {o.particles}' if o.particles else ''}"
                f"{f' --tag {o.tag}' if o.tag else ''}`. "
                f"The shipped calibration's bonds, E50 ({b['fracture_energy']['e50_j_kg']:.4g} J/kg) and drop settings "
                f"(1 kg weight, energies {', '.join(f'{m:g}' for m in multiples)} x E50, the calibration's packing "
                f"seeds), the time step a factor of System's critical step (the calibration's: "
                f"{DROP_TIME_STEP_FACTOR:g}). Intervals: the central {CI[1] - CI[0]:g} % of {o.boot} bootstrap "
                "resamples of the packings (breakage function and t10 refitted). wall_s: the tests' wall time on "
                f"{o.workers} worker processes (their cost; the steps scale as 1 / factor). Load average (1/5/15 min) "
                f"at the start {load0}, at the end {load_average()}.")


if __name__ == "__main__":
    main()
