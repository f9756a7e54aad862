"""The table step: named parameters of a calibration fitted to MISSION.md's table
(twin/calibration/data/reference_table.csv), least squares on the log-ratios of predicted to
measured KPIs, then their max-norm (the table's goal is every KPI within a percentage) by
SLSQP, with exact Jacobians from parametric twins (twin.calibration.parametric).

A steady state that fails during the fit (twin.SolverError, nothing else) is a rejected trial
point: its residuals are :data:`SOLVER_FAILURE_RESIDUAL` and it is counted, with its message,
in the fit record.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.optimize

from ..errors import SolverError, TwinInputError
from .fitted import on_bound
from .parametric import ParametricTwin, calibration_values
from .reference import KPIS, given_reference, reference_identity, reference_table

#: Tolerances (stated in every fit record). Step 1, scipy's trust-region least squares, stops on
#: relative changes below LSQ_TOL (ftol, xtol, gtol). Step 2, the max-norm by SLSQP, stops when
#: the max-norm t (a log-ratio: 1e-9 is 1e-7 %) changes by less than MINIMAX_FTOL.
LSQ_TOL = 1e-10
MINIMAX_FTOL = 1e-9
#: Log-ratio residual of a trial point whose steady state failed: far outside any fit (e^10), so
#: the optimiser rejects the step.
SOLVER_FAILURE_RESIDUAL = 10.0


def fit_log_ratios(fun, jac, z0, lo, hi, max_iter: int = 200, least_squares_first: bool = True):
    """Least squares on the residuals r(z) (exact Jacobian ``jac``), then their max-norm by
    SLSQP on the epigraph form ``min t`` s.t. ``-t <= r_i(z) <= t`` and the bounds (Kraft 1988)
    from the least-squares point (or from ``z0`` when ``least_squares_first`` is False).
    Returns a scipy OptimizeResult: ``x`` (the evaluated point with the least max |r|),
    ``success`` (the steps converged), ``message``/``nit`` of SLSQP, ``lsq`` (status, message,
    nfev of step 1, or None), ``nfev``/``njev`` (evaluations of r and J), ``cost`` (0.5 sum
    r^2 at x) and ``max_abs_residual``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    z0 = np.clip(np.asarray(z0, float), lo, hi)
    evaluated, counts = {}, {"fun": 0, "jac": 0}

    def r_at(z):
        key = tuple(np.asarray(z, float))
        if key not in evaluated:
            counts["fun"] += 1
            evaluated[key] = np.asarray(fun(np.asarray(z, float)), float)
        return evaluated[key]

    def j_at(z):
        counts["jac"] += 1
        return np.asarray(jac(np.asarray(z, float)), float)

    lsq = None
    if least_squares_first:
        ls = scipy.optimize.least_squares(r_at, z0, jac=j_at, bounds=(lo, hi), x_scale="jac", ftol=LSQ_TOL,
                                          xtol=LSQ_TOL, gtol=LSQ_TOL, max_nfev=max_iter)
        lsq = {"status": int(ls.status), "message": str(ls.message), "nfev": int(ls.nfev), "success": bool(ls.success)}
        z0 = ls.x
    n = z0.size

    def gap(y):
        return np.r_[y[n] - r_at(y[:n]), y[n] + r_at(y[:n])]

    def gap_jac(y):
        J = j_at(y[:n])
        ones = np.ones((len(J), 1))
        return np.block([[-J, ones], [J, ones]])

    epi = scipy.optimize.minimize(
        lambda y: y[n], np.r_[z0, np.max(np.abs(r_at(z0)))], jac=lambda y: np.r_[np.zeros(n), 1.0],
        method="SLSQP", bounds=[*zip(lo, hi), (0.0, None)],
        constraints=[{"type": "ineq", "fun": gap, "jac": gap_jac}],
        options={"maxiter": max_iter, "ftol": MINIMAX_FTOL})
    best = min(evaluated, key=lambda k: np.max(np.abs(evaluated[k])))
    r = evaluated[best]
    return scipy.optimize.OptimizeResult(
        x=np.array(best), success=bool(epi.success and (lsq is None or lsq["success"])),
        message=f"SLSQP: {epi.message}", nit=int(epi.nit), lsq=lsq, nfev=counts["fun"], njev=counts["jac"],
        cost=0.5 * float(r @ r), max_abs_residual=float(np.max(np.abs(r))))


class TableProblem:
    """The log-ratio residuals of a calibration's ``names`` on the reference ``ores`` and their
    exact Jacobian (parameters packed in log space when their lower bound is positive). ``reference``:
    values in place of the shipped table (their ``ores`` reference types or Mineralogy, named as the
    values' keys; ``source`` the file they came from), recorded as given."""

    def __init__(self, calibration, names, bounds: dict, ores=("A", "B", "C", "D"), reference: dict | None = None,
                 source=None):
        missing = [n for n in names if n not in bounds]
        if missing:
            raise TwinInputError(f"No bounds for the fitted parameter(s) {missing}.")
        self.names = tuple(names)
        self.bounds = {n: bounds[n] for n in self.names}
        self.log = np.array([self.bounds[n][0] > 0 for n in self.names])
        ref = reference or reference_table()
        keys = [ore_key(o) for o in ores]
        unknown = [k for k in keys if k not in ref]
        if unknown:
            raise TwinInputError(f"The 'ores' parameter names {unknown}, not in the reference table "
                                 f"(ores {sorted(ref)}).")
        self.ref = {k: ref[k] for k in keys}
        # what the fit is to: the shipped table, or values given (recorded as such, never as the table)
        own = {k: o for k, o in zip(keys, ores) if not isinstance(o, str)}
        self.fitted_to = reference_identity() if reference is None else given_reference(self.ref, source, own)
        self.twins = {k: ParametricTwin(o, calibration, self.names) for k, o in zip(keys, ores)}
        self.base = calibration_values(calibration)
        self.failures: list[str] = []
        self._cache = (None, None, None)

    def set_breakage(self, calibration) -> None:
        """Every ore's S and b from ``calibration``'s map (e.g. a bootstrap replicate's laws)."""
        for pt in self.twins.values():
            pt.set_breakage(calibration)
        self._cache = (None, None, None)

    def pack(self, values: dict) -> np.ndarray:
        v = np.array([values[n] for n in self.names], float)
        return np.where(self.log, np.log(np.maximum(v, 1e-300)), v)

    def unpack(self, z) -> dict:
        z = np.asarray(z, float)
        return {n: float(math.exp(v) if lg else v) for n, v, lg in zip(self.names, z, self.log)}

    def limits(self):
        lo = np.array([math.log(self.bounds[n][0]) if lg else self.bounds[n][0] for n, lg in zip(self.names, self.log)])
        hi = np.array([math.log(self.bounds[n][1]) if lg else self.bounds[n][1] for n, lg in zip(self.names, self.log)])
        return lo, hi

    def evaluate(self, z):
        """(residuals, Jacobian in z) at packed parameters z; cached for the last z."""
        z = np.asarray(z, float)
        if self._cache[0] is not None and np.array_equal(self._cache[0], z):
            return self._cache[1], self._cache[2]
        values = {**self.base, **self.unpack(z)}
        theta = np.array([values[n] for n in self.names])
        chain = np.where(self.log, theta, 1.0)  # d theta / d z
        rows, jac = [], []
        try:
            for ore, pt in self.twins.items():
                kpis, grad = pt.kpis(values)
                for k in KPIS:
                    rows.append(math.log(kpis[k] / self.ref[ore][k]))
                    jac.append(np.asarray(grad[k], float) / kpis[k] * chain)
            r, J = np.array(rows), np.array(jac)
        except SolverError as exc:
            self.failures.append(str(exc))
            for pt in self.twins.values():
                pt.reset()  # start cold next time
            r = np.full(len(self.ref) * len(KPIS), SOLVER_FAILURE_RESIDUAL)
            J = np.zeros((r.size, z.size))
        self._cache = (z.copy(), r, J)
        return r, J


def ore_key(ore) -> str:
    """An ore's key in a table: a reference type as given, a Mineralogy by its name."""
    return ore if isinstance(ore, str) else ore.name


def fit_to_table(calibration, names, bounds: dict, ores=("A", "B", "C", "D"), start: dict | None = None,
                 max_iter: int = 200, reference: dict | None = None, source=None):
    """Fit ``names`` of ``calibration`` to the table on ``ores``; returns (fitted Calibration in
    memory, fit record). The start is ``start`` (else the calibration's own values) clipped
    into the bounds. ``reference``, ``source``: values in place of the shipped table (:class:`TableProblem`)."""
    t0 = time.perf_counter()
    problem = TableProblem(calibration, names, bounds, ores, reference, source)
    record = fit_problem(problem, start, max_iter)
    record["optimizer"]["seconds"] = time.perf_counter() - t0  # with the parametric twins' build
    return with_fitted_values(calibration, record["values"]), record


def fit_problem(problem: TableProblem, start: dict | None = None, max_iter: int = 200,
                least_squares_first: bool = True) -> dict:
    """Fit a built :class:`TableProblem` from ``start`` (else its base values); the fit record.
    ``least_squares_first=False``: the max-norm step only (a refit from a nearby optimum)."""
    t0 = time.perf_counter()
    problem.failures = []
    lo, hi = problem.limits()
    z0 = problem.pack({**problem.base, **(start or {})})
    sol = fit_log_ratios(lambda z: problem.evaluate(z)[0], lambda z: problem.evaluate(z)[1], z0, lo, hi, max_iter,
                         least_squares_first)
    at_bound = [n for n, z, a, b in zip(problem.names, sol.x, lo, hi) if on_bound(z, a, b)]  # in the packed space
    return {
        "fitted_to": problem.fitted_to,
        "ores": list(problem.ref), "parameters_fitted": list(problem.names), "values": problem.unpack(sol.x),
        "at_bounds": at_bound,
        "optimizer": {"success": bool(sol.success), "message": sol.message, "slsqp_iterations": sol.nit,
                      "least_squares": sol.lsq, "residual_evaluations": sol.nfev, "jacobian_evaluations": sol.njev,
                      "tolerances": {"least_squares_ftol_xtol_gtol": LSQ_TOL, "slsqp_ftol": MINIMAX_FTOL},
                      "jacobian": "exact (implicit function theorem on the steady-state Newton system)",
                      "seconds": time.perf_counter() - t0},
        "solver_failures": {"count": len(problem.failures), "messages": problem.failures[:5]},
        "max_abs_log_ratio": sol.max_abs_residual,
    }


def with_fitted_values(calibration, values: dict):
    """The calibration (in memory) with fitted coefficients and ``lab_`` mill values."""
    coef = {k: v for k, v in values.items() if not k.startswith("lab_")}
    mills = {"lab": {k[len("lab_"):]: v for k, v in values.items() if k.startswith("lab_")}}
    return calibration.with_values(coefficients=coef, mills=mills)


def predict_table(calibration, ores=("A", "B", "C", "D")) -> dict:
    """The table's KPIs of each ore by the full twin of ``calibration`` (lab mill, 70 % critical,
    constant load): the numbers a fit record keeps, independent of the parametric twins."""
    from ..twin import Twin
    from .parametric import TABLE_LOAD_FRAC, TABLE_SPEED_FRAC_CRITICAL

    out = {}
    for ore in ores:
        ss = Twin(ore, mill=calibration.mill, effects=calibration.effects, grid=calibration.grid(),
                  n_mixers=calibration.n_mixers, calibration=calibration) \
            .steady_at_constant_load(speed_frac_critical=TABLE_SPEED_FRAC_CRITICAL, load_frac=TABLE_LOAD_FRAC)
        out[ore_key(ore)] = {"p80_um": ss.p80_um, "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"],
                    "throughput_kg_h": ss.feed_tph * 1000.0}
    return out


def table_errors(predicted: dict, reference: dict | None = None) -> dict:
    """Percent error of each predicted KPI against the table."""
    ref = reference or reference_table()
    return {o: {k: 100.0 * (predicted[o][k] / ref[o][k] - 1.0) for k in KPIS} for o in predicted}
