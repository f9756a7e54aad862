"""The shipped calibration file is the output of `grindtwin calibrate` for the code as it is:
re-predicting with its values gives back the numbers it recorded (regenerate it with the
command when the model changes, never by editing it)."""

import numpy as np
import pytest

from twin.calibration import table as calibration
from twin.calibration import shipped_calibration


def test_shipped_file_records_its_command_versions_and_errors():
    cal = shipped_calibration()
    assert cal["provenance"]["command"].startswith("grindtwin calibrate")
    for key in ("python", "numpy", "scipy", "casadi", "created"):
        assert cal["provenance"][key]
    assert set(cal["fit"]["error_pct"]) == {"A", "B", "C", "D"}


def test_shipped_values_reproduce_the_recorded_predictions():
    cal = shipped_calibration()
    values = dict(cal["coefficients"])
    values.update({f"lab_{k}": v for k, v in cal["mills"]["lab"].items()})
    pred = calibration.predict(values)
    for ore, kpis in cal["fit"]["predicted"].items():
        for key, value in kpis.items():
            assert pred[ore][key] == pytest.approx(value, rel=1e-6), (ore, key)


def test_calibrated_p80_order_follows_hardness():
    pred = shipped_calibration()["fit"]["predicted"]
    p80 = [pred[o]["p80_um"] for o in "ABCD"]
    energy = [pred[o]["specific_energy_kwh_t"] for o in "ABCD"]
    assert p80 == sorted(p80)  # soft ores give a coarser product ...
    assert energy[0] > energy[3]  # ... for less energy per tonne (MISSION.md reference table)


def test_minimax_step_reaches_the_linear_programme_optimum_and_the_pnorm_does_not_beat_it():
    """On an overdetermined linear system the max-norm optimum is a linear programme (an
    independent reference): min t s.t. -t <= A z - b <= t, lo <= z <= hi."""
    from scipy.optimize import linprog

    from twin.calibration import fit_log_ratios

    rng = np.random.default_rng(3)
    A, b = rng.normal(size=(12, 3)), rng.normal(size=12)
    lo, hi = np.array([-5.0, -5.0, 0.2]), np.array([5.0, 5.0, 5.0])  # the third bound is active
    lp = linprog(np.r_[0, 0, 0, 1.0], A_ub=np.block([[A, -np.ones((12, 1))], [-A, -np.ones((12, 1))]]),
                 b_ub=np.r_[b, -b], bounds=[*zip(lo, hi), (0, None)])
    assert lp.success
    res = fit_log_ratios(lambda z: A @ z - b, np.zeros(3) + 0.5, lo, hi, max_nfev=100)
    assert res.success and np.all((res.x >= lo) & (res.x <= hi))
    assert res.max_abs_residual == pytest.approx(lp.fun, rel=1e-5)
    pn = fit_log_ratios(lambda z: A @ z - b, np.zeros(3) + 0.5, lo, hi, max_nfev=100, final="pnorm")
    assert pn.max_abs_residual >= lp.fun * (1 - 1e-9)
    with pytest.raises(ValueError, match="'final'"):
        fit_log_ratios(lambda z: A @ z - b, np.zeros(3), lo, hi, max_nfev=5, final="max")


def test_a_fit_counts_the_solvers_own_failures_and_lets_any_other_error_through(monkeypatch):
    """The table fits turned any exception into a residual of 10, so a bug looked like a bad
    region of parameter space; only the steady state's SolverError is such a point now."""
    from twin.calibration import dem_link, table
    from twin.calibration.reference import reference_table
    from twin.errors import ModelError, SolverError

    ref = reference_table()
    z = table._pack(table.START)

    def solver_fails(values, *args, **kwargs):
        raise SolverError("Steady state did not converge")

    failures = []
    monkeypatch.setattr(table, "predict", solver_fails)
    assert np.all(table._residuals(z, ref, failures) == 10.0) and failures == ["Steady state did not converge"]
    for bug in (ModelError("b must be lower-triangular"), ZeroDivisionError("division by zero")):
        def raises(values, *args, bug=bug, **kwargs):
            raise bug
        monkeypatch.setattr(table, "predict", raises)
        with pytest.raises(type(bug)):
            table._residuals(z, ref, [])
        monkeypatch.setattr(dem_link, "predict", raises)
        with pytest.raises(type(bug)):
            dem_link.fit_table({}, max_nfev=2)

    calls = []

    def first_fails(values, record=None):  # the first point fails, then the table itself
        calls.append(1)
        if len(calls) == 1:
            raise SolverError("Steady state did not converge")
        return {o: dict(ref[o]) for o in ref}

    monkeypatch.setattr(dem_link, "predict", first_fails)
    fit = dem_link.fit_table({}, max_nfev=2)
    assert fit["solver_failures"]["count"] == 1
    assert fit["solver_failures"]["first"] == "Steady state did not converge"
