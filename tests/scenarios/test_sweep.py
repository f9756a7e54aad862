"""What-if sweeps: case expansion, checked key paths, local pool and Dask give one table."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from scenarios.errors import RunError, SceneError
from scenarios.scene.loader import read_toml
from scenarios.run.preflight import run_problems
from scenarios.run.sweep import expand_cases, parse_vary, run_sweep, validate_cases

VARY = {"feed.feed_tph": [25.0, 30.0, 44.0], "controller.weights.p80": [1.0, 2.0]}


def cheap_kpis(scene):
    """A pure-Python stand-in for the runner; fails on purpose above 40 t/h."""
    feed = scene.feed.feed_tph
    if feed > 40:
        raise RuntimeError(f"mill overloaded at {feed} t/h")
    return {"p80_um": 150 + 2 * feed, "score": feed * scene.controller.weights.p80}


def test_cartesian_expansion_sets_every_combination_and_leaves_the_base_alone(write_scene):
    base = read_toml(write_scene())
    cases = expand_cases(base, VARY)
    assert [c.values for c in cases] == [
        {"feed.feed_tph": f, "controller.weights.p80": w} for f in VARY["feed.feed_tph"]
        for w in VARY["controller.weights.p80"]]
    assert cases[5].data["feed"]["feed_tph"] == 44.0
    assert cases[5].data["controller"]["weights"] == {"p80": 2.0}  # created where absent
    assert base["feed"]["feed_tph"] == 30.0 and "weights" not in base["controller"]


def test_paired_expansion_zips_and_needs_equal_lengths(write_scene):
    base = read_toml(write_scene())
    cases = expand_cases(base, {"feed.feed_tph": [25.0, 35.0],
                                "feed.schedule[0].blend": [{"B": 1.0}, {"D": 1.0}]}, "paired")
    assert len(cases) == 2 and cases[1].data["feed"]["schedule"][0]["blend"] == {"D": 1.0}
    with pytest.raises(SceneError, match="equal length"):
        expand_cases(base, VARY, "paired")


@pytest.mark.parametrize("key,fragment", [
    ("feed.feed_tp", "'feed_tp' is not a key of feed (did you mean 'feed_tph'?)"),
    ("controler.kind", "'controler' is not a key of the scene (did you mean 'controller'?)"),
    ("feed.schedule[3].at_h", "feed.schedule has 1 entries in the scene file; index 3"),
])
def test_unknown_key_path_is_refused_with_close_matches(write_scene, key, fragment):
    with pytest.raises(SceneError) as info:
        expand_cases(read_toml(write_scene()), {key: [1.0]})
    assert fragment in str(info.value)


def test_controller_keys_on_a_scene_without_controller_are_refused(write_scene):
    """Four identical rows, no word: the open-loop scene's controller keys change nothing."""
    base = read_toml(write_scene())
    base["controller"] = {**base.get("controller", {}), "kind": "none"}
    with pytest.raises(SceneError, match="controller.horizon_steps: the scene has no controller"):
        expand_cases(base, {"controller.horizon_steps": [5, 50]})
    assert len(expand_cases(base, {"controller.kind": ["none", "pi"], "controller.horizon_steps": [5, 50]})) == 4
    # the power and load readings only a controller reads: refused too (two identical runs, no word)
    with pytest.raises(SceneError, match="sensors.power_noise_kw: the scene has no controller"):
        expand_cases(base, {"sensors.power_noise_kw": [0.0, 50.0]})
    # what an open loop reads (the KPIs' target and band, a start at the target) was refused as idle
    for key, values in (("controller.target_p80_um", [200.0, 260.0]), ("controller.load_band_frac", [[0.8, 1.2],
                                                                                                      [0.9, 1.1]]),
                        ("sensors.p80_noise_um", [0.0, 5.0])):
        assert len(expand_cases(base, {key: values})) == 2


def test_an_effect_option_nested_in_its_table_can_be_swept():
    """effect_options.classification.cyclone.d50c_um was refused ("not a key ...; allowed: " and
    nothing): below an effect's options the schema is free-form and the effect checks the keys."""
    from pathlib import Path

    moly = Path(__file__).resolve().parents[2] / "scenarios" / "molycop_ballsim.toml"
    cases = expand_cases(read_toml(moly), {"effect_options.classification.cyclone.d50c_um": [150.0, 220.0]})
    assert [c.data["effect_options"]["classification"]["cyclone"]["d50c_um"] for c in cases] == [150.0, 220.0]
    assert cases[0].data["effect_options"]["classification"]["cyclone"]["count"] == 6  # the rest kept


MOLYCOP = Path(__file__).resolve().parents[2] / "scenarios" / "molycop_ballsim.toml"


@pytest.mark.parametrize("key,fragment", [
    ("effect_options.classification.cyclone.d50_um",
     "'d50_um' is not a key of effect_options.classification.cyclone (did you mean 'd50c_um'?)"),
    ("effect_options.classification.cyclon.d50c_um",
     "'cyclon' is not a key of effect_options.classification (did you mean 'cyclone'?)"),
    ("effect_options.clasification.kind", "'clasification' is not a key of effect_options (did you mean "
                                          "'classification'?)"),
    ("plant.effect_options.classification.cyclone.d50_um",
     "'d50_um' is not a key of plant.effect_options.classification.cyclone (did you mean 'd50c_um'?)"),
    ("effect_options.classification.kind.grate", "effect_options.classification.kind takes one of 'grate', "
                                                 "'hydrocyclone', with no keys below it"),
])
def test_a_misspelt_key_inside_an_effects_options_is_refused_before_any_case(key, fragment):
    """Below effect_options the schema is free-form; the key path is checked against the effects'
    declared options (and the cyclone table's fields) up front, not once per case."""
    with pytest.raises(SceneError) as info:
        expand_cases(read_toml(MOLYCOP), {key: [150.0, 220.0]})
    assert f"sweep: unknown key path {key!r}" in str(info.value)
    assert fragment in str(info.value)
    assert "case 0" not in str(info.value)


def test_sweep_command_refuses_a_misspelt_cyclone_field_with_exit_2_and_runs_nothing(monkeypatch, capsys):
    from scenarios.cli import commands
    from tests.scenarios.test_cli import grindtwin

    ran = []
    monkeypatch.setattr(commands, "sweep_case", lambda scene: ran.append(scene) or {})
    assert grindtwin(["sweep", str(MOLYCOP), "--vary", "effect_options.classification.cyclone.d50_um=150,200",
                      "--workers", "1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "unknown key path 'effect_options.classification.cyclone.d50_um'" in err
    assert "did you mean 'd50c_um'?" in err and err.count("d50_um") == 2  # the key and its step, once
    assert ran == []


def test_an_invalid_case_is_refused_before_anything_runs(write_scene):
    with pytest.raises(SceneError) as info:
        run_sweep(write_scene(), {"feed.speed_frac_critical": [0.7, 1.2]}, cheap_kpis, problems=None,
                  workers=1, progress=False)
    assert "case 1 (feed.speed_frac_critical=1.2)" in str(info.value)
    assert "less than 1" in str(info.value)


def test_parse_vary_reads_lists_ranges_and_tables():
    assert parse_vary("feed.feed_tph=25,30,35") == ("feed.feed_tph", [25, 30, 35])
    assert parse_vary("feed.feed_tph=25:35:5") == ("feed.feed_tph", [25, 30, 35])
    assert parse_vary("controller.kind=none,nmpc") == ("controller.kind", ["none", "nmpc"])
    assert parse_vary("feed.blend={B=1.0},{B=0.6,D=0.4}") == \
        ("feed.blend", [{"B": 1.0}, {"B": 0.6, "D": 0.4}])
    key, values = parse_vary("feed.speed_frac_critical=0.65:0.75:0.05")
    assert values == pytest.approx([0.65, 0.70, 0.75])


def test_failing_case_is_reported_and_the_others_kept(write_scene):
    table = run_sweep(write_scene(), VARY, cheap_kpis, problems=None, workers=1, progress=False)
    assert list(table.columns) == ["case", "feed.feed_tph", "controller.weights.p80",
                                   "p80_um", "score", "error"]
    failed = table[table["error"].notna()]
    assert list(failed["case"]) == [4, 5]
    assert failed["error"].str.contains("RuntimeError: mill overloaded at 44.0 t/h").all()
    assert table.loc[table["error"].isna(), "p80_um"].tolist() == [200, 200, 210, 210]


def test_local_pool_and_dask_cluster_give_identical_tables(write_scene):
    distributed = pytest.importorskip("distributed")
    path = write_scene()
    serial = run_sweep(path, VARY, cheap_kpis, problems=None, workers=1, progress=False)
    pooled = run_sweep(path, VARY, cheap_kpis, problems=None, workers=2, progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        on_dask = run_sweep(path, VARY, cheap_kpis, problems=None, scheduler=cluster, progress=False)
    pd.testing.assert_frame_equal(pooled, serial)
    pd.testing.assert_frame_equal(on_dask, serial)


@pytest.mark.slow
def test_dask_worker_processes_give_the_same_table(write_scene):
    distributed = pytest.importorskip("distributed")
    path = write_scene()
    serial = run_sweep(path, VARY, cheap_kpis, problems=None, workers=1, progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        on_dask = run_sweep(path, VARY, cheap_kpis, problems=None, scheduler=cluster.scheduler_address,
                            progress=False)
    pd.testing.assert_frame_equal(on_dask, serial)


def test_a_run_case_that_cannot_reach_worker_processes_is_refused_clearly(write_scene):
    with pytest.raises(RunError, match="module-level function, or workers=1"):
        run_sweep(write_scene(), VARY, lambda scene: {}, problems=None, workers=2, progress=False)


@pytest.mark.parametrize("text,fragment", [
    ("feed.feed_tph=nan:30:1", "start:stop:step must be finite numbers"),
    ("feed.feed_tph=1:inf:1", "start:stop:step must be finite numbers"),
    ("feed.feed_tph=25,nan", "values must be finite numbers (got nan)"),
    ("feed.feed_tph=inf", "values must be finite numbers (got inf)"),
])
def test_parse_vary_refuses_nan_and_infinity(text, fragment):
    with pytest.raises(SceneError) as info:
        parse_vary(text)
    assert fragment in str(info.value)


def test_a_huge_sweep_is_refused_before_any_case_is_built_unless_allowed(write_scene):
    from scenarios.run.sweep import MAX_CASES

    path = write_scene()
    huge = {"feed.feed_tph": list(range(600)), "controller.weights.p80": list(range(500))}
    with pytest.raises(SceneError, match=r"300,000 cases, more than the limit of 1,000; .*--max-cases 300000"):
        run_sweep(path, huge, cheap_kpis, problems=None, workers=1, progress=False)
    assert MAX_CASES == 1000
    table = run_sweep(path, {"feed.feed_tph": [25.0, 30.0, 35.0]}, cheap_kpis, problems=None, workers=1,
                      progress=False, max_cases=3)
    assert len(table) == 3
    with pytest.raises(SceneError, match="3 cases, more than the limit of 2"):
        run_sweep(path, {"feed.feed_tph": [25.0, 30.0, 35.0]}, cheap_kpis, problems=None, workers=1,
                  progress=False, max_cases=2)


@pytest.mark.parametrize("address", ["notanaddress", "tcp://", "http://host:8786", "host:port"])
def test_a_scheduler_that_is_not_an_address_is_refused_before_any_case(write_scene, address):
    with pytest.raises(SceneError, match="not a Dask scheduler address; expected PROTOCOL://HOST:PORT"):
        run_sweep(write_scene(), VARY, cheap_kpis, problems=None, scheduler=address, progress=False)


def test_sweep_command_exits_1_naming_the_failed_cases(write_scene, monkeypatch, capsys):
    """A sweep whose cases fail exits non-zero and says which (it exited 0 unless all failed)."""
    from scenarios.cli import commands
    from tests.scenarios.test_cli import grindtwin

    monkeypatch.setattr(commands, "sweep_case", cheap_kpis)
    from tests.scenarios.conftest import BASE_SCENE

    runnable = BASE_SCENE.replace('kind = "nmpc"', 'kind = "none"')  # the base scene's NMPC: too large to build
    assert grindtwin(["sweep", write_scene(runnable), "--vary", "feed.feed_tph=25,30,44", "--workers", "1",
                      "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "grindtwin: sweep: 1 of 3 cases failed:" in err
    assert "case 2 (feed.feed_tph=44): RuntimeError: mill overloaded at 44.0 t/h" in err


def test_sweep_command_refuses_scheduler_and_huge_sweeps_with_exit_2(write_scene, capsys):
    from tests.scenarios.test_cli import grindtwin

    path = write_scene()
    assert grindtwin(["sweep", path, "--vary", "feed.feed_tph=20:40:1", "--scheduler", "notanaddress",
                      "--quiet"]) == 2
    assert "--scheduler 'notanaddress': not a Dask scheduler address" in capsys.readouterr().err
    assert grindtwin(["sweep", path, "--vary", "feed.feed_tph=1:1000:0.5", "--vary",
                      "controller.weights.p80=1:3:1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "5,997 cases, more than the limit of 1,000" in err and "Traceback" not in err


def test_a_case_that_warns_says_so_in_its_row_and_on_screen(tmp_path, capsys):
    """The real sweep_case on the short pyrite scene at 0.70 and 0.96 of critical: the second
    case's run warns (its charge centrifuges), and the sweep keeps that warning in a ``warnings``
    column and names the case on stderr; the first case's column is empty; exit 0."""
    from tests.scenarios.test_cli import grindtwin
    from tests.scenarios.test_runner import short_pyrite_scene

    out = tmp_path / "sweep"
    assert grindtwin(["sweep", str(short_pyrite_scene(tmp_path, duration_h=0.5)), "--vary",
                      "feed.speed_frac_critical=0.7,0.96", "--workers", "1", "--quiet", "--out", str(out)]) == 0
    table = pd.read_csv(out / "sweep.csv")
    assert table["warnings"].isna().tolist() == [True, False]
    assert "0.96 of critical is beyond 0.94 where the charge centrifuges" in table["warnings"][1]
    assert "grindtwin: warning: case 1 (feed.speed_frac_critical=0.96): from 0 h" in capsys.readouterr().err


def test_a_problem_of_the_base_scene_is_named_once_and_each_cases_own_with_its_case():
    """A bad value every case inherits was listed once per case (three identical lines)."""
    raw = read_toml(MOLYCOP)
    raw["feed"]["feed_tph"] = -5.0
    cases = expand_cases(raw, {"feed.speed_frac_critical": [0.6, 0.7, 2.0]})
    with pytest.raises(SceneError) as info:
        validate_cases(cases, MOLYCOP)
    lines = str(info.value).splitlines()
    assert lines[0].endswith("2 problems")
    assert [line for line in lines if "feed.feed_tph" in line] == [
        f"  every case: {MOLYCOP}: feed.feed_tph: Input should be greater than 0 (got -5.0)"]
    assert [line for line in lines if "speed_frac_critical:" in line] == [
        f"  case 2 (feed.speed_frac_critical=2.0): {MOLYCOP}: feed.speed_frac_critical: Input should be less "
        "than 1 (got 2.0)"]


def test_a_case_a_run_would_refuse_is_refused_before_any_case_runs(write_scene):
    """A case at 0.05 of critical passed the sweep's validation and failed when its turn came (the
    run's own refusal, after the cases before it had run); now every case is checked as a run checks
    its scene before building anything."""
    from scenarios.run.sweep import validate_cases

    from tests.scenarios.conftest import BASE_SCENE

    assert 'kind = "nmpc"' in BASE_SCENE and '"holdup", "cushioning"' in BASE_SCENE
    path = write_scene(BASE_SCENE.replace('kind = "nmpc"', 'kind = "none"')  # no bounds on the speed
                       .replace('"holdup", "cushioning"', '"holdup", "speed", "cushioning"'))
    cases = expand_cases(read_toml(path), {"feed.speed_frac_critical": [0.7, 0.05]})
    with pytest.raises(SceneError, match=r"1 problem\n  case 1 \(feed.speed_frac_critical=0.05\): "
                                         r"feed.speed_frac_critical: 0.05 is at or below 0.1 of critical"):
        validate_cases(cases, path, run_problems)
    assert len(validate_cases(cases[:1], path, run_problems)) == 1


def test_a_case_the_twin_refuses_is_refused_before_any_case_runs():
    """An analyser dead time of 5 h (minutes typed as hours) passed the sweep's checks and failed when its
    case was reached, after the cases before it had run: each case's models are now built up front."""
    path = MOLYCOP.parent / "reference_transition.toml"
    cases = expand_cases(read_toml(path), {"effect_options.sensor_delay.dead_time_h": [0.05, 5.0]})
    with pytest.raises(SceneError, match=r"1 problem\n  case 1 \(effect_options.sensor_delay.dead_time_h=5.0\): .*"
                                         r"the twin refused the scene: The 'dead_time_h' option of effect "
                                         r"'sensor_delay' must be at most 10 of the mill's nominal residence times"):
        validate_cases(cases, path, run_problems)


def test_a_key_inside_another_varied_key_is_refused(write_scene):
    """--vary feed.schedule[0].at_h=0.1,0.6 with --vary feed.schedule[0]={...at_h = 0.3...}: both cases ran
    at 0.3 (the table set last) and were labelled 0.1 and 0.6, exit 0."""
    base = read_toml(write_scene())
    table = dict(base["feed"]["schedule"][0])
    with pytest.raises(SceneError, match=r"sweep: feed.schedule\[0\].at_h lies inside feed.schedule\[0\], which is "
                                         r"varied too"):
        expand_cases(base, {"feed.schedule[0].at_h": [0.1, 0.6], "feed.schedule[0]": [table]})
    assert len(expand_cases(base, {"feed.schedule[0].at_h": [0.1, 0.6], "feed.feed_tph": [25.0]})) == 2


def test_the_sweep_files_tell_the_cases_apart():
    """feed.blend and feed.schedule[0].blend both showed as 'blend=' in sweep.png's legend; cases of 0.05 h
    and 0.03 h samples split the workbook's traces at 0.15 h into two rows (3 x 0.05 = 0.15000000000000002)."""
    from scenarios.output.plots import case_labels
    from scenarios.output.workbook import trace_table

    table = pd.DataFrame({"case": [0], "feed.blend": ["B"], "feed.schedule[0].blend": ["D"], "scene.seed": [3]})
    table.attrs["varied"] = ["feed.blend", "feed.schedule[0].blend", "scene.seed"]
    assert case_labels(table) == ["0: feed.blend=B, feed.schedule[0].blend=D, seed=3"]
    traces = pd.DataFrame({"case": [0, 0, 1, 1], "time_h": [0.0, 5 * 0.03, 0.0, 3 * 0.05],
                           "p80_um": [1.0, 2.0, 3.0, 4.0]})
    assert 5 * 0.03 != 3 * 0.05  # the test can fail
    wide = trace_table(traces)
    assert list(wide.index) == [0.0, 0.15] and wide.notna().all().all()


def test_a_sweep_that_varies_the_target_draws_no_single_target(monkeypatch, tmp_path):
    """sweep.png drew the base scene's 210 um as 'target' over cases that held 195 and 225 um."""
    import scenarios.output as output
    from scenarios.cli.commands import _write_sweep

    drawn = {}
    monkeypatch.setattr(output, "write_sweep_plot", lambda table, traces, folder, target: drawn.setdefault("t", target))
    scene = Path(__file__).resolve().parents[2] / "scenarios" / "reference_transition.toml"
    for varied, want in ((["controller.target_p80_um"], None), (["feed.feed_tph"], 210.0)):
        drawn.clear()
        table = pd.DataFrame({"case": [0, 1], varied[0]: [195.0, 225.0]})
        table.attrs.update(varied=varied, scene_table=read_toml(scene))
        _write_sweep(tmp_path, table, None, scene, xlsx=False)
        assert drawn["t"] == want


def test_an_option_of_the_controllers_model_varied_where_no_case_runs_the_nmpc_is_refused():
    """The reference scene's analyser dead time is the NMPC model's (its [plant] lists effects without
    sensor_delay): varied over open and PI loops, every pair of rows was the same run, labelled 0.05 and 0.15."""
    scene = read_toml(Path(__file__).resolve().parents[2] / "scenarios" / "reference_transition.toml")
    vary = {"effect_options.sensor_delay.dead_time_h": [0.05, 0.15]}
    with pytest.raises(SceneError, match=r"effect_options.sensor_delay.dead_time_h: options of an effect only the "
                                         r"controller's model has .* no case runs the NMPC"):
        expand_cases(scene, vary | {"controller.kind": ["none", "pi"]})
    assert len(expand_cases(scene, vary | {"controller.kind": ["pi", "nmpc"]})) == 4  # the NMPC reads it


def test_a_cases_blend_is_written_as_json():
    """sweep.csv, sweep.parquet and the workbook wrote a varied blend as Python's text ({'B': 0.8, 'D': 0.2}),
    which neither JSON nor TOML reads back."""
    import json

    from scenarios.output.workbook import tables_as_json

    table = pd.DataFrame({"case": [0, 1], "feed.blend": [{"B": 0.8, "D": 0.2}, {"B": 1.0}], "p80_um": [1.0, 2.0]})
    flat = tables_as_json(table)
    assert [json.loads(v) for v in flat["feed.blend"]] == list(table["feed.blend"])
    assert flat["p80_um"].tolist() == [1.0, 2.0] and table["feed.blend"][0] == {"B": 0.8, "D": 0.2}  # a copy


@pytest.mark.parametrize("edited", [False, True])
def test_a_sweep_describes_the_scene_its_cases_were_made_from_not_the_file_read_again(
        write_scene, monkeypatch, tmp_path, edited):
    """The sweep read its scene file again once every case had run: a file edited meanwhile drew its new target
    (250 um) beside cases scored against 210 um and was the workbook's scene; a file refused as written (an open
    loop giving the feed bounds its PI case reads) exited 2 after every case had run, and nothing was written."""
    import scenarios.output as output
    from scenarios.cli import commands
    from tests.scenarios.conftest import BASE_SCENE
    from tests.scenarios.test_cli import grindtwin

    # its bounds are read by the PI case only (which starts at the 14.5 t/h that holds 210 um)
    scene = write_scene(BASE_SCENE.replace('kind = "nmpc"', 'kind = "none"').replace("feed_tph_min = 20.0",
                                                                                    "feed_tph_min = 10.0"))

    def run_case(case):
        if edited:  # the user edits the file while the sweep runs
            scene.write_text(BASE_SCENE.replace("target_p80_um = 210.0", "target_p80_um = 250.0"))
        return cheap_kpis(case)

    drawn = {}
    monkeypatch.setattr(commands, "sweep_case", run_case)
    monkeypatch.setattr(output, "write_sweep_plot", lambda table, traces, folder, target: drawn.setdefault("t", target))
    out = tmp_path / "sweep"
    assert grindtwin(["sweep", scene, "--vary", "controller.kind=none,pi", "--workers", "1", "--quiet",
                      "--out", out, "--xlsx"]) == 0
    assert drawn["t"] == 210.0
    rows = pd.read_excel(out / "sweep.xlsx", sheet_name="scene").set_index("key")["value"]
    assert (rows["controller.kind"], rows["controller.target_p80_um"]) == ("none", 210)


def warned_kpis(scene):
    """cheap_kpis with the sweep's text column of warnings (None: none), as the CLI's sweep_case returns it."""
    return cheap_kpis(scene) | {"warnings": None}


def test_a_case_without_error_or_warnings_has_empty_text_cells_not_nan(write_scene, monkeypatch, tmp_path):
    """sweep.csv wrote a case's empty ``error`` (and ``warnings``) as the text NaN, an undefined number, and
    sweep.xlsx its warnings as #N/A; a missing text is now an empty cell in both, read back as no text by pandas
    and by the csv module, while an undefined number (the failed case's KPIs) stays NaN / #N/A."""
    import csv

    import openpyxl

    from scenarios.cli import commands
    from tests.scenarios.conftest import BASE_SCENE
    from tests.scenarios.test_cli import grindtwin

    monkeypatch.setattr(commands, "sweep_case", warned_kpis)
    runnable = BASE_SCENE.replace('kind = "nmpc"', 'kind = "none"')
    out = tmp_path / "sweep"
    assert grindtwin(["sweep", write_scene(runnable), "--vary", "feed.feed_tph=25,44", "--workers", "1",
                      "--out", out, "--xlsx", "--quiet"]) == 1  # case 1 fails
    failed = "RuntimeError: mill overloaded at 44.0 t/h"
    with open(out / "sweep.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [r["error"] for r in rows] == ["", failed] and [r["warnings"] for r in rows] == ["", ""]
    assert rows[1]["p80_um"] == "NaN"  # an undefined number is still NaN
    table = pd.read_csv(out / "sweep.csv")
    assert table["error"].isna().tolist() == [True, False] and table["error"][1] == failed
    assert table["warnings"].isna().all() and table["p80_um"].isna().tolist() == [False, True]
    sheet = openpyxl.load_workbook(out / "sweep.xlsx")["cases"]
    header = [c.value for c in sheet[1]]
    cells = [dict(zip(header, row)) for row in sheet.iter_rows(min_row=2, values_only=True)]
    assert [c["error"] for c in cells] == [None, failed] and [c["warnings"] for c in cells] == [None, None]
    assert "#N/A" in cells[1].values()  # the failed case's KPIs
