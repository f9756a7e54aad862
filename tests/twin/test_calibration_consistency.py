"""A calibration records what it was fitted with (effects, size grid, mixers of its mill, the
reference table) and is not used silently with something else: the Python API notes a twin
that differs from it, scenes refuse one unless ``calibration_mismatch_ok = true`` (then note it
once), and a file fitted to another reference table than the shipped one is refused."""

import json

import pytest

from scenarios.errors import SceneError
from scenarios.run.models import build_models
from scenarios.scene import check_scene, load_scene
from twin import SizeGrid, Twin, TwinInputError
from twin.calibration import CALIBRATION_DIR, load_calibration, shipped_names
from twin.calibration import reference
from twin.twin import DEFAULT_EFFECTS


def test_the_default_twin_has_no_mismatch_and_a_twin_without_rheology_says_what_to_do():
    """The Python API builds the twin (benchmarks do so on purpose) and notes it, in every steady
    state: the missing effect, the command that refits and the scene key that means it."""
    assert Twin("B").calibration_mismatch == [] and Twin("B").notes == []
    twin = Twin("B", effects=[e for e in DEFAULT_EFFECTS if e != "rheology"])
    (problem,) = twin.calibration_mismatch
    assert "missing ['rheology']" in problem
    notes = twin.steady(feed_tph=0.031).notes
    (note,) = [n for n in notes if problem in n]
    assert "grindtwin calibrate" in note and "calibration_mismatch_ok" in note


def test_a_twin_on_another_grid_or_its_own_breakage_map_is_noted_too():
    """The grid is compared, and a breakage_map does not hide it: the effects still read the
    calibration's coefficients and the mill its fitted values."""
    coarse = SizeGrid(top_um=6700.0, ratio=2.0, count=13)
    twin = Twin("B", grid=coarse, breakage_map=lambda ore, coef: load_calibration().breakage(ore))
    (problem,) = twin.calibration_mismatch
    assert problem.startswith("size grid") and any(problem in n for n in twin.notes)


def test_mixers_are_compared_on_the_calibrations_own_mill_only():
    """The lab mill's fitted values were fitted with the record's n_mixers equal mixers: four, or
    Whiten's unequal shares, on the lab mill contradict the fit; on the industrial mill the mixers
    are that mill's own."""
    cal = load_calibration()
    assert cal.mill == "lab" and cal.n_mixers == 3
    assert cal.mixers_mismatch("lab", [1 / 3] * 3) == [] and cal.mixers_mismatch("industrial", [1.0]) == []
    (unequal,) = cal.mixers_mismatch("lab", [0.7, 0.15, 0.15])
    assert "mixer_volume_fracs" in unequal and "n_mixers = 3" in unequal
    four = Twin("B", n_mixers=4)
    (problem,) = four.calibration_mismatch
    assert "n_mixers = 4" in problem and "'lab'" in problem and any(problem in n for n in four.notes)
    assert Twin("B", mill="industrial", n_mixers=1).calibration_mismatch == []


LAB_SCENE = """\
{ok}effects = ["breakage", "transport", "holdup", "speed", "cushioning", "rheology", "power", "classification"]
[scene]
name = "lab_mixers"
duration_h = 0.2
sample_period_h = 0.05
[mill]
preset = "lab"
n_mixers = 4
[ores.B]
type = "B"
[feed]
blend = {{ B = 1.0 }}
feed_tph = 0.031
speed_frac_critical = 0.70
"""


def test_a_lab_scene_with_four_mixers_is_refused_unless_it_means_it_then_noted_once(tmp_path):
    refused = tmp_path / "refused.toml"
    refused.write_text(LAB_SCENE.format(ok=""))
    (message,) = check_scene(refused)
    assert f"{refused}: mill.n_mixers: " in message and "n_mixers = 4" in message
    assert "calibration_mismatch_ok" in message
    meant = tmp_path / "meant.toml"
    meant.write_text(LAB_SCENE.format(ok="calibration_mismatch_ok = true\n"))
    assert check_scene(meant) == []
    scene = load_scene(meant)
    scene.calibration_mismatch_ok = False  # the runner refuses it too, past grindtwin check
    with pytest.raises(SceneError, match="n_mixers = 4.*calibration_mismatch_ok"):
        build_models(scene)
    models = build_models(load_scene(meant))
    mentions = [n for n in models.notes if "n_mixers = 4" in n]
    assert len(mentions) == 1 and mentions[0].startswith("calibration_mismatch_ok: ")
    steady = models.plant.steady(feed_tph=0.031).notes  # what `grindtwin steady --scene` prints
    assert len([n for n in steady if "n_mixers = 4" in n]) == 1


def test_a_separate_plant_with_other_mixers_on_the_lab_mill_is_refused_at_its_key(tmp_path):
    path = tmp_path / "plant.toml"
    path.write_text(LAB_SCENE.format(ok="").replace("n_mixers = 4\n", "")
                    + '[plant]\nmodel = "twin"\nn_mixers = 2\n')
    (message,) = check_scene(path)
    assert f"{path}: plant.n_mixers: " in message and "n_mixers = 2" in message


def test_the_shipped_calibrations_were_fitted_to_the_shipped_table():
    now = reference.reference_identity()["sha256"]
    for name in shipped_names():
        record = json.loads((CALIBRATION_DIR / f"{name}.json").read_text())
        assert record["fit"]["fitted_to"]["sha256"] == now, name
        assert load_calibration(name).name == name


def test_a_calibration_fitted_to_another_table_is_refused_naming_both_hashes(tmp_path):
    record = json.loads((CALIBRATION_DIR / "table.json").read_text())
    now = record["fit"]["fitted_to"]["sha256"]
    record["fit"]["fitted_to"]["sha256"] = old = "0" * 64
    path = tmp_path / "old.json"
    path.write_text(json.dumps(record))
    for spec, where in ((path, str(path)), (record, "the calibration record")):
        with pytest.raises(TwinInputError) as err:
            load_calibration(spec)
        text = str(err.value)
        assert where in text and old in text and now in text and "grindtwin calibrate" in text


def test_an_edited_reference_table_refuses_the_calibrations_fitted_to_it(tmp_path, monkeypatch):
    """Someone edits the shipped table after the fit: every calibration fitted to it is refused
    (even one already read in this process), naming its file and both hashes."""
    before = reference.reference_identity()["sha256"]
    load_calibration("table")  # read and cached before the edit
    edited = tmp_path / "reference_table.csv"
    edited.write_text(reference.REFERENCE_TABLE_PATH.read_text() + "\n# edited\n")
    monkeypatch.setattr(reference, "REFERENCE_TABLE_PATH", edited)
    after = reference.reference_identity()["sha256"]
    assert after != before
    with pytest.raises(TwinInputError) as err:
        load_calibration("table")
    text = str(err.value)
    assert str(CALIBRATION_DIR / "table.json") in text and before in text and after in text
    assert "grindtwin calibrate --map mineralogy" in text
    assert load_calibration("table", check_table=False).name == "table"  # for reusing a file's DEM step only
