"""A calibration is refused by a twin whose equations give other table KPIs than its fit recorded
(twin.calibration.model_code): the shipped files pass, a refactor passes, a changed term is
refused with the ore, the KPI, both values and the refit command."""

import json
import shutil

import pytest

import twin.mill
from twin import Twin, TwinInputError
from twin.calibration import model_code
from twin.calibration.files import CALIBRATION_DIR, content_digest, load_calibration
from twin.calibration.model_code import source_digest
from twin.calibration.record_checks import dem_step_sha256


@pytest.fixture
def fresh_checks(monkeypatch):
    """No file checked yet in this process, and sources whose digest is not the files' (so the
    table's KPIs are recomputed, as after any edit of the twin)."""
    monkeypatch.setattr(model_code, "_CHECKED", set())
    monkeypatch.setattr(model_code, "model_digest", lambda: "0123456789abcdef")


@pytest.fixture
def dem_copy(tmp_path):
    path = tmp_path / "mine.json"
    shutil.copy(CALIBRATION_DIR / "dem.json", path)
    return path


@pytest.mark.parametrize("name", ["dem", "table"])
def test_shipped_calibrations_reproduce_their_fit(fresh_checks, name):
    cal = load_calibration(name)
    Twin("B", calibration=cal)  # recomputes the table's KPIs: equal to the recorded ones
    assert (cal.path, cal.sha256) in model_code._CHECKED


def test_changed_power_term_is_refused(fresh_checks, monkeypatch, dem_copy):
    """The error of 2026: Bond's power at 0.6x. The old file ran with exit 0 (124 um for 204)."""
    monkeypatch.setattr(twin.mill, "ROWLAND_KW_PER_T", 0.6 * twin.mill.ROWLAND_KW_PER_T)
    with pytest.raises(TwinInputError) as err:
        Twin("B", calibration=str(dem_copy))
    text = str(err.value)
    assert "fitted with other model equations" in text
    assert "fit.predicted" in text and "0123456789abcdef" in text
    assert f"grindtwin calibrate --from {dem_copy} --out {dem_copy}" in text
    # refused again, not remembered as checked
    with pytest.raises(TwinInputError):
        Twin("B", calibration=str(dem_copy))


def test_matching_digest_skips_the_recomputation(monkeypatch, dem_copy):
    record = json.loads(dem_copy.read_text())
    record["model_code"] = {"sha256": "fedcba9876543210"}
    record["content_sha256"] = content_digest(record)  # a file another grindtwin wrote
    dem_copy.write_text(json.dumps(record))
    monkeypatch.setattr(model_code, "_CHECKED", set())
    monkeypatch.setattr(model_code, "model_digest", lambda: "fedcba9876543210")
    monkeypatch.setattr(model_code, "_compare_predictions", lambda *a: pytest.fail("recomputed"))
    Twin("B", calibration=str(dem_copy))


def test_a_recorded_prediction_not_the_models_is_refused(fresh_checks, dem_copy):
    record = json.loads(dem_copy.read_text())
    record["fit"]["predicted"]["C"]["p80_um"] *= 1 + 10 * model_code.PREDICTION_RTOL
    record["content_sha256"] = content_digest(record)  # written so: its model's predictions are not today's
    dem_copy.write_text(json.dumps(record))
    with pytest.raises(TwinInputError, match=r"ore C's p80_um = 2\d\d\.\d+ .*\(-0\.001 %"):
        Twin("C", calibration=str(dem_copy))


def test_bad_model_code_field_is_refused(dem_copy):
    record = json.loads(dem_copy.read_text())
    record["model_code"] = "863f08614574b6d5"
    dem_copy.write_text(json.dumps(record))
    with pytest.raises(TwinInputError, match="'model_code' must be a table with the 'sha256'"):
        load_calibration(str(dem_copy))


def test_digest_ignores_comments_and_docstrings_not_code(tmp_path):
    src = tmp_path / "pkg"
    src.mkdir()
    (src / "m.py").write_text('"""Doc."""\n\ndef f(x):\n    """What f does."""\n    return 2 * x  # twice\n')
    base = source_digest(src)
    (src / "m.py").write_text('"""Other words."""\n\n\ndef f(x):\n    # a comment\n    return 2 * x\n')
    assert source_digest(src) == base
    (src / "m.py").write_text('"""Doc."""\n\ndef f(x):\n    return 3 * x\n')
    changed = source_digest(src)
    assert changed != base
    (src / "sub").mkdir()
    (src / "sub" / "n.py").write_text("y = 1\n")
    assert source_digest(src, skip=("sub",)) == changed != source_digest(src)


def test_new_calibration_records_the_model_digest():
    from twin.calibration.files import base_record

    assert base_record("x", "dem", "d")["model_code"]["sha256"] == model_code.model_digest()


def test_from_records_the_sources_and_says_when_its_dem_step_is_another_dems(tmp_path, capsys, monkeypatch):
    """--from a DEM step run by other DEM sources says so and records it; the new file carries the
    model's digest, so a twin built from it needs no recomputation."""
    from twin.calibration import main

    record = json.loads((CALIBRATION_DIR / "dem.json").read_text())
    record["dem"]["sources_sha256"] = "0000aaaa0000aaaa"
    record["dem"]["sha256"] = dem_step_sha256(record["dem"])  # a step that ran so (an edited one is refused)
    source, out = tmp_path / "old.json", tmp_path / "mine.json"
    source.write_text(json.dumps(record))
    assert main(["--from", str(source), "--replicates", "0", "--out", str(out), "--quiet"]) == 0
    note = "the DEM step was run by other DEM sources (digest 0000aaaa0000aaaa; now "
    assert note in capsys.readouterr().err
    made = load_calibration(out)
    assert made.record["dem_step_from"]["note"].startswith(note)
    assert made.record["model_code"]["sha256"] == model_code.model_digest()
    monkeypatch.setattr(model_code, "_CHECKED", set())
    monkeypatch.setattr(model_code, "_compare_predictions", lambda *a: pytest.fail("recomputed"))
    Twin("B", calibration=str(out))
    record = json.loads(out.read_text())
    record["dem"]["sources_sha256"] = model_code.dem_step_digest()
    assert model_code.dem_step_note(record["dem"]) is None


def test_a_record_given_as_a_dict_is_checked_too(fresh_checks, monkeypatch):
    record = json.loads((CALIBRATION_DIR / "table.json").read_text())
    Twin("B", calibration=record)  # its own predictions: accepted
    monkeypatch.setattr(twin.mill, "ROWLAND_KW_PER_T", 0.6 * twin.mill.ROWLAND_KW_PER_T)
    record["description"] += " (a copy)"  # another record: checked again
    with pytest.raises(TwinInputError, match="fitted with other model equations"):
        Twin("B", calibration=record)
