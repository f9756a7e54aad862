"""The DEM's particle-to-particle scatter carried to the twin: a bootstrap over the virtual
particles (no new DEM runs).

A replicate resamples, with replacement, the packings of the compression tests and of the
drop-weight tests. The ores share their packings (twin.calibration.dem_link: particle k has
the same seed for every ore), so a replicate draws one set of packing indices and uses it for
every ore (a paired bootstrap; Efron & Tibshirani 1993, ch. 6). Each replicate refits the laws
(twin.calibration.dem_map) and then the table step from the nominal fit's values: the
calibration is an estimator run on the DEM data, and the bootstrap reruns all of it. A
prediction's interval is the spread of the prediction over the replicates (percentile
intervals, Efron & Tibshirani ch. 13).
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..errors import SolverError, TwinInputError
from .dem_map import fit_law, law_e50_j_kg
from .files import Calibration

#: Two-sided level of the intervals printed by ``grindtwin steady --uncertainty``.
INTERVAL_LEVEL = 0.90


def resample_dem(dem: dict, rng: np.random.Generator, n_particles: int | None = None) -> dict:
    """The DEM record's ores with resampled packings (module docstring); ``n_particles`` keeps
    only the first n packings of each test kind (a smaller experiment) before resampling."""
    n_comp = min(len(o["specific_fracture_energy_J_kg"]) for o in dem["ores"].values())
    n_drop = 1 + max(t["particle"] for o in dem["ores"].values() for t in o["drop_weight"]["tests"])
    if n_particles is not None:
        if not 2 <= n_particles <= n_comp:
            raise TwinInputError(f"The 'n_particles' of a bootstrap must be in [2, {n_comp}]. Got {n_particles}.")
        n_comp, n_drop = n_particles, min(n_drop, n_particles)
    comp = rng.integers(n_comp, size=n_comp)
    drop = rng.integers(n_drop, size=n_drop)
    ores = {}
    for name, o in dem["ores"].items():
        by_packing = {}
        for t in o["drop_weight"]["tests"]:
            by_packing.setdefault(t["particle"], []).append(t)
        tests = [t for k in drop for t in by_packing.get(int(k), [])]
        ores[name] = {**o, "specific_fracture_energy_J_kg": list(np.asarray(o["specific_fracture_energy_J_kg"])[comp]),
                      "drop_weight": {"tests": tests}}
    return ores


def replicate_laws(dem: dict, law: dict, n: int, seed: int, n_particles: int | None = None) -> list:
    """``n`` bootstrap replicates of the laws (their ``energy`` and ``breakage_function``)."""
    rng = np.random.default_rng(seed)
    multiples = law["breakage_function"]["energy_multiple"]
    out = []
    for _ in range(n):
        rep = fit_law(resample_dem(dem, rng, n_particles), dem["drum"], law["sizes_um"], multiples)
        out.append({"energy": rep["energy"], "breakage_function": rep["breakage_function"]})
    return out


def replicate_calibration(calibration: Calibration, replicate: dict, k: int) -> Calibration:
    """The calibration of replicate ``k``: its laws and, when refitted, its table-step values."""
    law = {**calibration.record["law"], "energy": replicate["energy"],
           "breakage_function": replicate["breakage_function"]}
    coef = {n: v for n, v in replicate.get("values", {}).items() if not n.startswith("lab_")}
    mills = {"lab": {n[len("lab_"):]: v for n, v in replicate.get("values", {}).items() if n.startswith("lab_")}}
    return calibration.with_values(coefficients=coef, mills=mills, law=law,
                                   name=f"{calibration.name}#bootstrap{k}")


def bootstrap(calibration: Calibration, names, bounds: dict, n: int, seed: int, progress: bool = True,
              table: tuple | None = None) -> dict:
    """Replicates of a fitted DEM calibration, each with its laws and its own table step (from
    the nominal values); with the standard errors they give of each reference ore's E50. ``table``:
    (ores, values, file) of a user's table in place of the shipped one (:class:`TableProblem`)."""
    from tqdm.auto import tqdm

    from .fitting import TableProblem, fit_problem

    t0 = time.perf_counter()
    record = calibration.record
    laws = replicate_laws(record["dem"], record["law"], n, seed)
    problem = TableProblem(calibration, names, bounds, *(table or ()))
    reps = []
    for k, law in enumerate(tqdm(laws, desc="bootstrap", unit="replicate", disable=not progress)):
        problem.set_breakage(replicate_calibration(calibration, law, k))
        fit = fit_problem(problem, least_squares_first=False)  # the max-norm from the nominal optimum
        reps.append({**law, "values": fit["values"], "success": fit["optimizer"]["success"],
                     "max_abs_error_pct": 100.0 * (math.exp(fit["max_abs_log_ratio"]) - 1.0),
                     "solver_failures": fit["solver_failures"]["count"]})
    return {"n": n, "seed": seed, "method": "paired bootstrap over packings; laws and table step refitted",
            "replicates": reps, "standard_errors": law_standard_errors(calibration, reps),
            "seconds": time.perf_counter() - t0}


def law_standard_errors(calibration: Calibration, replicates: list) -> dict:
    """Bootstrap standard errors: of the law's coefficients and sigma, and (relative, in ln) of
    each reference ore's E50 by the law and from its own particles alone."""
    from ..ore.ores import load_ore

    law, dem = calibration.record["law"], calibration.record["dem"]
    out = {k: float(np.std([r["energy"][k] for r in replicates], ddof=1)) for k in ("c0", "c1", "sigma")}
    e50 = {}
    for name, o in dem["ores"].items():
        ore = load_ore(name)
        ln = [math.log(law_e50_j_kg({**law, "energy": r["energy"]}, ore)) for r in replicates]
        e = np.log(o["specific_fracture_energy_J_kg"])
        e50[name] = {"law_j_kg": law_e50_j_kg(law, ore), "law_rel_se": float(np.std(ln, ddof=1)),
                     "own_particles_j_kg": float(np.exp(e.mean())),
                     "own_particles_rel_se": float(e.std() / math.sqrt(e.size)), "n_particles": int(e.size)}
    out["e50"] = e50
    return out


def intervals(samples: list, level: float = INTERVAL_LEVEL) -> dict:
    """{kpi: (low, median, high)}: percentile interval of the replicates' predictions."""
    lo, hi = 50.0 * (1.0 - level), 50.0 * (1.0 + level)
    keys = samples[0].keys() if samples else []
    return {k: tuple(float(np.percentile([s[k] for s in samples], q)) for q in (lo, 50.0, hi)) for k in keys}


def replicate_steady_states(ores, calibration: Calibration, mill: str = "lab", feed_tph: float | None = None,
                            speed_frac_critical: float | None = None, at_load: bool = False,
                            n: int | None = None) -> list:
    """A steady state's P80, specific energy, throughput and load for each of the calibration's
    bootstrap replicates whose table step converged (the first ``n``), ``None`` where the
    steady state failed. One parametric twin serves every replicate (its S, b and fitted
    numbers are symbols, twin.calibration.parametric), so a replicate costs a Newton solve."""
    from .parametric import ParametricTwin, fittable

    boot = calibration.record.get("bootstrap") or {}
    reps = [r for r in boot.get("replicates", []) if r.get("success", True)]
    if not reps:
        raise TwinInputError(f"Calibration {calibration.label()} keeps no bootstrap replicates; make it with "
                             "`grindtwin calibrate` (replicates > 0).")
    reps = reps[:n] if n else reps
    names = [k for k in reps[0]["values"] if k in fittable(calibration, mill)]
    pt = ParametricTwin(ores, calibration, names, mill=mill)
    out = []
    for k, rep in enumerate(reps):
        pt.set_breakage(replicate_calibration(calibration, {**rep, "values": {}}, k))
        try:
            ss = pt.steady({**pt.base, **rep["values"]}, feed_tph, speed_frac_critical,
                           at_load=1.0 if at_load else None)
        except SolverError:
            out.append(None)
            pt.reset()
            continue
        out.append({"p80_um": ss.p80_um, "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"],
                    "throughput_tph": ss.outputs["throughput_tph"], "load_frac": ss.outputs["load_frac"]})
    return out


def min_replicates(level: float) -> int:
    """Fewest bootstrap replicates a two-sided percentile interval at ``level`` is computed from:
    the interval leaves (1 - level) / 2 of the replicates beyond each end, and only from
    2 / (1 - level) replicates (20 at 90 %) is at least one of them there; with fewer, its ends are
    the extreme replicates' own (interpolated): the spread of a few draws, not an interval at that level."""
    return math.ceil(round(2.0 / (1.0 - level), 9))


def steady_intervals(ores, calibration: Calibration, mill: str = "lab", feed_tph: float | None = None,
                     speed_frac_critical: float | None = None, at_load: bool = False, n: int | None = None,
                     level: float = INTERVAL_LEVEL) -> dict:
    """Percentile intervals of a steady state's KPIs over the bootstrap replicates
    (:func:`replicate_steady_states`): {"intervals": {kpi: (low, median, high)}, "n", "failed"
    (steady states that failed), "unconverged" (replicates left out because their table step did
    not converge when the calibration was made), "level"}. ``n`` below :func:`min_replicates` is
    refused (TwinInputError) before anything is solved."""
    if n and n < min_replicates(level):
        raise TwinInputError(f"The 'n' parameter of steady_intervals must be 0/None (all replicates) or at least "
                             f"{min_replicates(level)}: a {level:.0%} interval leaves {(1 - level) / 2:.0%} of the "
                             f"replicates beyond each end. Got {n}.")
    states = replicate_steady_states(ores, calibration, mill, feed_tph, speed_frac_critical, at_load, n)
    ok = [s for s in states if s is not None]
    return {"intervals": intervals(ok, level), "n": len(ok), "failed": len(states) - len(ok),
            "unconverged": _unconverged(calibration, n), "level": level}


def _unconverged(calibration: Calibration, n: int | None) -> int:
    """Replicates skipped for an unconverged table step before the ``n`` converged ones used."""
    skipped = used = 0
    for rep in (calibration.record.get("bootstrap") or {}).get("replicates", []):
        if n and used >= n:
            break
        ok = rep.get("success", True)
        used += ok
        skipped += not ok
    return skipped
