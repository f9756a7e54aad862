"""Calibrations as named objects: the shipped files say what they are and reproduce what they
recorded (regenerate them with their command when the model changes, never by editing them);
the table step converges and counts its solver failures; new files go where they are told and
never over a file grindtwin did not write."""

import json
import math

import numpy as np
import pytest

from tests.conftest import strict_json
from twin import FastCalibrationWarning, SizeGrid, SolverError, Twin, TwinInputError
from twin.calibration import (DEFAULT_CALIBRATION, DEM_FITTED, DEM_NAMES, Calibration, check_writable,
                              fit_log_ratios, load_calibration, predict_table, shipped_names)
from twin.calibration.fitting import SOLVER_FAILURE_RESIDUAL, TableProblem
from twin.calibration.files import content_digest, default_output_path, write_calibration
from twin.twin import DEFAULT_EFFECTS


@pytest.fixture(scope="module", params=["dem", "table"])
def shipped(request):
    return load_calibration(request.param)


def test_the_default_is_the_dem_chain():
    assert DEFAULT_CALIBRATION == "dem" and {"dem", "table"} <= set(shipped_names())
    assert Twin("B").calibration.name == "dem" and Twin("B").calibration.breakage_map == "dem"


def test_a_shipped_file_says_what_it_is_and_where_it_came_from(shipped):
    rec = shipped.record
    assert rec["effects"] == list(DEFAULT_EFFECTS) and rec["mill"] == "lab" and rec["n_mixers"] == 3
    assert SizeGrid(**rec["size_grid"]) == SizeGrid()
    assert rec["provenance"]["command"].startswith("grindtwin calibrate")
    for key in ("python", "numpy", "scipy", "casadi", "created"):
        assert rec["provenance"][key]
    assert rec["fit"]["fitted_to"]["path"] == "twin/calibration/data/reference_table.csv"
    assert set(shipped.fitted) == set(rec["fit"]["parameters_fitted"])
    for name, item in shipped.fitted.items():
        assert item["value"] == pytest.approx(rec["fit"]["values"][name], rel=1e-12)
        assert len(item["why_not_derivable"]) > 30, name


def test_shipped_values_reproduce_the_recorded_predictions(shipped):
    pred = predict_table(shipped)
    for ore, kpis in shipped.record["fit"]["predicted"].items():
        for key, value in kpis.items():
            assert pred[ore][key] == pytest.approx(value, rel=1e-6), (shipped.name, ore, key)


def test_the_table_step_converged_without_solver_failures(shipped):
    opt = shipped.record["fit"]["optimizer"]
    assert opt["success"], opt["message"]
    assert shipped.record["fit"]["solver_failures"]["count"] == 0
    assert "exact" in opt["jacobian"]


def test_a_fit_that_did_not_converge_is_said_with_every_answer():
    """A calibration written after its optimizer stopped short (``grindtwin calibrate`` prints "NOT
    converged" once) ran silently ever after: every steady state now carries the note."""
    record = json.loads(json.dumps(load_calibration("table").record))
    assert not any("did not converge" in n for n in Twin("B", calibration=record).steady().notes)
    record["fit"]["optimizer"] |= {"success": False, "message": "Iteration limit reached"}
    notes = Twin("B", calibration=record).steady().notes
    assert any("did not converge" in n and "Iteration limit reached" in n and "'table'" in n for n in notes), notes


def test_the_dem_chain_fits_only_ore_independent_numbers():
    cal = load_calibration("dem")
    assert tuple(cal.record["fit"]["parameters_fitted"]) == DEM_NAMES == tuple(DEM_FITTED)
    # nothing fitted is per ore: no fitted name mentions an ore, and every ore's breakage
    # parameters come from the laws and the mineralogy alone
    assert not any(n.endswith(("_A", "_B", "_C", "_D")) for n in DEM_NAMES)
    assert len(DEM_NAMES) <= 8


def test_names_paths_and_refusals(tmp_path):
    cal = load_calibration("dem")
    assert load_calibration(cal.path) is cal  # the same file, read once
    with pytest.raises(TwinInputError, match="shipped name .*dem.*table"):
        load_calibration("dme")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"coefficients": {}}))
    with pytest.raises(TwinInputError, match="not a grindtwin calibration file"):
        load_calibration(bad)


def test_mismatch_names_both_lists():
    cal = load_calibration("dem")
    assert cal.mismatch(DEFAULT_EFFECTS + ("sensor_delay",), SizeGrid()) == []  # a measurement effect
    msgs = cal.mismatch(["breakage", "transport"], SizeGrid(count=7, ratio=2.5))
    assert len(msgs) == 2
    assert "['breakage', 'transport']" in msgs[0] and "'rheology'" in msgs[0]
    assert "'count': 7" in msgs[1] and "'count': 25" in msgs[1]


def test_new_files_never_overwrite_what_grindtwin_did_not_write(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = default_output_path("dem")
    assert out.parent == tmp_path and not out.exists()
    foreign = tmp_path / "notes.json"
    foreign.write_text('{"mine": true}')
    with pytest.raises(TwinInputError, match="Refusing to overwrite"):
        check_writable(foreign)
    assert foreign.read_text() == '{"mine": true}'
    rec = dict(load_calibration("table").record, name="copy")
    written = write_calibration(tmp_path / "copy.json", rec)
    assert written.name == "copy" and check_writable(tmp_path / "copy.json")  # its own file: allowed
    assert load_calibration(tmp_path / "copy.json").sha256 == written.sha256


def test_a_calibration_file_is_strict_json_with_an_undefined_number(tmp_path):
    """A DEM step in which no test had a force mismatch records its mean as NaN (``quasi_static_mismatch_rel``):
    the file held the token NaN, no JSON (many readers refuse the file). It is null, the file reads back as
    grindtwin's (its content_sha256 is of what was written), and one an earlier grindtwin wrote with the token
    still does."""
    rec = dict(json.loads(json.dumps(load_calibration("dem").record)), name="strict")
    rec["dem"]["ores"]["A"]["quasi_static_mismatch_rel"] = math.nan
    written = write_calibration(tmp_path / "strict.json", rec)
    back = strict_json((tmp_path / "strict.json").read_text(encoding="utf-8"))
    assert back["dem"]["ores"]["A"]["quasi_static_mismatch_rel"] is None
    assert load_calibration(tmp_path / "strict.json").sha256 == written.sha256
    old = dict(back, name="old")  # as written before: the token NaN, and the digest of that text
    old["dem"]["ores"]["A"]["quasi_static_mismatch_rel"] = math.nan
    old["content_sha256"] = content_digest(old, strict=False)
    (tmp_path / "old.json").write_text(json.dumps(old, indent=1) + "\n", encoding="utf-8")
    assert load_calibration(tmp_path / "old.json").name == "old" and check_writable(tmp_path / "old.json")


@pytest.mark.parametrize("command_fast,dem_fast", [(True, True), (False, True), (True, False)],
                         ids=["--fast", "--from a --fast file", "--from a full file --fast"])
def test_a_fast_calibration_says_so_wherever_it_is_used(tmp_path, command_fast, dem_fast):
    """`grindtwin calibrate --fast` runs the DEM step on a few particles, a check of the machinery:
    its file runs, but every use warns and every label and record says what it is, also for a file
    made --from it. --from a full DEM step, --fast only cuts the bootstrap: not flagged."""
    shipped = load_calibration("dem")
    assert not shipped.fast and "fast" not in shipped.identity() and "--fast" not in shipped.label()
    rec = json.loads(json.dumps(shipped.record))
    rec["provenance"]["fast"], rec["dem"]["settings"]["fast"] = command_fast, dem_fast
    if dem_fast:
        with pytest.warns(FastCalibrationWarning, match="made with --fast: a check of the machinery"):
            cal = write_calibration(tmp_path / "quick.json", rec)
    else:
        cal = write_calibration(tmp_path / "quick.json", rec)  # no warning: the suite turns one into an error
    assert cal.fast is dem_fast and cal.identity().get("fast", False) is dem_fast
    assert ("not a calibration" in cal.label()) is dem_fast
    twin = Twin("B", calibration=cal.path)  # read once per process: the warning came with the first read
    assert twin.calibration is cal


def test_a_failed_steady_state_is_a_counted_rejected_point(monkeypatch):
    problem = TableProblem(load_calibration("dem"), ("dem_capture_scale",), {"dem_capture_scale": (1e-4, 1e4)},
                           ores=("B",))

    def fail(values, with_gradient=True):
        raise SolverError("Steady state not found (test)")

    monkeypatch.setattr(problem.twins["B"], "kpis", fail)
    r, J = problem.evaluate(np.array([math.log(0.02)]))
    assert np.all(r == SOLVER_FAILURE_RESIDUAL) and np.all(J == 0)
    assert problem.failures == ["Steady state not found (test)"]
    monkeypatch.setattr(problem.twins["B"], "kpis", lambda *a, **k: (_ for _ in ()).throw(ValueError("bug")))
    with pytest.raises(ValueError, match="bug"):  # anything else is not swallowed
        problem.evaluate(np.array([math.log(0.03)]))


def test_minimax_step_reaches_the_linear_programme_optimum():
    """On an overdetermined linear system the max-norm optimum is a linear programme (an
    independent reference): min t s.t. -t <= A z - b <= t, lo <= z <= hi."""
    from scipy.optimize import linprog

    rng = np.random.default_rng(3)
    A, b = rng.normal(size=(12, 3)), rng.normal(size=12)
    lo, hi = np.array([-5.0, -5.0, 0.2]), np.array([5.0, 5.0, 5.0])  # the third bound is active
    lp = linprog(np.r_[0, 0, 0, 1.0], A_ub=np.block([[A, -np.ones((12, 1))], [-A, -np.ones((12, 1))]]),
                 b_ub=np.r_[b, -b], bounds=[*zip(lo, hi), (0, None)])
    assert lp.success
    res = fit_log_ratios(lambda z: A @ z - b, lambda z: A, np.zeros(3) + 0.5, lo, hi, max_iter=100)
    assert res.success and np.all((res.x >= lo) & (res.x <= hi))
    assert res.max_abs_residual == pytest.approx(lp.fun, rel=1e-6)
    ls = np.linalg.lstsq(A, b, rcond=None)[0]
    assert np.max(np.abs(A @ ls - b)) > lp.fun * 1.05  # least squares alone would not do


def test_a_calibration_in_memory_runs_with_its_values():
    cal = load_calibration("dem")
    faster = cal.with_values(coefficients={"dem_capture_scale": 2 * cal.coefficients["dem_capture_scale"]})
    assert isinstance(faster, Calibration) and faster.sha256 is None
    a = Twin("B", calibration=cal).steady(0.031, 0.70)
    b = Twin("B", calibration=faster).steady(0.031, 0.70)
    assert b.p80_um < a.p80_um  # twice the capture: faster breakage, a finer product
