"""The runner: a scene becomes a run with KPIs in physical ranges; batch grinds; mineralogy
histories mapped to ores; replays; no half-written result presented as complete."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from twin import get_mill

from scenarios.run import replay_scene, run_scene, runner
from scenarios.run.kpis import feed_stopped
from scenarios.run.feed import mineralogy_to_blend
from scenarios.run.models import build_models
from scenarios.scene import load_scene

LIBRARY = Path(__file__).resolve().parents[2] / "scenarios"


def short_pyrite_scene(tmp_path: Path, duration_h: float = 1.0, target_p80_um: float = 250.0) -> Path:
    """The library's pyrite surge, shortened (duration d: B, pyrite-rich B from 0.3 d, B again
    from 0.6 d), on a coarser grid (13 classes, ratio 2, one mixer) so that tests run fast (the
    scene says it means the mismatch with its calibration's grid)."""
    text = (LIBRARY / "pyrite_surge.toml").read_text()
    for old, new in (("duration_h = 6.0", f"duration_h = {duration_h}"),
                     ("at_h = 2.0", f"at_h = {0.3 * duration_h:g}"),
                     ("at_h = 4.0", f"at_h = {0.6 * duration_h:g}"),
                     ('preset = "industrial"', 'preset = "industrial"\nn_mixers = 1\n'
                      'size_classes = { ratio = 2.0, count = 13 }'),
                     ('kind = "none"', f'kind = "none"\ntarget_p80_um = {target_p80_um}'),
                     ("\n[scene]", "\ncalibration_mismatch_ok = true  # the coarse test grid\n\n[scene]")):
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "short.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """One open-loop run of the short scene (1 h, target 250 um), shared by several tests."""
    return run_scene(short_pyrite_scene(tmp_path_factory.mktemp("short")), progress=False)


def test_open_loop_run_kpis_in_physical_ranges(short_run):
    res = short_run
    k = res.kpis
    fr = res.frame
    assert len(fr) == 61 and fr["time_h"].iloc[-1] == pytest.approx(1.0)
    # 30 t/h for 1 h, from steady state: about 30 t fed and produced
    assert k["fed_t"] == pytest.approx(30.0, rel=1e-9)
    assert k["throughput_t"] == pytest.approx(30.0, rel=0.02)
    assert 3.0 < k["specific_energy_kwh_t"] < 30.0
    # specific energy = energy / feed, and energy = integral of power
    assert k["specific_energy_kwh_t"] == pytest.approx(k["energy_kwh"] / k["fed_t"])
    assert k["energy_kwh"] == pytest.approx(np.trapezoid(fr["power_kw"], fr["time_h"]))
    assert k["mass_balance_error"] < 1e-6
    assert 50.0 < k["p80_final_um"] < 1000.0
    lo, hi = get_mill("industrial").stable_band  # the one-mixer test grid runs above it: the KPI says so
    assert k["load_outside_band_frac"] == pytest.approx(float(((fr["load_frac"] < lo) | (fr["load_frac"] > hi)).mean()))
    # open loop: no solver ran, solve times are NaN (not 0)
    assert math.isnan(k["solve_time_median_s"]) and math.isnan(k["solve_time_p95_s"])
    # the schedule reached the plant: the harder, denser pyrite-rich ore (0.3-0.6 h) builds up
    # in the mill at the same feed, while the power stays (it follows the clay, which is the same)
    held = fr.set_index("time_h")["holdup_t"]
    assert held.loc[0.6 - 1e-9:0.61].iloc[0] > held.iloc[0] * 1.01
    assert np.ptp(fr["power_kw"]) == pytest.approx(0.0, abs=1e-9 * fr["power_kw"].iloc[0])
    assert {"blend_B_ref_frac", "blend_B_pyrite_frac", "p80_um", "load_frac"} <= set(fr.columns)
    assert res.summary["mode"] == "open_loop" and res.summary["seed"] == 3


def test_target_kpis_follow_their_definition(short_run):
    fr = short_run.frame
    err = np.abs(fr["p80_um"] - 250.0)
    assert short_run.kpis["p80_iae_um_h"] == pytest.approx(np.trapezoid(err, fr["time_h"]))
    assert short_run.kpis["p80_within_10um_frac"] == pytest.approx(float(np.mean(err <= 10)))
    assert short_run.kpis["p80_iae_um_h"] > 0


def test_no_target_means_no_p80_kpis(short_run):
    from scenarios.run import compute_kpis

    scene = short_run.summary  # the KPIs are a function of the frame and the scene's target
    assert scene["target_p80_um"] == 250.0
    from scenarios.scene.loader import load_scene

    bare = load_scene(LIBRARY / "pyrite_surge.toml")
    k = compute_kpis(bare, short_run.frame)
    assert math.isnan(k["p80_iae_um_h"]) and math.isnan(k["p80_within_10um_frac"])


def test_batch_grind_refines_the_charge():
    res = run_scene(LIBRARY / "batch_50B_50D.toml", progress=False)
    k = res.kpis
    assert res.summary["mode"] == "batch"
    assert k["throughput_t"] == pytest.approx(0.012)
    assert "p80_um" not in res.frame  # a batch mill has no product: its P80 is the content's
    p80 = res.frame["content_p80_um"].to_numpy()
    assert p80[0] > 2000 and p80[-1] < 0.3 * p80[0]
    assert np.all(np.diff(p80) <= 1e-6)  # a batch grind only gets finer
    assert 1.0 < k["specific_energy_kwh_t"] < 100.0
    assert k["mass_balance_error"] < 1e-9
    assert math.isnan(k["load_outside_band_frac"])
    # size distributions over time: passing at any size grows
    psd = res.psd.to_numpy()
    assert psd.shape[0] >= 2 and np.all(np.diff(psd, axis=0) >= -1e-9)
    final = res.summary["final_psd"]
    assert final["what"] == "mill content" and final["time_h"] == pytest.approx(0.5)
    assert final["passing_frac"] == pytest.approx(list(psd[-1]))


def test_mineralogy_rows_are_mapped_to_the_ores_by_nnls():
    from twin.ore.ores import reference_ores

    ores = {n: reference_ores()[n] for n in ("B", "D")}
    minerals = sorted(set(ores["B"].wt_pct) | set(ores["D"].wt_pct))
    mix = {m: 0.6 * ores["B"].wt_pct.get(m, 0) + 0.4 * ores["D"].wt_pct.get(m, 0) for m in minerals}
    rows = pd.DataFrame([{f"{m}_wt_pct": v for m, v in mix.items()},
                         {f"{m}_wt_pct": ores["D"].wt_pct.get(m, 0) for m in minerals}])
    fr, resid = mineralogy_to_blend(rows, ores)
    assert fr[0] == pytest.approx([0.6, 0.4], abs=1e-6)
    assert fr[1] == pytest.approx([0.0, 1.0], abs=1e-6)
    assert resid == pytest.approx([0, 0], abs=1e-6)
    # a mineralogy that is no mix of B and D: fractions still a blend, residual reported
    odd = pd.DataFrame([{"quartz_wt_pct": 100.0}])
    fr, resid = mineralogy_to_blend(odd, ores)
    assert fr.sum() == pytest.approx(1.0) and np.all(fr >= 0) and resid[0] > 10


def _history_csv(tmp_path: Path) -> Path:
    t = pd.date_range("2026-01-15T00:00", periods=31, freq="1min")
    feed = np.where(np.arange(31) < 15, 30.0, 33.0)
    df = pd.DataFrame({"timestamp": t.strftime("%Y-%m-%dT%H:%M:%S"), "ore_B_ref_frac": 1.0,
                       "ore_B_pyrite_frac": 0.0, "feed_tph": feed, "speed_frac_critical": 0.70,
                       "p80_um": 260.0})
    path = tmp_path / "hist.csv"
    df.to_csv(path, index=False)
    return path


def test_run_says_it_does_not_drive_a_historys_recorded_inputs(tmp_path):
    """A scene whose feed.history records feed and speed: `run` uses the scene's own inputs, as
    documented, but said nothing; now a note points at `replay`, which drives them."""
    from scenarios.scene.loader import load_scene, scene_from_dict

    scene = load_scene(short_pyrite_scene(tmp_path, duration_h=0.25))
    data = scene.model_dump(exclude_none=True)
    data["feed"].pop("blend", None)
    data["feed"].pop("schedule", None)
    data["feed"]["history"] = str(_history_csv(tmp_path))
    res = run_scene(scene_from_dict(data, scene.source_path), progress=False)
    assert any("the history records feed_tph and speed_frac_critical; run uses the scene's inputs" in n
               for n in res.summary["notes"])
    assert res.frame["feed_tph"].iloc[-1] == scene.feed.feed_tph != 33.0


def test_replay_drives_the_recorded_inputs_and_compares(tmp_path):
    scene = short_pyrite_scene(tmp_path, duration_h=1.0)
    res = replay_scene(scene, _history_csv(tmp_path), progress=False)
    fr = res.frame
    assert {"recorded_feed_tph", "recorded_speed_frac_critical", "recorded_p80_um"} <= set(fr.columns)
    np.testing.assert_allclose(fr["feed_tph"], fr["recorded_feed_tph"])
    cmp = res.summary["replay"]["run_minus_recorded"]
    assert cmp["feed_tph_mean_abs_diff"] == pytest.approx(0.0)
    assert cmp["p80_um_mean_diff"] == pytest.approx(float(np.nanmean(fr["p80_as_recorded_um"] - 260.0)))
    assert res.kpis["fed_t"] == pytest.approx(0.25 * 30 + 0.25 * 33, rel=1e-6)
    # default duration: the whole history (30 min here), whatever the scene file says
    assert res.kpis["duration_h"] == pytest.approx(0.5)
    short = replay_scene(scene, _history_csv(tmp_path), progress=False, duration_h=0.25)
    assert short.kpis["fed_t"] == pytest.approx(0.25 * 30)


def test_a_replay_of_its_own_analysers_readings_differs_by_nothing(tmp_path):
    """A recorded P80 is an analyser's reading: a history of the run's own analyser readings (noise-free),
    replayed, was 5 um off on this half hour (16 um over a feed stop) because the run's P80 leaving the mill
    was set beside readings a dead time late; the comparison is now of the run's P80 as the scene's analyser
    reads it, and it is nothing."""
    scene = short_pyrite_scene(tmp_path, duration_h=1.0)
    scene.write_text(scene.read_text() + "\n[sensors]\np80_dead_time_h = 0.1\n")  # a 6-minute analyser
    first = replay_scene(scene, _history_csv(tmp_path), progress=False).frame
    reading = first["p80_as_recorded_um"].to_numpy()
    dead = load_scene(scene).sensors.p80_dead_time_h
    shown = first["time_h"].to_numpy() >= dead - 1e-9
    assert np.isnan(reading[~shown]).all() and not np.isnan(reading[shown]).any()
    # independently: the reading at t is the P80 that left the mill a dead time before (1-min analyser)
    lag = int(round(dead / scene_sample_h(scene)))
    np.testing.assert_allclose(reading[shown], first["p80_um"].to_numpy()[:len(reading) - lag], rtol=1e-12)
    hist = pd.read_csv(_history_csv(tmp_path))
    hist["p80_um"] = np.where(shown, reading, reading[shown][0])
    own = tmp_path / "own.csv"
    hist.to_csv(own, index=False)
    second = replay_scene(scene, own, progress=False)
    assert second.summary["replay"]["run_minus_recorded"]["p80_um_mean_abs_diff"] == pytest.approx(0.0, abs=1e-9)
    fr = second.frame
    assert np.mean(np.abs(fr["p80_um"] - fr["recorded_p80_um"])[shown]) > 1.0  # what was compared before


def scene_sample_h(path) -> float:
    return load_scene(path).scene.sample_period_h


def test_written_run_is_complete_and_json_has_no_nan(short_run, tmp_path):
    from scenarios.output.write import write_run

    out = tmp_path / "run"
    assert write_run(short_run, out, csv=True, plots=False) == out
    names = {p.name for p in out.iterdir()}
    assert {"timeseries.parquet", "timeseries.csv", "summary.json", "product_psd.csv"} <= names
    assert not any(n.endswith(".partial") or n == "_INCOMPLETE" for n in names)
    text = (out / "summary.json").read_text()
    summary = json.loads(text)
    assert "NaN" not in text  # strict JSON: undefined KPIs are null
    assert summary["kpis"]["solve_time_median_s"] is None
    assert summary["scene"] == "pyrite_surge" and summary["seed"] == 3
    assert "Effects:" in summary["plant_model"] and summary["versions"]["numpy"]
    assert summary["effects"] == ["breakage", "transport", "holdup", "speed", "cushioning", "rheology", "power",
                                  "classification"]
    back = pd.read_parquet(out / "timeseries.parquet")
    pd.testing.assert_frame_equal(back, short_run.frame, check_dtype=False)


@pytest.mark.parametrize("where", ["plots", "summary"])
def test_interrupted_write_leaves_no_complete_looking_output(short_run, tmp_path, monkeypatch, where):
    import scenarios.output.write as outputs

    out = tmp_path / "run"
    outputs.write_run(short_run, out, plots=False)
    before = (out / "summary.json").read_text()

    def boom(*args, **kwargs):
        raise KeyboardInterrupt  # Ctrl-C half-way through writing

    monkeypatch.setattr(outputs, "write_plots" if where == "plots" else "json_text", boom)
    with pytest.raises(KeyboardInterrupt):
        outputs.write_run(short_run, tmp_path / "fresh", plots=True)
    assert not (tmp_path / "fresh").exists() and not (tmp_path / "fresh.partial").exists()
    # an earlier complete result is untouched by an interrupted rewrite
    with pytest.raises(KeyboardInterrupt):
        outputs.write_run(short_run, out, plots=True)
    assert (out / "summary.json").read_text() == before
    assert not (tmp_path / "run.partial").exists()


def test_run_interrupted_mid_simulation_writes_nothing(tmp_path, monkeypatch):
    import scenarios.run.open_loop as open_loop

    calls = []
    real = open_loop.run_size_data

    def boom(*args, **kwargs):  # the run dies after the integration, before any output
        calls.append(1)
        raise RuntimeError("killed")

    monkeypatch.setattr(open_loop, "run_size_data", boom)
    scene = short_pyrite_scene(tmp_path, 0.25)
    with pytest.raises(RuntimeError, match="killed"):
        run_scene(scene, out_dir=tmp_path / "run", progress=False)
    assert calls and real is not boom
    assert not (tmp_path / "run").exists() and not (tmp_path / "run.partial").exists()


def _controlled(path, kind):
    nmpc = "\nhorizon_steps = 5\nmove_block = 1" if kind == "nmpc" else ""  # a PI file giving them is refused
    text = path.read_text().replace('kind = "none"', f'kind = "{kind}"{nmpc}')
    text += "\n[controller.bounds]\nfeed_tph_min = 20.0\nfeed_tph_max = 40.0\n"
    path.write_text(text)
    return path


@pytest.mark.parametrize("kind", ["pi", "nmpc"])
def test_closed_loop_through_the_real_loop(tmp_path, kind):
    """The runner wires the scene into mpc.closed_loop: the plant starts at the target, the
    loop's KPIs and solve times come back, mass is conserved."""
    path = _controlled(short_pyrite_scene(tmp_path, duration_h=0.25), kind)
    path.write_text(path.read_text().replace("move_block = 1", "move_block = 1\npreview_lead_h = 0.1"))
    res = run_scene(path, progress=False)
    k = res.kpis
    assert res.summary["mode"] == "closed_loop"
    # the preview is the NMPC's: a PI run recorded the scene's lead it never read (and plotted it)
    assert res.summary["preview_lead_h"] == (0.1 if kind == "nmpc" else None)
    assert res.frame["p80_um"].iloc[0] == pytest.approx(250.0, abs=1.0)  # started at the target
    assert 0 <= k["p80_within_10um_frac"] <= 1 and k["p80_iae_um_h"] >= 0
    if kind == "nmpc":
        assert k["solve_time_median_s"] > 0 and k["solve_time_p95_s"] >= k["solve_time_median_s"]
    # start_feed_tph is the start state's feed rate (the steady state holding the target), not
    # the first row's feed, which is the controller's move at t = 0 (the NMPC moves at once)
    from scenarios.run.closed_loop import start_feed_tph
    from scenarios.run.feed import component_blend, feed_schedule
    from scenarios.run.models import build_models, component_ores
    from scenarios.scene import load_scene
    scene = load_scene(path)
    models = build_models(scene)
    feed, _ = feed_schedule(scene, models.components, scene.time_grid_h(), component_ores(scene))
    feed0 = start_feed_tph(scene, models, component_blend(feed, models.components)[0])
    assert k["start_feed_tph"] == pytest.approx(feed0, rel=1e-9)
    if kind == "nmpc":
        assert res.frame["feed_tph"].iloc[0] != pytest.approx(feed0, rel=1e-4)  # the test can fail
    assert {"feed_tph", "speed_frac_critical", "solve_time_s"} <= set(res.frame.columns)
    assert k["mass_balance_error"] < 1e-6  # the plant's fed and produced mass close with its hold-up


def test_nmpc_settings_from_the_scene():
    from scenarios.run.closed_loop import nmpc_settings
    from scenarios.scene import load_scene

    s = nmpc_settings(load_scene(LIBRARY / "reference_transition.toml"))
    assert (s.target_p80_um, s.horizon_steps, s.move_block, s.rk4_substeps) == (210.0, 10, 1, 3)
    assert s.dt_h == pytest.approx(0.05) and s.weight_energy == 0.01
    assert (s.feed_tph_min, s.feed_tph_max, s.speed_rate_max_per_h) == (20.0, 45.0, 0.10)
    assert tuple(s.load_band_frac) == (0.8, 1.2) and s.power_max_kw == math.inf and s.preview


def test_mineralogy_history_without_ores_runs_on_the_reference_types(tmp_path):
    """replay_day's form: mineral wt% and texture per minute, no [ores]: the components are the
    reference types A-D and each minute is their NNLS mix (here exactly B, then 60 % B / 40 % D)."""
    from twin.ore.ores import reference_ores

    ref = reference_ores()
    minerals = sorted(set(ref["B"].wt_pct) | set(ref["D"].wt_pct))
    rows = []
    for i in range(16):
        w = 0.0 if i < 8 else 0.4
        row = {"time_h": i / 60}
        row |= {f"{m}_wt_pct": (1 - w) * ref["B"].wt_pct.get(m, 0) + w * ref["D"].wt_pct.get(m, 0)
                for m in minerals}
        row |= {"mean_grain_um": 125.0, "uniformity": 0.6, "association_entropy": 0.55}
        rows.append(row)
    pd.DataFrame(rows).to_csv(tmp_path / "mineralogy.csv", index=False)
    scene = tmp_path / "min.toml"
    scene.write_text("""effects = ["breakage", "transport", "holdup", "power"]
calibration_mismatch_ok = true
[scene]
name = "mineralogy_replay"
duration_h = 0.25
sample_period_h = 0.016666666666666666
[mill]
preset = "industrial"
n_mixers = 1
size_classes = { ratio = 2.0, count = 13 }
[feed]
history = "mineralogy.csv"
feed_tph = 30.0
speed_frac_critical = 0.70
""")
    res = run_scene(scene, progress=False)
    fr = res.frame
    assert res.summary["components"] == ["A", "B", "C", "D"]
    blends = fr[[f"blend_{c}_frac" for c in "ABCD"]].to_numpy()
    np.testing.assert_allclose(blends[0], [0, 1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(blends[-1], [0, 0.6, 0, 0.4], atol=1e-6)
    assert fr["history_fit_residual_wt_pct"].max() < 1e-6
    assert any("NNLS" in n for n in res.summary["notes"])
    assert res.kpis["mass_balance_error"] < 1e-6


def test_a_different_plant_is_built_and_simulated(tmp_path):
    path = short_pyrite_scene(tmp_path, duration_h=0.25)
    text = path.read_text().replace("size_classes = { ratio = 2.0, count = 13 }", "")  # read by nothing open loop
    path.write_text(text + "\n[plant]\nmodel = \"twin\"\nsize_classes = { ratio = 2.0, count = 11 }\n")
    res = run_scene(path, progress=False)
    assert res.summary["plant_model"] is not None and "11 size classes" in res.summary["plant_model"]
    assert res.summary["controller_model"] is None  # open loop: the scene's own model is not run
    assert res.psd.shape[1] == 11  # the plant's grid is what ran
    assert any("plant is a separate twin" in n for n in res.summary["notes"])


def test_analyser_trace_delays_samples_holds_and_adds_seeded_noise():
    import types

    from scenarios.run.open_loop import analyser_trace

    t = np.arange(13) / 12  # 5-min grid over 1 h
    p80 = 200 + 60 * t  # a ramp
    quiet = types.SimpleNamespace(p80_noise_um=0.0, p80_dead_time_h=0.25, p80_sample_period_h=0.25)
    y = analyser_trace(t, p80, quiet, seed=1)
    assert np.all(np.isnan(y[:3]))  # nothing reported before the first sample's dead time has passed
    np.testing.assert_allclose(y[3:6], 200.0)  # sample at 0.25 h sees t = 0
    np.testing.assert_allclose(y[6:9], 215.0)  # sample at 0.5 h sees t = 0.25 h, held
    noisy = types.SimpleNamespace(p80_noise_um=3.0, p80_dead_time_h=0.25, p80_sample_period_h=0.25)
    a, b = analyser_trace(t, p80, noisy, seed=7), analyser_trace(t, p80, noisy, seed=7)
    np.testing.assert_array_equal(a, b)  # reproducible from the seed
    assert not np.allclose(a, analyser_trace(t, p80, noisy, seed=8))
    assert np.all(a[3:6] == a[3]) and 0 < np.nanstd(a - y) < 10  # held between samples, noise ~ 3 um


def test_open_loop_frame_has_the_analyser(short_run):
    fr = short_run.frame
    assert "p80_analyser_um" in fr  # the short scene has no [sensors]: a perfect analyser
    np.testing.assert_allclose(fr["p80_analyser_um"], fr["p80_um"])


def test_reference_scene_builds_a_coarse_controller_model_and_a_full_plant():
    from scenarios.scene.loader import load_scene
    from scenarios.run import build_models

    models = build_models(load_scene(LIBRARY / "reference_transition.toml"))
    control, plant = models.control.model, models.plant.model
    assert control.shape == (2, 3, 7) and plant.shape == (2, 3, 25)
    assert "sensor_delay" in control.effect_names and "sensor_delay" not in plant.effect_names
    assert control.parameters["analyser_dead_time_h"][0] == 0.1


def test_an_unstable_rk4_substep_count_is_refused_with_the_needed_one():
    from scenarios.errors import SceneError
    from scenarios.scene.loader import load_scene

    scene = load_scene(LIBRARY / "reference_transition.toml")
    scene.scene.duration_h = 0.2
    scene.scene.sample_period_h = 0.1  # the controller model needs 2 RK4 steps at 0.05 h at its start, 4 at 0.1 h
    scene.controller.rk4_substeps = 2
    with pytest.raises(SceneError, match=r"controller.rk4_substeps = 2 is unstable.*at least 4 steps.*"
                                         r"fastest rate, [0-9.]+ /h, is in the mill's masses"):
        run_scene(scene, progress=False)


@pytest.mark.parametrize(("dead_time_h", "what"), [(1e-3, r"at least \d+ steps"), (1e-7, "No stable RK4 sub-step")])
def test_a_refused_rk4_count_names_the_fastest_state_an_analyser_lag(dead_time_h, what):
    """A short analyser dead time, not the mill, sets the step count: the refusal says so (its
    fastest mode's largest participation is in the lag chain). At 1e-7 h the run failed before
    (exit 1) on the controller model's steady state, blaming a low feed."""
    from scenarios.errors import SceneError
    from scenarios.scene.loader import read_toml, scene_from_dict

    data = read_toml(LIBRARY / "reference_transition.toml")
    data["effect_options"]["sensor_delay"]["dead_time_h"] = dead_time_h
    scene = scene_from_dict(data, source_path=LIBRARY / "reference_transition.toml")
    lag = r".*fastest rate, [0-9.e+]+ /h, is in p80_lag_um \(effect sensor_delay\)"
    with pytest.raises(SceneError, match=what + lag):
        run_scene(scene, progress=False)


@pytest.mark.parametrize(("scene_substeps", "ekf_substeps", "not_substeps"), [(2, 3, 2), (5, 5, 3)])
def test_the_estimator_predicts_with_the_scenes_rk4_substeps_or_its_own_where_more(scene_substeps, ekf_substeps,
                                                                                   not_substeps):
    """The EKF predicts with the model the NMPC runs, over the same sample: with fewer RK4 steps
    than the count the runner checked stable (``controller.rk4_substeps``) its prediction and
    covariance grew without bound (a reverse circuit at rk4_substeps = 4 on the EKF's 3, once the
    load passed 0.88: five resets in 4 h). Its prediction (no measurement) is the RK4 map of the
    larger of the scene's count and its own default, to rounding, and not the other's."""
    from mpc import rk4_map
    from scenarios.run.closed_loop import make_estimator
    from scenarios.scene.loader import load_scene

    scene = load_scene(LIBRARY / "reference_transition.toml")
    scene.controller.rk4_substeps = scene_substeps
    tw = build_models(scene).control
    css = tw.steady(feed_tph=23.4, speed_frac_critical=0.70, blend=[1.0, 0.0])
    ekf = make_estimator(scene, tw, css, codegen="off")
    m, dt = tw.model, scene.scene.sample_period_h
    x = css.x * (1.0 + 0.3 * np.sin(np.arange(css.x.size)))  # off the steady state: the prediction moves
    u, blend, hardness = np.array([27.0, 0.73]), np.array([1.0, 0.0]), 1.0
    z, _, _ = ekf.step_function(np.r_[x, hardness], ekf.P, u, blend, np.zeros(3), np.zeros(3))
    predicted = np.asarray(z, float).ravel()[: x.size]
    own = np.asarray(rk4_map(m.f, dt, ekf_substeps)(x, u, np.r_[blend, hardness]), float).ravel()
    other = np.asarray(rk4_map(m.f, dt, not_substeps)(x, u, np.r_[blend, hardness]), float).ravel()
    np.testing.assert_allclose(predicted, own, rtol=1e-10, atol=1e-12 * np.abs(own).max())
    assert np.max(np.abs(predicted - other)) > 1e-6 * np.abs(own).max()


def reverse_reference_scene(tmp_path, rk4_substeps: int) -> Path:
    """The reference scene in a reverse closed circuit (fresh feed to the cyclone sump), 4 h, at a
    P80 target its start reaches (195 um)."""
    text = (LIBRARY / "reference_transition.toml").read_text()
    text = text.replace("[effect_options.sensor_delay]", '[effect_options.classification]\nkind = "hydrocyclone"\n'
                        'circuit = "reverse"\n\n[effect_options.sensor_delay]', 1)
    text = text.replace("duration_h = 8.0", "duration_h = 4.0", 1)
    text = text.replace("target_p80_um = 210.0", "target_p80_um = 195.0", 1)
    text = re.sub(r"(?m)^rk4_substeps = \d+", f"rk4_substeps = {rk4_substeps}", text, count=1)
    path = tmp_path / "reverse.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.slow
def test_rk4_substeps_stable_at_the_start_but_not_at_the_top_of_the_load_band_are_refused(tmp_path):
    """In a reverse circuit the mill's through-flow is the circulating load times the feed, and both
    grow along the load band: on the sized mill the controller's model needs 6 RK4 steps a sample at
    the start and 9 at the band's top (load 1.2; its fastest rate 356/h). Fewer steps, stable at the
    start, let the NMPC's prediction overflow there (steps with nan QP data, infeasible ones,
    estimator resets); the runner refuses them, naming the top of the band and the count it needs,
    and with that count the loop runs without a failed step or an estimator reset."""
    from scenarios.errors import SceneError

    with pytest.raises(SceneError, match=r"rk4_substeps = 6 is unstable .* at the top of the load band .* at "
                                         r"least 9 steps"):
        run_scene(reverse_reference_scene(tmp_path, 6), progress=False)
    k = run_scene(reverse_reference_scene(tmp_path, 9), progress=False).kpis
    assert k["controller_failed_steps"] == 0 and k["estimator_resets"] == 0


def test_a_run_whose_plant_overflows_its_mill_says_so(tmp_path, short_run):
    """A replay at 250 t/h into the 30-t/h mill: its hold-up passes what the mill holds filled to
    its shell; the run warns (summary warnings and notes, so the screen and the report) with the
    share of samples over it, counted here from the frame. The short open-loop run has no such
    warning."""
    t = pd.date_range("2026-01-15T00:00", periods=61, freq="1min")
    df = pd.DataFrame({"timestamp": t.strftime("%Y-%m-%dT%H:%M:%S"), "ore_B_ref_frac": 1.0,
                       "ore_B_pyrite_frac": 0.0, "feed_tph": np.where(np.arange(61) < 5, 30.0, 250.0),
                       "speed_frac_critical": 0.70, "p80_um": 260.0})
    hist = tmp_path / "flood.csv"
    df.to_csv(hist, index=False)
    res = replay_scene(short_pyrite_scene(tmp_path), hist, progress=False)
    plant = build_models(res.scene).plant
    held = res.frame["holdup_t"].to_numpy(float)
    # the shell's volume at the content's own density (B and its pyrite-rich variant differ): volume over the
    # nominal hold-up's is the load, so the shell holds max_holdup(rho_nom) x holdup / (load x H_nom) tonnes
    capacity = (plant.mill.max_holdup_t(plant.spec.solids_density_t_m3) * held
                / (res.frame["load_frac"].to_numpy(float) * plant.spec.holdup_nominal_t))
    over = [w for w in res.summary["warnings"] if "filled to its shell" in w]
    assert len(over) == 1 and over[0] in res.summary["notes"]
    assert f"filled to its shell ({capacity[np.argmax(held)]:.4g} t)" in over[0]
    share = float(re.search(r"on ([0-9]+)% of the samples", over[0]).group(1)) / 100
    assert share == pytest.approx(np.mean(held > capacity), abs=0.006) and share > 0
    assert not any("filled to its shell" in w for w in short_run.summary["warnings"])


def test_a_run_at_a_centrifuging_speed_says_so(tmp_path, short_run):
    """The short scene at 0.96 of critical: a warning from the first sample; none at 0.70."""
    path = short_pyrite_scene(tmp_path)
    text = path.read_text()
    assert "speed_frac_critical = 0.70" in text
    path.write_text(text.replace("speed_frac_critical = 0.70", "speed_frac_critical = 0.96"))
    res = run_scene(path, progress=False)
    spun = [w for w in res.summary["warnings"] if "centrifuges" in w]
    assert len(spun) == 1 and spun[0].startswith("from 0 h to 1 h the speed 0.96 of critical")
    assert not any("centrifuges" in w for w in short_run.summary["warnings"])


def test_a_run_whose_product_lies_in_the_grids_sink_says_so(tmp_path, short_run):
    """Five classes of ratio 2 from 6.7 mm end at 419 um: the short scene's product (P80 ~260 um)
    lies mostly below it, and its P80 is the sink's extrapolation; steady states said so, runs did
    not. The warning gives the snapshots' times and the largest share, read here from the PSD."""
    path = short_pyrite_scene(tmp_path)
    text = path.read_text()
    path.write_text(text.replace("size_classes = { ratio = 2.0, count = 13 }",
                                 "size_classes = { ratio = 2.0, count = 5 }"))
    res = run_scene(path, progress=False)
    (sunk,) = [w for w in res.summary["warnings"] if "below the finest size class (419 um)" in w]
    share = res.psd.iloc[:, -1]
    assert f"({int((share >= 0.8).sum())} of {len(share)} size snapshots)" in sunk
    assert f"{share.max():.0%} of the product" in sunk and sunk in res.summary["notes"]
    assert not any("finest size class" in w for w in short_run.summary["warnings"])


def test_a_run_whose_slurry_jams_says_when():
    """trajectory_notes: the samples whose hold-up clay passes the jamming fraction, first to
    last; none below it, without the rheology effect, or without clay crowding."""
    from types import SimpleNamespace

    from twin import trajectory_notes
    from twin.effects.rheology import jamming_clay_frac

    k = 0.9
    limit = jamming_clay_frac(k)
    frame = pd.DataFrame({"time_h": [0.0, 0.5, 1.0, 1.5, 2.0],
                          "clay_frac": [0.1, limit + 0.01, 0.2, limit + 0.05, 0.1]})
    spec = SimpleNamespace(coefficients={"clay_crowding_coeff": k}, holdup_nominal_t=1.0, feed_nominal_tph=1.0)
    (w,) = trajectory_notes(frame, spec, ("rheology",))
    assert w.startswith("from 0.5 h to 1.5 h the mill slurry holds") and f"past the {limit:.0%}" in w
    assert trajectory_notes(frame.assign(clay_frac=limit - 0.01), spec, ("rheology",)) == []
    assert trajectory_notes(frame, spec, ("breakage",)) == []
    spec.coefficients["clay_crowding_coeff"] = 0.0
    assert trajectory_notes(frame.assign(clay_frac=0.9), spec, ("rheology",)) == []  # no crowding: never jams


def test_a_batch_charge_the_mill_cannot_hold_is_refused_before_any_work(tmp_path):
    """500 kg into the laboratory mill, whose shell holds about 81 kg of this blend around its
    balls: bad input naming the key and the largest charge (the plant's own capacity), and no
    output folder; the shipped 12-kg charge runs."""
    from scenarios.errors import SceneError
    from scenarios.scene import load_scene

    text = (LIBRARY / "batch_50B_50D.toml").read_text()
    assert "batch_charge_kg = 12.0" in text
    path = tmp_path / "big.toml"
    path.write_text(text.replace("batch_charge_kg = 12.0", "batch_charge_kg = 500.0"))
    plant = build_models(load_scene(path)).plant
    capacity_kg = 1000.0 * plant.mill.max_holdup_t(plant.spec.solids_density_t_m3)
    assert 12.0 < capacity_kg < 500.0
    with pytest.raises(SceneError, match=rf"feed.batch_charge_kg: 500 kg is more than the mill holds filled to its "
                                         rf"shell .*allowed: up to {capacity_kg:.4g} kg"):
        run_scene(path, out_dir=tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()


def test_a_closed_loop_with_a_feed_inventory_closes_its_mass_balance_and_has_the_open_loops_columns(tmp_path):
    """The mass balance counted the mill's hold-up only: a PI loop's feed moves change the ore held ahead of the
    mill (feed_inventory: I = F tau), and the run reported 1.2 % unbalanced; its frame lacked feed_inventory_t and
    the slurry's and contents' columns an open loop has. The P80 stays the product's and the reading the sensor's."""
    path = _controlled(short_pyrite_scene(tmp_path, duration_h=0.5), "pi")
    text = path.read_text()
    effects = text.split("effects = [", 1)[1].split("]", 1)[0]
    path.write_text(text.replace(f"effects = [{effects}]", f"effects = [{effects}, \"feed_inventory\"]", 1)
                    + "\n[effect_options.feed_inventory]\ntime_constant_h = 0.4\n")
    res = run_scene(path, progress=False)
    f = res.frame
    mill_only = f["fed_t"] - f["produced_t"] - (f["holdup_t"] - f["holdup_t"].iloc[0])
    assert mill_only.abs().max() / (f["fed_t"].iloc[-1] + f["holdup_t"].iloc[0]) > 1e-4  # the test can fail
    assert res.kpis["mass_balance_error"] < 1e-6
    assert {"soft_frac", "clay_frac", "content_p80_um", "discharge_tph"} <= set(f.columns)
    assert f["p80_um"].iloc[0] == pytest.approx(250.0, abs=1.0)  # the product's P80 at the target's steady state


def test_a_replays_p80_comparison_leaves_out_a_feed_stops_readings(tmp_path):
    """A history whose feed stops for 10 minutes, its recorded P80 the run's own analyser readings except those
    of the stop (the analyser reads the draining charge, or nothing: 999 here): the comparison counted them
    (a mean gap of hundreds of um); they are left out as they are of the KPIs, the rest agree exactly."""
    scene = short_pyrite_scene(tmp_path, duration_h=1.0)
    hist = pd.read_csv(_history_csv(tmp_path))
    hist["feed_tph"] = np.where((np.arange(31) >= 10) & (np.arange(31) < 20), 0.0, 30.0)
    stop = tmp_path / "stop.csv"
    hist.to_csv(stop, index=False)
    first = replay_scene(scene, stop, progress=False).frame
    reading = first["p80_as_recorded_um"].to_numpy()
    stopped = runner._as_read(load_scene(scene), first, feed_stopped(load_scene(scene), first)) > 0
    assert 10 <= stopped.sum() < 20  # the stop's samples and the restart's, a dead time late
    hist["p80_um"] = np.where(stopped, 999.0, np.nan_to_num(reading, nan=reading[~np.isnan(reading)][0]))
    hist.to_csv(stop, index=False)
    cmp = replay_scene(scene, stop, progress=False).summary["replay"]["run_minus_recorded"]
    assert cmp["p80_um_mean_abs_diff"] == pytest.approx(0.0, abs=1e-9)


def test_a_batch_grind_into_the_sink_says_its_p80_is_extrapolated(tmp_path):
    """A batch grind of 2,000 h leaves most of the charge below the finest class (1.64 um): its P80 (1.5 um) was
    written without a word, as a continuous mill's in the same state is not; the run now warns, from when."""
    text = (LIBRARY / "batch_50B_50D.toml").read_text()
    text = re.sub(r"(?m)^duration_h = .*$", "duration_h = 2000.0", text)
    text = re.sub(r"(?m)^sample_period_h = .*$", "sample_period_h = 10.0", text)
    path = tmp_path / "long_batch.toml"
    path.write_text(text)
    res = run_scene(load_scene(path), progress=False)
    finest = float(res.frame["content_p80_um"].min())
    assert finest < 1.64
    (note,) = [w for w in res.summary["warnings"] if "below the finest size class" in w]
    assert "of the mill content lies below the finest size class (1.64 um)" in note and note.startswith("from ")


@pytest.mark.parametrize("charge_kg, factor, too", [(26.46, 0.541, "fine"), (0.012, 2.0, "coarse")])
def test_a_batch_charge_off_the_mills_stable_load_says_its_rates_are_the_nominal_hold_ups(tmp_path, charge_kg,
                                                                                       factor, too):
    """A batch grinds at the rates of the mill's nominal hold-up; S = S^E P / H (Herbst & Fuerstenau 1980) gives
    another charge other rates. 12 kg typed in lb (26.46) or in t (0.012) ground to the shipped charge's P80
    without a word; the run now warns with the charge's load and rate factor. The shipped 12 kg does not."""
    text = (LIBRARY / "batch_50B_50D.toml").read_text()
    path = tmp_path / "charge.toml"
    path.write_text(text.replace("batch_charge_kg = 12.0", f"batch_charge_kg = {charge_kg!r}"))
    res = run_scene(load_scene(path), progress=False)
    (note,) = [w for w in res.summary["warnings"] if "batch charge" in w]
    assert f"{charge_kg:.4g} kg" in note and "stable band 0.8-1.2" in note and f"too {too}" in note
    assert f"{factor:.3g} x them" in note
    shipped = run_scene(LIBRARY / "batch_50B_50D.toml", progress=False)
    assert not [w for w in shipped.summary["warnings"] if "batch charge" in w]


def _then(fn, after):
    """``fn``, then ``after()``: a file changed once a run's work is done, before its results are written."""
    def wrapped(*args, **kwargs):
        out = fn(*args, **kwargs)
        after()
        return out
    return wrapped


def test_a_replay_gives_the_clock_of_the_history_it_ran_not_of_the_file_after_it(tmp_path, monkeypatch):
    """The history's clock at time 0 (summary.json, the report) was read from the file once the run had ended: a
    history replaced during the replay (the next day's export to the same file) gave the new file's date."""
    hist = _history_csv(tmp_path)
    monkeypatch.setattr(runner, "_run", _then(runner._run, lambda: hist.write_text(
        hist.read_text().replace("2026-01-15T", "2026-03-02T"))))
    res = replay_scene(short_pyrite_scene(tmp_path, duration_h=0.5), hist, progress=False)
    assert "2026-03-02" in hist.read_text()  # the test can fail
    assert res.summary["replay"]["history_start"] == "2026-01-15T00:00:00"


@pytest.mark.parametrize("duration_h", [None, 0.5])
def test_a_scene_file_edited_while_a_replay_runs_does_not_lose_the_run(tmp_path, monkeypatch, duration_h):
    """A replay read its scene file again once the run had ended (for the note on its duration_h, with or without
    --duration-h): a file being edited then, not TOML for a moment, made the finished replay exit 2 with nothing
    written."""
    scene = short_pyrite_scene(tmp_path, duration_h=0.5)
    monkeypatch.setattr(runner, "_run", _then(runner._run, lambda: scene.write_text("[scene\n")))
    res = replay_scene(scene, _history_csv(tmp_path), out_dir=tmp_path / "out", progress=False, duration_h=duration_h,
                       plots=False)
    assert scene.read_text() == "[scene\n"  # the test can fail
    assert res.out_dir is not None and (tmp_path / "out" / "summary.json").is_file()


def test_a_history_replaced_while_a_replay_runs_does_not_lose_the_run(tmp_path, monkeypatch):
    """A run read its history again once the plant had run (for the warnings on what reading it changed): a
    history replaced meanwhile by a file it refuses made the finished replay exit 2 with nothing written."""
    hist = _history_csv(tmp_path)
    monkeypatch.setattr(runner, "run_open_loop", _then(runner.run_open_loop, lambda: hist.write_text(
        "timestamp,feed_tph\nnot a time,30\n")))
    res = replay_scene(short_pyrite_scene(tmp_path, duration_h=0.5), hist, out_dir=tmp_path / "out", progress=False,
                       plots=False)
    assert hist.read_text().startswith("timestamp,feed_tph\nnot")  # the test can fail
    assert (tmp_path / "out" / "summary.json").is_file() and res.kpis["fed_t"] > 0
