"""Calibration of the mineralogy -> breakage map and of the laboratory mill against the
reference table (``twin/calibration/data/reference_table.csv``, MISSION.md).

What is fitted here, to that table (12 numbers: P80, specific energy, throughput at constant
load for A-D): S^E_ref, the hardness and texture exponents of the breakage map, the two
cushioning coefficients, the clay-crowding coefficient of the slurry rheology
(twin.effects.rheology), and the laboratory mill's power factor, grate cut size and sharpness
and discharge factor (11 numbers). Nothing else. Least squares on the log-ratios, then a
p-norm stand-in for the max-norm (:func:`fit_log_ratios`): the table's goal is every KPI within 5 %.
The DEM calibration (a separate issue) is to replace the map's S^E by values derived from
virtual breakage tests, leaving fewer numbers fitted to the table.

Run: ``grindtwin calibrate`` (or ``python -m twin.calibration``); writes
``twin/calibration/files/table.json`` with the command, versions, the fitted values and the errors.
``python -m twin.calibration --dem [--fast] [--seed N]`` runs the DEM path instead
(:func:`twin.calibration.dem_link.calibrate_from_dem`, writes ``twin/calibration/files/dem.json``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from ..errors import SolverError
from .breakage_map import COEFFICIENT_NAMES
from .files import DEM_CALIBRATION_PATH, TABLE_CALIBRATION_PATH, lab_mill_values, provenance, write_json_atomically
from .fitting import FAILED_POINT_RESIDUAL, failed_points_record, fit_log_ratios
from .reference import KPIS, reference_table

#: Start of the fit and bounds (log-space for positive values); only a starting point.
START = {"se_ref_t_kwh": 0.55, "hardness_exponent": 0.05, "texture_exponent": 0.01, "alpha_texture_exponent": 0.2,
         "cushioning_rate_coeff": 0.01, "cushioning_power_coeff": 0.6, "clay_crowding_coeff": 0.9,
         "lab_power_factor": 1.3, "lab_grate_d50_um": 25.0, "lab_grate_sharpness": 1.2,
         "lab_discharge_factor": 2.4}
#: Signs are physical: harder minerals and finer textures never speed breakage up, cushioning
#: never adds energy.
BOUNDS = {"se_ref_t_kwh": (0.05, 20.0), "hardness_exponent": (0.0, 5.0), "texture_exponent": (0.0, 5.0),
          "alpha_texture_exponent": (-1.0, 2.0),
          "cushioning_rate_coeff": (0.0, 20.0), "cushioning_power_coeff": (0.0, 20.0),
          "clay_crowding_coeff": (0.0, 5.0),
          "lab_power_factor": (0.3, 3.0), "lab_grate_d50_um": (10.0, 3000.0), "lab_grate_sharpness": (0.5, 10.0),
          "lab_discharge_factor": (0.5, 50.0)}
NAMES = tuple(START)


def calibration_dict(values: dict) -> dict:
    return {"coefficients": {k: values[k] for k in COEFFICIENT_NAMES},
            "mills": {"lab": lab_mill_values(values)}}


def predict(values: dict, ores=("A", "B", "C", "D"), **twin_kwargs) -> dict:
    """Steady state at constant load, 70 % critical, in the laboratory mill, per ore."""
    from ..twin import Twin

    out = {}
    for ore in ores:
        ss = Twin(ore, mill="lab", calibration=calibration_dict(values), **twin_kwargs) \
            .steady_at_constant_load(speed_frac_critical=0.70)
        out[ore] = {"p80_um": ss.p80_um, "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"],
                    "throughput_kg_h": ss.feed_tph * 1000.0}
    return out


def _residuals(z, ref, failures: list | None = None):
    """Log-ratios of predicted to reference KPIs at ``z``. Where the steady state's own solver
    fails (:class:`twin.SolverError`, and only that) the point gets ``FAILED_POINT_RESIDUAL``
    and its message is appended to ``failures``; any other error propagates."""
    values = _unpack(z)
    try:
        pred = predict(values)
    except SolverError as exc:
        if failures is not None:
            failures.append(str(exc))
        return np.full(len(ref) * len(KPIS), FAILED_POINT_RESIDUAL)
    return np.array([np.log(pred[o][k] / ref[o][k]) for o in ref for k in KPIS])


def _pack(values):
    return np.array([np.log(values[n]) if BOUNDS[n][0] > 0 else values[n] for n in NAMES])


def _unpack(z):
    return {n: float(np.exp(v)) if BOUNDS[n][0] > 0 else float(v) for n, v in zip(NAMES, z)}


def fit(max_nfev: int = 200, verbose: int = 0, progress: bool = False) -> dict:
    """Least squares on log-ratios of predicted to reference KPIs, then the p-norm stand-in for
    their max-norm (:func:`fit_log_ratios`), each with ``max_nfev``; returns the record to save.
    ``progress``: a bar counting the evaluations (four steady states each) with the worst error."""
    from tqdm.auto import tqdm

    ref = reference_table()
    lo = np.array([np.log(BOUNDS[n][0]) if BOUNDS[n][0] > 0 else BOUNDS[n][0] for n in NAMES])
    hi = np.array([np.log(BOUNDS[n][1]) if BOUNDS[n][0] > 0 else BOUNDS[n][1] for n in NAMES])
    t0 = time.perf_counter()
    # "pnorm": the shipped calibration.json was made so. The minimax step reaches 3.44 % against
    # 3.51 % but moves S^E_ref by -10 %, clay crowding by -25 % and the discharge factor by +36 %
    # (a flat valley), which moves the industrial operating point the controller is tuned at.
    failures: list[str] = []
    with tqdm(desc="calibrate", unit="evaluation", disable=not progress) as bar:
        def residuals(z):
            r = _residuals(z, ref, failures)
            bar.set_postfix_str(f"worst |error| {100 * (np.exp(np.max(np.abs(r))) - 1):.2f} %", refresh=False)
            bar.update()
            return r

        sol = fit_log_ratios(residuals, _pack(START), lo, hi, max_nfev, verbose, final="pnorm")
    values = _unpack(sol.x)
    pred = predict(values)
    errors = {o: {k: 100.0 * (pred[o][k] / ref[o][k] - 1.0) for k in KPIS} for o in ref}
    record = calibration_dict(values)
    record["fit"] = {
        "fitted_to": "twin/calibration/data/reference_table.csv (MISSION.md reference table)",
        "parameters_fitted": list(NAMES),
        "predicted": pred, "error_pct": errors,
        "max_abs_error_pct": max(abs(e) for row in errors.values() for e in row.values()),
        "solver_failures": failed_points_record(failures),
        "optimizer": {"status": int(sol.status), "message": str(sol.message), "nfev": int(sol.nfev),
                      "cost": float(sol.cost), "seconds": time.perf_counter() - t0},
    }
    return record


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="grindtwin calibrate", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=TABLE_CALIBRATION_PATH)
    ap.add_argument("--fast", action="store_true", help="fewer optimiser evaluations (a quick check)")
    ap.add_argument("--dem", action="store_true",
                    help="the DEM path instead: regenerate twin/calibration/files/dem.json (twin.calibration.dem_link)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the DEM path")
    args = ap.parse_args(argv)
    if args.dem:
        from .dem_link import calibrate_from_dem  # the DEM chain (numba) only when asked for

        out = args.out if "--out" in (argv if argv is not None else sys.argv) else DEM_CALIBRATION_PATH
        calibrate_from_dem(fast=args.fast, seed=args.seed, out=out)
        return 0
    record = fit(max_nfev=12 if args.fast else 80, progress=True)
    record["provenance"] = provenance("grindtwin calibrate" + (" --fast" if args.fast else ""))
    write_json_atomically(args.out, record)
    print(f"wrote {args.out}: max |error| {record['fit']['max_abs_error_pct']:.2f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
