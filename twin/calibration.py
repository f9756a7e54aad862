"""Calibration of the mineralogy -> breakage map and of the laboratory mill against the
reference table (``twin/data/reference_table.csv``, MISSION.md).

What is fitted here, to that table (12 numbers: P80, specific energy, throughput at constant
load for A-D): S^E_ref, the hardness and texture exponents of the breakage map, the two
cushioning coefficients, the clay-crowding coefficient of the slurry rheology
(twin.effects.rheology), and the laboratory mill's power factor, grate cut size and sharpness
and discharge factor (11 numbers). Nothing else. Least squares on the log-ratios, then a
p-norm stand-in for the max-norm (:func:`fit_log_ratios`): the table's goal is every KPI within 5 %.
The DEM calibration (a separate issue) is to replace the map's S^E by values derived from
virtual breakage tests, leaving fewer numbers fitted to the table.

Run: ``grindtwin calibrate`` (or ``python -m twin.calibration``); writes
``twin/data/calibration.json`` with the command, versions, the fitted values and the errors.
``python -m twin.calibration --dem [--fast] [--seed N]`` runs the DEM path instead
(:func:`twin.dem_link.calibrate_from_dem`, writes ``twin/data/dem_calibration.json``).
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import sys
import time
from importlib import resources
from pathlib import Path

import numpy as np
import scipy.optimize

from .breakage_map import COEFFICIENT_NAMES

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
KPIS = ("p80_um", "specific_energy_kwh_t", "throughput_kg_h")


def reference_table() -> dict:
    text = resources.files("twin").joinpath("data", "reference_table.csv").read_text(encoding="utf-8")
    rows = csv.DictReader([ln for ln in text.splitlines() if ln and not ln.startswith("#")])
    return {r["ore"]: {k: float(r[k]) for k in KPIS} for r in rows}


def calibration_dict(values: dict) -> dict:
    return {"coefficients": {k: values[k] for k in COEFFICIENT_NAMES},
            "mills": {"lab": lab_mill_values(values)}}


def lab_mill_values(values: dict) -> dict:
    """The lab mill's fitted fields (twin.mill.Mill) from a fit's ``lab_*`` values."""
    return {k[len("lab_"):]: v for k, v in values.items() if k.startswith("lab_")}


def predict(values: dict, ores=("A", "B", "C", "D"), **twin_kwargs) -> dict:
    """Steady state at constant load, 70 % critical, in the laboratory mill, per ore."""
    from .twin import Twin

    out = {}
    for ore in ores:
        ss = Twin(ore, mill="lab", calibration=calibration_dict(values), **twin_kwargs) \
            .steady_at_constant_load(speed_frac_critical=0.70)
        out[ore] = {"p80_um": ss.p80_um, "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"],
                    "throughput_kg_h": ss.feed_tph * 1000.0}
    return out


def _residuals(z, ref):
    values = _unpack(z)
    try:
        pred = predict(values)
    except Exception:  # a failed steady state is a bad point for the optimiser, not a crash
        return np.full(len(ref) * len(KPIS), 10.0)
    return np.array([np.log(pred[o][k] / ref[o][k]) for o in ref for k in KPIS])


def _pack(values):
    return np.array([np.log(values[n]) if BOUNDS[n][0] > 0 else values[n] for n in NAMES])


def _unpack(z):
    return {n: float(np.exp(v)) if BOUNDS[n][0] > 0 else float(v) for n, v in zip(NAMES, z)}


#: Forward-difference step of the fits' Jacobians, in the log-parameters (a 0.01 % change).
DIFF_STEP = 1e-4
#: The ``"pnorm"`` step minimises sum (r / r_goal)^(2 PNORM_HALF_POWER), a smooth stand-in for
#: max |r| (p = 8); r_goal = ln 1.05 scales the residuals to order one for the tolerances.
PNORM_HALF_POWER = 4
PNORM_SCALE = float(np.log(1.05))


def fit_log_ratios(residuals, z0, lo, hi, max_nfev: int, verbose: int = 0, final: str = "minimax"):
    """Least squares on the log-ratio residuals r(z), then their max-norm from there.

    The table's goal is every KPI within 5 %, a max-norm. ``final="minimax"`` solves its
    epigraph form, ``min t`` subject to ``-t <= r_i(z) <= t`` and the bounds, by SLSQP (Kraft
    1988, scipy) with forward-difference Jacobians, ``max_nfev`` iterations. ``"pnorm"`` is the
    smooth stand-in (:data:`PNORM_HALF_POWER`) by least squares, ``max_nfev`` evaluations: it
    stopped 0.2 points short of the max-norm on the DEM table fit (5.13 against 4.93 %), but it
    made the shipped mineralogy-map calibration (:func:`fit`), whose valley is flat (see there).
    Step 1 runs ``max_nfev`` evaluations. Returns a scipy OptimizeResult: ``x`` (minimax: the
    evaluated point with the least max |r|, so a failed step 2 never loses step 1's point;
    pnorm: step 2's), ``status``/``message``/``success``/``nfev`` of step 2, ``cost``
    (0.5 sum r^2 at x), ``max_abs_residual``."""
    if final not in ("minimax", "pnorm"):
        raise ValueError(f"The 'final' parameter must be 'minimax' or 'pnorm'. Got {final!r}.")
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    evaluated = {}

    def r_at(z):
        key = tuple(np.asarray(z, float))
        if key not in evaluated:
            evaluated[key] = np.asarray(residuals(np.asarray(z, float)), float)
        return evaluated[key]

    def jac(z):
        r0 = r_at(z)
        J = np.empty((r0.size, z.size))
        for j in range(z.size):
            h = DIFF_STEP if z[j] + DIFF_STEP <= hi[j] else -DIFF_STEP
            zz = z.copy()
            zz[j] += h
            J[:, j] = (r_at(zz) - r0) / h
        return J

    ls = scipy.optimize.least_squares(r_at, z0, bounds=(lo, hi), x_scale=1.0, diff_step=DIFF_STEP,
                                      max_nfev=max_nfev, verbose=verbose)
    if final == "pnorm":
        step2 = scipy.optimize.least_squares(
            lambda z: np.sign(r_at(z)) * np.abs(r_at(z) / PNORM_SCALE) ** PNORM_HALF_POWER, ls.x,
            bounds=(lo, hi), x_scale=1.0, diff_step=DIFF_STEP, max_nfev=max_nfev, verbose=verbose)
        return _result(step2.x, r_at(step2.x), step2, "least squares on the p-norm")
    # epigraph variables y = [z, t]: minimise t with t - r(z) >= 0 and t + r(z) >= 0
    n = ls.x.size

    def gap(y):
        return np.r_[y[n] - r_at(y[:n]), y[n] + r_at(y[:n])]

    def gap_jac(y):
        J = jac(y[:n])
        ones = np.ones((len(J), 1))
        return np.block([[-J, ones], [J, ones]])

    epi = scipy.optimize.minimize(
        lambda y: y[n], np.r_[ls.x, np.max(np.abs(r_at(ls.x)))], jac=lambda y: np.r_[np.zeros(n), 1.0],
        method="SLSQP", bounds=[*zip(lo, hi), (0.0, None)],
        constraints=[{"type": "ineq", "fun": gap, "jac": gap_jac}],
        options={"maxiter": max_nfev, "ftol": 1e-8, "disp": bool(verbose)})
    best = min(evaluated, key=lambda k: np.max(np.abs(evaluated[k])))
    return _result(np.array(best), evaluated[best], epi, "SLSQP")


def _result(x, r, step2, name: str):
    """fit_log_ratios' OptimizeResult at ``x`` (residuals ``r``) with step 2's status."""
    return scipy.optimize.OptimizeResult(
        x=np.asarray(x, float), status=int(step2.status), message=f"{name}: {step2.message}",
        success=bool(step2.success), nfev=int(step2.nfev), cost=0.5 * float(r @ r),
        max_abs_residual=float(np.max(np.abs(r))))


def fit(max_nfev: int = 200, verbose: int = 0) -> dict:
    """Least squares on log-ratios of predicted to reference KPIs, then the p-norm stand-in for
    their max-norm (:func:`fit_log_ratios`), each with ``max_nfev``; returns the record to save."""
    ref = reference_table()
    lo = np.array([np.log(BOUNDS[n][0]) if BOUNDS[n][0] > 0 else BOUNDS[n][0] for n in NAMES])
    hi = np.array([np.log(BOUNDS[n][1]) if BOUNDS[n][0] > 0 else BOUNDS[n][1] for n in NAMES])
    t0 = time.perf_counter()
    # "pnorm": the shipped calibration.json was made so. The minimax step reaches 3.44 % against
    # 3.51 % but moves S^E_ref by -10 %, clay crowding by -25 % and the discharge factor by +36 %
    # (a flat valley), which moves the industrial operating point the controller is tuned at.
    sol = fit_log_ratios(lambda z: _residuals(z, ref), _pack(START), lo, hi, max_nfev, verbose, final="pnorm")
    values = _unpack(sol.x)
    pred = predict(values)
    errors = {o: {k: 100.0 * (pred[o][k] / ref[o][k] - 1.0) for k in KPIS} for o in ref}
    record = calibration_dict(values)
    record["fit"] = {
        "fitted_to": "twin/data/reference_table.csv (MISSION.md reference table)",
        "parameters_fitted": list(NAMES),
        "predicted": pred, "error_pct": errors,
        "max_abs_error_pct": max(abs(e) for row in errors.values() for e in row.values()),
        "optimizer": {"status": int(sol.status), "message": str(sol.message), "nfev": int(sol.nfev),
                      "cost": float(sol.cost), "seconds": time.perf_counter() - t0},
    }
    return record


def versions() -> dict:
    """Versions of what shapes a calibration, for its provenance record."""
    import casadi
    import numba

    return {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
            "numba": numba.__version__, "casadi": casadi.__version__}


def provenance(command: str) -> dict:
    return {"command": command, **versions(), "seed": None,
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def write_json_atomically(path: Path, record: dict, indent: int = 2) -> None:
    """Write to a temporary file and rename it over ``path``: nothing is ever half-written."""
    path = Path(path)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(record, indent=indent) + "\n", encoding="utf-8")
    tmp.replace(path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="grindtwin calibrate", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path(str(resources.files("twin").joinpath("data", "calibration.json"))))
    ap.add_argument("--fast", action="store_true", help="fewer optimiser evaluations (a quick check)")
    ap.add_argument("--dem", action="store_true",
                    help="the DEM path instead: regenerate twin/data/dem_calibration.json (twin.dem_link)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the DEM path")
    args = ap.parse_args(argv)
    if args.dem:
        from .dem_link import DEM_CALIBRATION_PATH, calibrate_from_dem

        out = args.out if "--out" in (argv if argv is not None else sys.argv) else DEM_CALIBRATION_PATH
        calibrate_from_dem(fast=args.fast, seed=args.seed, out=out)
        return 0
    record = fit(max_nfev=12 if args.fast else 80)
    record["provenance"] = provenance("grindtwin calibrate" + (" --fast" if args.fast else ""))
    write_json_atomically(args.out, record)
    print(f"wrote {args.out}: max |error| {record['fit']['max_abs_error_pct']:.2f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
