"""Calibrations from scenes and the command line: the scene key, the check that refuses a
mismatch, the record of what ran, --calibration, --uncertainty and calibrate's refusals."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios.cli import main
from scenarios.output import write_report
from scenarios.run import run_scene
from scenarios.scene.loader import check_scene
from tests.scenarios.conftest import BASE_SCENE
from tests.scenarios.test_runner import short_pyrite_scene
from twin.calibration import load_calibration
from twin.calibration.files import content_digest


def test_check_refuses_a_scene_whose_effects_differ_from_its_calibration(write_scene):
    lean = BASE_SCENE.replace("calibration_mismatch_ok = true", "calibration = \"dem\"")
    messages = check_scene(write_scene(lean))
    assert len(messages) == 1
    m = messages[0]
    assert "effects:" in m and "['breakage', 'cushioning', 'holdup', 'power', 'transport']" in m
    assert "'rheology'" in m and "calibration 'dem'" in m and "calibration_mismatch_ok = true" in m
    assert check_scene(write_scene(BASE_SCENE)) == []  # the scene that says it means it


def test_check_refuses_an_unknown_calibration(write_scene):
    messages = check_scene(write_scene(BASE_SCENE.replace("calibration_mismatch_ok = true",
                                                          "calibration = \"dme\"")))
    assert len(messages) == 1 and "calibration:" in messages[0] and "'dme'" in messages[0]


@pytest.fixture(scope="module")
def short_scene(tmp_path_factory):
    return short_pyrite_scene(tmp_path_factory.mktemp("cal"), duration_h=0.25)


def test_summary_and_report_record_which_calibration_ran(short_scene, tmp_path):
    from scenarios.scene import load_scene

    out = tmp_path / "run"
    res = run_scene(load_scene(short_scene), out_dir=out, progress=False, plots=False)
    cal = load_calibration("dem")
    assert res.summary["calibration"]["name"] == "dem" and res.summary["calibration"]["sha256"] == cal.sha256
    assert json.loads((out / "summary.json").read_text())["calibration"]["sha256"] == cal.sha256
    html = write_report(out).read_text()
    assert "calibration" in html and cal.sha256[:12] in html


def test_run_with_another_calibration(short_scene, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", str(short_scene), "--calibration", "table", "--out", str(out), "--no-plots", "--quiet"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["calibration"]["name"] == "table" and s["calibration"]["sha256"] == load_calibration("table").sha256


def test_steady_calibration_by_name_and_by_path(capsys):
    argv = ["steady", "--ore", "B", "--feed-tph", "0.031", "--json"]
    assert main(argv) == 0
    dem = json.loads(capsys.readouterr().out)
    assert main(argv + ["--calibration", "table"]) == 0
    table = json.loads(capsys.readouterr().out)
    assert main(argv + ["--calibration", str(load_calibration("table").path)]) == 0
    by_path = json.loads(capsys.readouterr().out)
    assert dem["calibration"]["name"] == "dem" and table["calibration"]["name"] == "table"
    assert table["p80_um"] == by_path["p80_um"] != dem["p80_um"]


def test_steady_uncertainty_prints_intervals(capsys):
    """Each interval beside the replicates' median, said as such: it differs from the point estimate above it (the
    median read as the steady state's own number)."""
    assert main(["steady", "--ore", "B", "--at-constant-load", "--uncertainty", "20"]) == 0
    out = capsys.readouterr().out
    assert "90% intervals over 20 bootstrap replicates" in out and ": the replicates' median [interval]" in out
    for key in ("p80_um", "specific_energy_kwh_t", "throughput_tph"):
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(key) and "[" in ln)
        lo, hi = (float(v) for v in line.split("[")[1].rstrip("]").split(","))
        assert lo <= hi


def test_calibrate_refuses_to_overwrite_a_file_it_did_not_write(tmp_path, capsys):
    foreign = tmp_path / "notes.json"
    foreign.write_text('{"mine": true}')
    assert main(["calibrate", "--from", "dem", "--out", str(foreign)]) == 2
    assert "Refusing to overwrite" in capsys.readouterr().err and foreign.read_text() == '{"mine": true}'
    assert main(["calibrate", "--map", "mineralogy", "--from", "dem", "--out", str(tmp_path / "x.json")]) == 2
    assert not (tmp_path / "x.json").exists()
    # options of the DEM chain with --map mineralogy were recorded in the file's provenance, unused
    capsys.readouterr()
    assert main(["calibrate", "--map", "mineralogy", "--fast", "--seed", "5", "--out", str(tmp_path / "x.json")]) == 2
    assert "--fast, --seed: options of the DEM chain" in capsys.readouterr().err
    assert main(["calibrate", "--seed", "-5", "--out", str(tmp_path / "x.json")]) == 2
    assert "--seed must be >= 0" in capsys.readouterr().err and not (tmp_path / "x.json").exists()
    assert main(["calibrate", "--workers", "0", "--out", str(tmp_path / "x.json")]) == 2
    assert "--workers must be >= 1" in capsys.readouterr().err and not (tmp_path / "x.json").exists()
    assert main(["calibrate", "--from", "dem", "--workers", "2", "--out", str(tmp_path / "x.json")]) == 2
    assert "no DEM test runs" in capsys.readouterr().err and not (tmp_path / "x.json").exists()
    assert main(["calibrate", "--map", "mineralogy", "--workers", "2", "--out", str(tmp_path / "x.json")]) == 2
    assert "--workers: option of the DEM chain" in capsys.readouterr().err


def test_a_fast_calibration_warns_in_one_line_on_the_command_line(tmp_path):
    """A --fast calibration (its DEM step on a few particles) runs, but the command says what it
    is, as its other warnings read: one line, no Python source line."""
    rec = json.loads(json.dumps(load_calibration("dem").record))
    rec["dem"]["settings"]["fast"] = True
    rec["content_sha256"] = content_digest(rec)  # as `grindtwin calibrate --fast` writes it
    path = tmp_path / "quick.json"
    path.write_text(json.dumps(rec))
    command = "import sys; from scenarios.cli import main; sys.exit(main(sys.argv[1:]))"
    res = subprocess.run([sys.executable, "-c", command, "steady", "--ore", "B", "--feed-tph", "0.031", "--speed",
                          "0.70", "--calibration", str(path)],
                         capture_output=True, text=True, timeout=300, cwd=Path(__file__).parents[2])
    assert res.returncode == 0, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if "warning" in ln.lower()]
    sha = hashlib.sha256(path.read_bytes()).hexdigest()[:12]
    assert lines == [f"grindtwin: warning: calibration 'dem' ({path}, sha256 {sha}; made with --fast: a check of the "
                     "machinery on a few particles, not a calibration) (FastCalibrationWarning)"], res.stderr
    assert "not a calibration" in res.stdout and "p80_um" in res.stdout  # and so does the header


def test_a_run_that_means_a_mismatch_records_each_twins(write_scene):
    """calibration_mismatch_ok = true runs the scene, and its notes say every way each twin
    differs from the calibration: the size grid's scheme too, and a separate plant's effects."""
    from scenarios.run.models import build_models
    from scenarios.scene import load_scene
    from twin import SizeGrid

    text = BASE_SCENE.replace("[mill]\n", "[mill]\nsize_classes = { scheme = \"austin\" }\n") + (
        "\n[plant]\nmodel = \"twin\"\neffects = [\"breakage\", \"transport\", \"holdup\", \"power\"]\n")
    models = build_models(load_scene(write_scene(text)))
    cal, scene = models.calibration, load_scene(write_scene(text))
    want = cal.mismatch(scene.effects, SizeGrid(scheme="austin"))
    assert any("size grid" in m and "'austin'" in m for m in want)  # the scheme is a difference
    mine = [n for n in models.notes if n.startswith("calibration_mismatch_ok")]
    assert mine[:len(want)] == [f"calibration_mismatch_ok: {m}" for m in want]
    plant = cal.mismatch(scene.plant.effects, SizeGrid(scheme="austin"))
    assert mine[len(want):] == [f"calibration_mismatch_ok: the plant's {m}" for m in plant]


def test_the_shipped_table_calibration_is_what_its_command_makes(tmp_path, capsys):
    """README's `grindtwin calibrate --map mineralogy` run end to end (a few seconds): it makes
    exactly the shipped table.json's coefficients and mill values. It failed with a KeyError on
    the record it was fitting (the extrapolation note read a fit that did not exist yet). It says
    which fitted numbers ended on a bound of their ranges."""
    out = tmp_path / "table_again.json"
    assert main(["calibrate", "--map", "mineralogy", "--out", str(out)]) == 0
    made, shipped = json.loads(out.read_text()), load_calibration("table").record
    assert made["coefficients"] == shipped["coefficients"] and made["mills"] == shipped["mills"]
    said = capsys.readouterr().out
    assert made["fit"]["at_bounds"] and all(f"{n} " in said for n in made["fit"]["at_bounds"]), said
    command = "grindtwin calibrate --map mineralogy --out twin/calibration/files/table.json"
    assert shipped["provenance"]["command"] == command


def test_a_commands_twin_takes_its_calibrations_effects_grid_and_mixers():
    """`steady --calibration FILE` built the default twin whatever the file was fitted with, and a file fitted
    without cushioning ran with it (a note, exit 0) where a scene of it is refused. The command's twin is now
    the calibration's: its effects, size grid and mixers; so no mismatch."""
    from scenarios.cli.commands import _calibrated_twin
    from twin.calibration import Calibration

    record = json.loads(json.dumps(load_calibration("dem").record))
    record["effects"] = [e for e in record["effects"] if e != "cushioning"]
    record["size_grid"] = {**record["size_grid"], "count": 20}
    record["n_mixers"] = 2
    twin = _calibrated_twin("B", "lab", Calibration(record))
    assert "cushioning" not in twin.model.effect_names and twin.grid.count == 20 and twin.spec.n_mixers == 2
    assert twin.calibration_mismatch == []


def test_uncertainty_on_the_mineralogy_map_says_what_can_give_intervals(capsys):
    """The refusal advised `grindtwin calibrate --replicates N`, which `--map mineralogy` refuses."""
    assert main(["steady", "--ore", "B", "--feed-tph", "0.031", "--calibration", "table", "--uncertainty"]) == 2
    err = capsys.readouterr().err
    assert "mineralogy map has no bootstrap" in err and "--replicates" not in err
