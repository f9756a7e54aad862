"""A mill preset file `grindtwin size-mill --write-preset PATH` writes is a mill a scene (``mill.preset``), the
CLI (``--mill``) and the Python API (``get_mill``, ``Twin(mill=...)``) run: it was written and read by nothing."""

import json
import re

import pytest

from scenarios.cli import main
from scenarios.errors import SceneError
from scenarios.scene import check_scene, load_scene
from twin import SizeGrid, Twin, TwinInputError, get_mill, power_kw
from twin.calibration import load_calibration
from twin.mill import INDUSTRIAL_PRESET_PATH

from .conftest import BASE_BOUNDS, BASE_SCENE

#: The scene's classification: the mill's own hydrocyclones (no cyclone table: the preset's).
CYCLONES = '\n[effect_options.classification]\nkind = "hydrocyclone"\n'
EFFECTS = 'effects = ["breakage", "transport", "holdup", "cushioning", "power", "classification"]\n'


def _scene(tmp_path, preset: str, name: str = "scene.toml"):
    text = BASE_SCENE.replace('preset = "industrial"', f'preset = "{preset}"')
    text = EFFECTS + text.split("\n", 1)[1] + CYCLONES
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _steady(path, capsys, *extra) -> dict:
    assert main(["steady", "--scene", str(path), "--json", *extra]) == 0
    return json.loads(capsys.readouterr().out)


def _preset(tmp_path, name="sized/my_mill.json", **mill):
    """The shipped preset's record with ``mill`` changes, written as a user's preset file."""
    record = json.loads(INDUSTRIAL_PRESET_PATH.read_text(encoding="utf-8"))
    record["mill"].update(mill)
    path = tmp_path / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record), encoding="utf-8")
    return path


def test_a_written_preset_runs_in_a_scene_as_the_mill_it_sized(tmp_path, capsys):
    """size-mill's own preset file, named by a scene relative to the scene's folder, is the same mill with
    the same cyclones as the shipped preset the same command wrote: the same circuit, number for number."""
    preset = tmp_path / "sized" / "my_mill.json"
    preset.parent.mkdir()
    command = json.loads(INDUSTRIAL_PRESET_PATH.read_text())["command"].split()
    argv = command[1:command.index("--write-preset")] + ["--write-preset", str(preset)]
    assert main(argv) == 0
    capsys.readouterr()
    shipped, own = (_steady(_scene(tmp_path, p, f"{n}.toml"), capsys) for n, p in
                    (("a", "industrial"), ("b", "sized/my_mill.json")))
    for key in ("p80_um", "circulating_load_frac", "power_kw", "cyclone_pressure_kpa"):
        assert own[key] == pytest.approx(shipped[key], rel=1e-6), key
    assert load_scene(tmp_path / "b.toml").mill.diameter_m == pytest.approx(get_mill("industrial").diameter_m)


def test_a_preset_files_own_dimensions_draw_their_own_power(tmp_path, capsys):
    """A larger sized mill in its file: its power is Bond's for its dimensions (D^2.3 L at the same ball filling
    and speed, Rowland's form), in the scene, the CLI's --mill and the API alike."""
    base = get_mill("industrial")
    d, length = 1.2 * base.diameter_m, 1.2 * base.length_m
    path = _preset(tmp_path, diameter_m=d, length_m=length, feed_nominal_tph=45.0)
    ratio = (d / base.diameter_m) ** 2.3 * (length / base.length_m)
    at = 0.7
    assert float(power_kw(get_mill(path), at)) == pytest.approx(ratio * float(power_kw(base, at)), rel=1e-12)
    scene = _steady(_scene(tmp_path, "sized/my_mill.json"), capsys, "--feed-tph", "30")
    shipped = _steady(_scene(tmp_path, "industrial", "shipped.toml"), capsys, "--feed-tph", "30")
    assert scene["power_kw"] == pytest.approx(ratio * shipped["power_kw"], rel=1e-9)
    cal = load_calibration()
    api = Twin("B", mill=get_mill(path, cal.record), calibration=cal, effects=list(cal.effects),
               grid=SizeGrid(**cal.size_grid), n_mixers=cal.n_mixers).steady(feed_tph=30.0).summary()
    for mill in (str(path), "industrial"):
        assert main(["steady", "--mill", mill, "--ore", "B", "--feed-tph", "30", "--json"]) == 0
        cli = json.loads(capsys.readouterr().out)
        assert cli["mill"] == mill
        assert (cli["power_kw"] == pytest.approx(api["power_kw"], rel=1e-9)) == (mill == str(path))


@pytest.mark.parametrize("record, message", [
    (None, "No mill preset file"),
    ({"mill": {}}, "not a mill preset grindtwin wrote.*missing cyclone, sizing, command"),
    ("diameter", "diameter_m"),
    ("[1, 2]", "not a mill preset grindtwin wrote"),
    ("{", "cannot be read as JSON"),
])
def test_a_preset_file_that_is_no_preset_is_refused_before_any_work(tmp_path, capsys, record, message):
    """A missing file, another JSON file, a preset edited to a negative diameter, a broken file: refused by the scene's
    check (naming mill.preset), the CLI (exit 2, the option named) and get_mill, before anything is solved."""
    path = tmp_path / "mill.json"
    if record == "diameter":
        path = _preset(tmp_path, "mill.json", diameter_m=-2.1)
    elif isinstance(record, dict):
        path.write_text(json.dumps(record))
    elif isinstance(record, str):
        path.write_text(record)
    problems = check_scene(_scene(tmp_path, "mill.json"))
    assert len(problems) == 1 and "mill.preset:" in problems[0]
    assert re.search(message, problems[0])
    with pytest.raises(SceneError, match="mill.preset"):
        load_scene(tmp_path / "scene.toml")
    with pytest.raises(SystemExit) as exc:
        main(["steady", "--mill", str(path), "--ore", "B"])
    assert exc.value.code == 2
    assert "argument --mill:" in capsys.readouterr().err
    with pytest.raises(TwinInputError, match=message):
        get_mill(path)


def test_a_misspelt_preset_is_named_with_what_is_allowed(tmp_path):
    problems = check_scene(_scene(tmp_path, "industral"))
    assert problems == [f"{tmp_path / 'scene.toml'}: mill.preset: must be one of 'lab', 'industrial' or a preset "
                        "file ending in .json (`grindtwin size-mill --write-preset PATH` writes one) (did you mean "
                        "'industrial'?) (got 'industral')"]


def test_a_run_records_its_preset_file_and_the_scene_as_run(tmp_path, capsys):
    """A run folder said only `preset = "my_mill.json"` (relative, no digest; a later size-mill --write-preset
    rewrites it) and, without --xlsx, held no copy of the scene: summary.json now records the preset file's
    path and SHA-256 and the scene as it was run, defaults filled in."""
    import hashlib

    path = _preset(tmp_path, diameter_m=2.4, length_m=3.6)
    scene = _scene(tmp_path, "sized/my_mill.json")
    scene.write_text(scene.read_text().replace("duration_h = 8.0", "duration_h = 0.5")
                     .replace('kind = "nmpc"', 'kind = "none"').replace(BASE_BOUNDS, "\n").replace("at_h = 2.0", "at_h = 0.1")
                     .replace("ramp_h = 1.0", "ramp_h = 0.2"))
    assert main(["run", str(scene), "--out", str(tmp_path / "run"), "--quiet", "--no-plots"]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["mill_preset_file"] == {"path": str(path.resolve()),
                                           "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}
    assert summary["scene_as_run"]["mill"]["diameter_m"] == 2.4
    assert summary["scene_as_run"]["effect_options"]["classification"]["kind"] == "hydrocyclone"


def test_a_runs_preset_file_is_hashed_as_loaded_shown_in_its_report_and_workbook_and_a_change_is_warned(tmp_path):
    """summary.json alone named the preset file, hashed after the run: a file rewritten during the run was recorded
    with the new file's hash. It is now hashed as the scene is loaded, a file changed by the run's end is warned of,
    and the report and the workbook's summary show the file and its hash as they show the calibration's."""
    import hashlib

    import pandas as pd

    from scenarios.output.report import write_report
    from scenarios.run import run_scene

    path = _preset(tmp_path)
    scene_path = _scene(tmp_path, "sized/my_mill.json")
    scene_path.write_text(scene_path.read_text().replace("duration_h = 8.0", "duration_h = 0.5")
                          .replace('kind = "nmpc"', 'kind = "none"').replace(BASE_BOUNDS, "\n").replace("at_h = 2.0", "at_h = 0.1")
                          .replace("ramp_h = 1.0", "ramp_h = 0.2"))
    loaded = hashlib.sha256(path.read_bytes()).hexdigest()
    scene = load_scene(scene_path)
    path.write_text(path.read_text() + "\n")  # the same mill, another file: rewritten after the scene was loaded
    out = tmp_path / "run"
    res = run_scene(scene, out, progress=False, plots=False, xlsx=True)
    assert res.summary["mill_preset_file"] == {"path": str(path.resolve()), "sha256": loaded}
    (changed,) = [w for w in res.summary["warnings"] if "mill preset file" in w]
    assert str(path.resolve()) in changed and "changed during the run" in changed
    assert hashlib.sha256(path.read_bytes()).hexdigest()[:12] in changed
    shown = f"{path.resolve()} (sha256 {loaded[:12]})"
    assert f"<th>mill preset file</th><td>{shown}</td>" in write_report(out).read_text(encoding="utf-8")
    book = pd.read_excel(out / "run.xlsx", sheet_name="summary")
    assert book.loc[book["item"] == "mill preset file", "value"].tolist() == [shown]
