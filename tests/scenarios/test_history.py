"""Recorded histories: a messy CSV is cleaned by the documented rules or refused naming rows."""

from __future__ import annotations

import json
import subprocess
import warnings
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from scenarios.errors import SceneError
from scenarios.scene import blend_at, feed_table, read_history
from scenarios.scene.loader import load_scene, read_toml

ROOT = Path(__file__).parents[2]
DT = 1 / 60

# irregular (02:30), out of order (row 4), duplicated time (rows 3 and 5: the last is kept),
# NaN (row 6: held), a row summing to 99 (row 7: rescaled), a 1.5 min hold (within limit).
MESSY = """\
# a comment line, ignored
timestamp,quartz_wt_pct,kaolinite_wt_pct,feed_tph
2026-01-15T00:00:00,60,40,30
2026-01-15T00:01:00,60,40,30
2026-01-15T00:03:00,50,50,31
2026-01-15T00:02:30,70,30,
2026-01-15T00:03:00,40,60,32
2026-01-15T00:04:00,,55,33
2026-01-15T00:05:00,49.5,49.5,34
2026-01-15T00:06:00,50,50,35
"""


def write(tmp_path, text, name="history.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_messy_csv_is_cleaned_by_the_documented_rules(tmp_path):
    h = read_history(write(tmp_path, MESSY), DT)
    assert h.kind == "mineralogy" and h.minerals == ["quartz", "kaolinite"]
    assert list(h.frame.index) == pytest.approx([k / 60 for k in range(7)])
    # time-weighted mean over each minute of the held signal
    assert h.frame["quartz_wt_pct"].to_numpy() == pytest.approx([60, 60, 65, 40, 40, 50, 50])
    assert h.frame["feed_tph"].to_numpy() == pytest.approx([30, 30, 30, 32, 33, 34, 35])
    assert np.allclose(h.frame[["quartz_wt_pct", "kaolinite_wt_pct"]].sum(axis=1), 100)
    text = "\n".join(h.report)
    assert "out of time order (first: data row 4); sorted" in text
    assert "dropped data rows 3, keeping the last row of each time; the values of dropped data row 3 differ" in text
    same = read_history(write(tmp_path, MESSY.replace("00:03:00,50,50,31", "00:03:00,40,60,32"), "same.csv"), DT)
    dup = [r for r in same.report if "keeping the last row of each time" in r]
    assert len(dup) == 1 and "differ" not in dup[0]  # a record logged twice alike: nothing more to say
    assert "missing values held from the previous row" in text
    assert "rows rescaled so that the composition sums to 100" in text
    assert "irregular records" in text
    assert h.start == pd.Timestamp("2026-01-15T00:00:00")


def test_timestamps_across_a_daylight_saving_change_are_one_clock(tmp_path):
    """A CSV pandas wrote from a tz-aware index across 2026-03-29 (+01:00, then +02:00) was refused:
    "rows with and without a UTC offset" though every row had one. One minute apart in UTC, each."""
    text = ("timestamp,quartz_wt_pct,kaolinite_wt_pct\n2026-03-29T01:58:00+01:00,60,40\n"
            "2026-03-29T01:59:00+01:00,60,40\n2026-03-29T03:00:00+02:00,50,50\n2026-03-29T03:01:00+02:00,50,50\n")
    h = read_history(write(tmp_path, text), DT)
    assert list(h.frame.index) == pytest.approx([0, 1 / 60, 2 / 60, 3 / 60])
    assert h.frame["quartz_wt_pct"].to_list() == [60, 60, 50, 50]
    assert h.start == pd.Timestamp("2026-03-29T00:58:00+00:00")
    mixed = text.replace("2026-03-29T03:01:00+02:00", "2026-03-29T03:01:00")
    with pytest.raises(SceneError, match=r"rows with and without a UTC offset cannot be put on one clock \(first data "
                                         r"row that differs from the first: 4\)"):
        read_history(write(tmp_path, mixed), DT)


def test_parquet_reads_like_csv(tmp_path):
    csv = write(tmp_path, MESSY)
    frame = pd.read_csv(csv, comment="#")
    frame.to_parquet(tmp_path / "history.parquet")
    a, b = read_history(csv, DT), read_history(tmp_path / "history.parquet", DT)
    pd.testing.assert_frame_equal(a.frame, b.frame)
    # a frame indexed by its time column, as pandas users keep one, was refused: "needs exactly one time column"
    frame.set_index("timestamp").to_parquet(tmp_path / "indexed.parquet")
    pd.testing.assert_frame_equal(read_history(tmp_path / "indexed.parquet", DT).frame, a.frame)


@pytest.mark.parametrize("text,fragments", [
    (MESSY + "2026-01-15T00:30:00,50,50,35\n",
     ["composition: no valid value for 24 min between data rows 8 and 9", "limit 10 min: the scene's "
                                                                            "feed.history_max_gap_h"]),
    (MESSY.replace("2026-01-15T00:05:00,49.5,49.5", "2026-01-15T00:05:00,40,40"),
     ["does not sum to 100 within 2%", "data rows 7", "80"]),
    (MESSY.replace("2026-01-15T00:00:00,60,40,30", "2026-01-15T00:00:00,,40,30"),
     ["composition: missing in the first data row 1"]),
    (MESSY.replace("00:04:00,,55", "00:04:00,-5,55"), ["column quartz_wt_pct: negative values in data rows 6; "
                                                       "allowed: >= 0"]),
    (MESSY.replace("2026-01-15T00:06:00", "yesterday noon"), ["unreadable or missing time in data rows 8"]),
    (MESSY.replace("kaolinite_wt_pct", "kaolinte_wt_pct"),
     ["'kaolinte_wt_pct': unknown mineral (did you mean 'kaolinite'"]),
    (MESSY.replace("feed_tph", "feed_tp"), ["unknown column 'feed_tp' (did you mean 'feed_tph'?)"]),
    (MESSY.replace("timestamp", "time"), ["exactly one time column"]),
    (MESSY.replace("00:05:00,", "00:05:00+00:00,").replace("00:06:00,", "00:06:00+00:00,"),
     ["rows with and without a UTC offset", "first data row that differs from the first: 7"]),
], ids=["gap", "row sum", "NaN first row", "negative", "bad timestamp", "unknown mineral",
        "unknown column", "no time column", "mixed offsets"])
def test_messy_csv_beyond_the_rules_is_refused_naming_rows(tmp_path, text, fragments):
    path = write(tmp_path, text)
    with pytest.raises(SceneError) as info:
        read_history(path, DT)
    message = str(info.value)
    assert str(path) in message
    for f in fragments:
        assert f in message, message


def _day(n_rows: int = 60) -> list[str]:
    """A clean one-minute history of ``n_rows`` rows (header first)."""
    t = pd.date_range("2026-01-15T00:00", periods=n_rows, freq="1min").strftime("%Y-%m-%dT%H:%M:%S")
    return ["timestamp,quartz_wt_pct,kaolinite_wt_pct,feed_tph"] + [f"{ts},60,40,{30 + i % 3}"
                                                                     for i, ts in enumerate(t)]


def test_rows_logged_twice_at_the_end_are_named_as_duplicated_timestamps_not_as_disorder(tmp_path):
    """Two earlier rows appended again at the end were reported as dozens of rows out of order
    (every row the sort moved); they are two repeated times, the first being data row 61."""
    lines = _day()
    h = read_history(write(tmp_path, "\n".join(lines + lines[41:43]) + "\n"), DT)
    text = "\n".join(h.report)
    assert "out of time order" not in text
    assert ("2 rows repeat the time of an earlier row (duplicated timestamps; first: data row 61, timestamp "
            "2026-01-15T00:40:00 as data row 41): dropped data rows 41, 42, keeping the last row of each time") in text
    assert len(h.frame) == 60


def test_rows_out_of_time_order_are_counted_as_the_rows_misplaced(tmp_path):
    """Two late records appended at the end: 2 rows out of order (61 and 62), not every row the
    sort moves; one row typed an hour late (row 11) is that one row."""
    lines = _day()
    late = [f"2026-01-15T00:{m:02d}:30,60,40,30" for m in (40, 41)]
    text = "\n".join(read_history(write(tmp_path, "\n".join(lines + late) + "\n"), DT).report)
    assert "2 rows out of time order (first: data row 61; all: data rows 61, 62); sorted by time" in text
    assert "repeat" not in text
    typo = lines.copy()
    typo[11] = typo[11].replace("T00:10:00", "T01:10:00")
    text = "\n".join(read_history(write(tmp_path, "\n".join(typo) + "\n"), DT, max_gap_h=2.0).report)
    assert "1 row out of time order (first: data row 11); sorted by time" in text


def test_a_feed_column_of_zeros_is_refused_naming_the_file_and_column(tmp_path):
    path = write(tmp_path, GOOD_ROWS.replace(",30,", ",0,"))
    with pytest.raises(SceneError) as info:
        read_history(path, DT)
    assert f"{path}: column feed_tph: 0 t/h in all 3 data rows that give it; allowed: rates >= 0 t/h with at " \
           "least one above 0" in str(info.value)
    stopped = GOOD_ROWS.replace("0.0,60,40,30", "0.0,60,40,0")  # a mill stopped for a while is a record
    assert read_history(write(tmp_path, stopped), DT).frame["feed_tph"].iloc[0] == 0.0


def test_replay_refuses_a_feed_column_of_zeros_before_it_runs(tmp_path, capsys):
    """It ran the whole replay and failed on "Cumulative passing needs a positive total mass",
    naming neither the file nor the column."""
    from tests.scenarios.test_cli import grindtwin
    from tests.scenarios.test_runner import _history_csv, short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=0.5)
    hist = _history_csv(tmp_path)
    frame = pd.read_csv(hist)
    frame["feed_tph"] = 0.0
    frame.to_csv(hist, index=False)
    out = tmp_path / "out"
    assert grindtwin(["replay", scene, "--history", hist, "--out", out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"{hist}: column feed_tph: 0 t/h in all 31 data rows" in err
    assert "Traceback" not in err and "Cumulative passing" not in err and not out.exists()


def test_a_replay_that_starts_with_the_mill_stopped_runs(tmp_path):
    """A history whose feed starts at 0 (the mill stopped, fed later) failed at the end on
    "Cumulative passing needs a positive total mass" (the first size snapshot has no product).
    Its snapshots with no product are NaN, the later ones a distribution, and the run's product
    comes to its usual P80 once fed."""
    from scenarios.run import replay_scene
    from tests.scenarios.test_runner import _history_csv, short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=0.5)
    hist = _history_csv(tmp_path)
    frame = pd.read_csv(hist)
    frame.loc[: len(frame) // 3, "feed_tph"] = 0.0
    frame.to_csv(hist, index=False)
    res = replay_scene(scene, hist, progress=False)
    assert res.psd.iloc[0].isna().all() and res.psd.iloc[-1].notna().all()
    assert res.psd.iloc[-1].is_monotonic_decreasing and res.frame["p80_um"].iloc[-1] > 0


def test_a_stop_averages_to_an_exact_zero_feed_on_the_sample_grid(tmp_path):
    """Feed 0 for an hour of one-minute records: the sample-period means came from differences of
    running integrals, 1.4e-13 t/h at 1.45 h, and the replay's time series showed 4.5e6 kWh/t there."""
    t = np.arange(121) / 60
    stop = (np.arange(121) >= 30) & (np.arange(121) < 90)
    path = tmp_path / "stop.csv"
    pd.DataFrame({"time_h": t, "ore_B_frac": 1.0, "feed_tph": np.where(stop, 0.0, 30.0)}).to_csv(path, index=False)
    h = read_history(path, 0.05)
    feed = h.frame["feed_tph"]
    assert np.all(feed[(feed.index >= 0.5 - 1e-9) & (feed.index < 1.5 - 1e-9)] == 0.0)
    assert feed[(feed.index < 0.5 - 1e-9) | (feed.index >= 1.5 - 1e-9)].to_numpy() == pytest.approx(30.0, rel=1e-15)
    assert len(feed) == 41


def test_gap_limit_is_a_parameter(tmp_path):
    path = write(tmp_path, MESSY + "2026-01-15T00:30:00,50,50,35\n")
    h = read_history(path, DT, max_gap_h=0.5)
    assert h.frame["quartz_wt_pct"].iloc[-2] == pytest.approx(50)


def test_coarse_records_are_repeated_on_the_grid(tmp_path):
    text = "time_h,ore_B_frac,ore_D_frac\n0,1,0\n0.1,0.5,0.5\n"
    h = read_history(write(tmp_path, text), 0.025, max_gap_h=0.2)
    assert h.kind == "blend" and h.ores == ["B", "D"]
    assert h.frame["ore_D_frac"].to_numpy() == pytest.approx([0, 0, 0, 0, 0.5])


def test_ore_fraction_history_drives_blend_at(tmp_path, write_scene):
    write(tmp_path, "time_h,ore_B_frac,ore_D_frac\n" +
          "".join(f"{t / 4},{1 - t / 40},{t / 40}\n" for t in range(33)), name="day.csv")
    from tests.scenarios.conftest import BASE_SCENE
    text = BASE_SCENE.split("[[feed.schedule]]")[0].replace("blend = { B = 1.0 }",
                                                            'history = "day.csv"\n'
                                                            "history_max_gap_h = 0.25")
    text += BASE_SCENE[BASE_SCENE.index("[controller]"):]
    scene = load_scene(write_scene(text))
    assert blend_at(scene, 4.0) == pytest.approx({"B": 0.6, "D": 0.4})
    table = feed_table(scene)
    assert list(table.columns) == ["ore_B_frac", "ore_D_frac"] and len(table) == 33


def test_sample_history_is_a_synthetic_day_at_one_minute():
    path = ROOT / "scenarios" / "data" / "sample_history.csv"
    assert "SYNTHETIC" in path.read_text(encoding="utf-8").splitlines()[0]
    h = read_history(path, DT)
    assert len(h.frame) == 24 * 60 and h.kind == "mineralogy"
    assert not any("held" in line or "dropped" in line for line in h.report)


def test_sample_history_script_reproduces_the_shipped_file(tmp_path):
    out = tmp_path / "again.csv"
    subprocess.run([sys.executable, str(ROOT / "scenarios" / "data" / "make_sample_history.py"),
                    "--out", str(out)], check=True, cwd=ROOT, capture_output=True,
                   env={"PYTHONPATH": str(ROOT), "PATH": ""})
    shipped = (ROOT / "scenarios" / "data" / "sample_history.csv").read_bytes()
    assert out.read_bytes() == shipped


def test_replay_scene_feed_table_has_mineralogy_texture_and_recorded_values():
    scene = load_scene(ROOT / "scenarios" / "replay_day.toml")
    table = feed_table(scene)
    assert len(table) == 24 * 20 + 1  # the one-minute records averaged to the scene's 3-minute samples
    assert {"quartz_wt_pct", "mean_grain_um", "recorded_feed_tph", "recorded_p80_um"} <= set(table)
    with pytest.raises(SceneError, match="records mineralogy"):
        blend_at(scene, 1.0)


GOOD_ROWS = """\
time_h,quartz_wt_pct,kaolinite_wt_pct,feed_tph,speed_frac_critical
0.0,60,40,30,0.72
0.0166667,60,40,30,0.72
0.0333333,60,40,30,0.72
"""


@pytest.mark.parametrize("old,new,fragments", [
    ("0.0166667,60,40,30,0.72", "0.0166667,60,40,thirty,0.72",
     ["column feed_tph: not a number in data rows 2", "'thirty'"]),
    ("0.0333333,60,40,30,0.72", "0.0333333,inf,40,30,0.72", ["column quartz_wt_pct: infinite value in data rows 3"]),
    (",0.72\n", ",72\n", ["column speed_frac_critical: speed 72 is outside (0, 1): fraction of critical "
                          "expected, not percent (72 % is 0.72) in data rows 1, 2, 3"]),
    ("0.0,60,40,30,0.72", "0.0,60,40,30,1.2", ["speed 1.2 is outside (0, 1) in data rows 1"]),
    # rpm was named as percent ("14.5 % is 0.145")
    (",0.72\n", ",14.5\n", ["speed 14.5 is outside (0, 1): fraction of critical expected, not rpm (14.5 rpm is"]),
    # pandas read "#" as a comment anywhere: the row's cells from "#VALUE!" on were lost and held
    ("0.0166667,60,40,30,0.72", "0.0166667,#VALUE!,40,30,0.72",
     ["column quartz_wt_pct: not a number in data rows 2 (e.g. '#VALUE!')"]),
    # a historian's quality word: what stands for a missing value was not said
    ("0.0166667,60,40,30,0.72", "0.0166667,60,40,#N/A,0.72", ["column feed_tph: not a number in data rows 2",
                                                              "allowed: a number, or for a missing value (held from "
                                                              "the row before, up to the history's max gap) an empty "
                                                              "cell or one of nan, NaN, NA, N/A, n/a, null"]),
])
def test_a_bad_cell_is_refused_with_its_row_and_the_likely_mistake(tmp_path, old, new, fragments):
    text = GOOD_ROWS.replace(old, new)
    assert text != GOOD_ROWS
    with pytest.raises(SceneError) as info:
        read_history(write(tmp_path, text), DT)
    for fragment in fragments:
        assert fragment in str(info.value)


def test_a_product_p80_in_mm_or_coarser_than_the_feed_is_refused_naming_rows(tmp_path):
    """Only P80 > 0 was checked: a P80 in mm (0.265) and a recorder's fill value (9999 um) replayed
    with exit 0, the latter into a mean P80 difference of 400 um."""
    text = GOOD_ROWS.replace(",0.72\n", ",0.72,265\n").replace("speed_frac_critical\n", "speed_frac_critical,p80_um\n")
    assert read_history(write(tmp_path, text), DT, feed_p80_um=3200.0).frame["p80_um"].iloc[0] == 265.0
    mm = write(tmp_path, text.replace(",265\n", ",0.265\n"))
    with pytest.raises(SceneError, match=r"column p80_um: P80 0.265 um is below 1 um, finer than any mill's product "
                                         r"\(mm\? 0.265 mm is 265 um\) in data rows 1, 2, 3"):
        read_history(mm, DT)
    fill = write(tmp_path, text.replace("0.0166667,60,40,30,0.72,265", "0.0166667,60,40,30,0.72,9999"))
    read_history(fill, DT)  # no feed P80 known: no upper bound
    with pytest.raises(SceneError, match=r"column p80_um: P80 9999 um is not finer than the scene's feed P80 3200 um "
                                         r".* in data rows 2$"):
        read_history(fill, DT, feed_p80_um=3200.0)


def test_a_feed_in_kg_per_hour_is_refused_against_the_mills_nominal_feed(tmp_path):
    path = write(tmp_path, GOOD_ROWS.replace(",30,", ",30000,"))
    read_history(path, DT)  # no mill known: no bound
    with pytest.raises(SceneError, match=r"column feed_tph: feed 30000 t/h is more than 10 x the mill's nominal "
                                         r"30 t/h \(kg/h\? t/h expected\) in data rows 1, 2, 3"):
        read_history(path, DT, feed_nominal_tph=30.0)


def test_replay_refuses_a_history_recorded_in_percent_of_critical(tmp_path, capsys):
    """The issue's case: speed 72 in a history gave -1.2e216 kWh/t and exit 0."""
    from tests.scenarios.test_cli import grindtwin
    from tests.scenarios.test_runner import _history_csv, short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=0.5)
    hist = _history_csv(tmp_path)
    hist.write_text(hist.read_text().replace(",0.7,", ",70.0,"))
    out = tmp_path / "out"
    assert grindtwin(["replay", scene, "--history", hist, "--out", out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "speed 70 is outside (0, 1): fraction of critical expected, not percent" in err
    assert "data rows 1, 2, 3" in err and "Traceback" not in err and not out.exists()


def test_replay_refuses_a_recorded_speed_where_the_breakage_rates_vanish_before_it_runs(tmp_path, capsys):
    """Speed 0.05 in rows 10-19 (a stop) passed the history's (0, 1) check, then the run failed in
    the solver with exit 1 naming no row; now refused with the scene's own bound before any work."""
    from tests.scenarios.test_cli import grindtwin
    from tests.scenarios.test_runner import _history_csv, short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=0.5)
    hist = _history_csv(tmp_path)
    frame = pd.read_csv(hist)
    frame.loc[9:18, "speed_frac_critical"] = 0.05
    frame.to_csv(hist, index=False)
    out = tmp_path / "out"
    assert grindtwin(["replay", scene, "--history", hist, "--out", out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"feed.history {hist}: column speed_frac_critical: 0.05 (the lowest sample-period mean" in err
    assert "is at or below 0.1 of critical" in err and "a stopped mill cannot be replayed" in err
    assert "Traceback" not in err and not out.exists()
    frame.loc[9:18, "speed_frac_critical"] = 0.11  # above the bound: it replays
    frame.to_csv(hist, index=False)
    assert grindtwin(["replay", scene, "--history", hist, "--out", out, "--quiet", "--no-plots"]) == 0


def test_replay_refuses_a_batch_scene_whose_charge_a_history_cannot_change(tmp_path, capsys):
    """A batch scene replayed with a history switching ore and speed at 0.25 h ran with the scene's
    speed and its first blend throughout (the content's P80 that of a pure-B charge) while its
    time series showed the recorded blend and speed, exit 0."""
    from tests.scenarios.test_cli import grindtwin

    t = np.arange(31) / 60
    late = t >= 0.25
    hist = tmp_path / "batch_history.csv"
    pd.DataFrame({"time_h": t, "ore_B_frac": np.where(late, 0.0, 1.0), "ore_D_frac": np.where(late, 1.0, 0.0),
                  "speed_frac_critical": np.where(late, 0.8, 0.7)}).to_csv(hist, index=False)
    out = tmp_path / "out"
    assert grindtwin(["replay", ROOT / "scenarios" / "batch_50B_50D.toml", "--history", hist, "--out", out,
                      "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "feed.history: a batch scene (effects without `transport`) grinds one charge of feed.blend" in err
    assert "Traceback" not in err and not out.exists()


def test_a_recorded_mineralogy_the_ores_cannot_mix_is_a_warning():
    """The shipped day's assays are mixes of the ores A-D (NNLS residual below 1 wt%): no warning.
    Add 30 wt% of a mineral none of them holds (magnetite) from the second hour, the ores kept in
    proportion: the residual jumps and the run warns (it was a note only, under KPIs computed on
    a feed that is not the recorded one)."""
    from scenarios.run.feed import feed_schedule, fit_warnings, mineralogy_to_blend
    from scenarios.run.models import build_models, component_ores

    scene = load_scene(ROOT / "scenarios" / "replay_day.toml")
    models = build_models(scene)
    times = scene.time_grid_h()[:41]  # two hours
    feed, _ = feed_schedule(scene, models.components, times)
    assert fit_warnings(feed, models.components) == []
    history = read_history(ROOT / "scenarios" / "data" / "sample_history.csv", scene.scene.sample_period_h)
    frame = history.frame.copy()
    wt = [c for c in frame.columns if c.endswith("_wt_pct")]
    frame = frame[frame.index < 2.0]
    late = frame.index >= 1.0  # hours
    frame.loc[late, wt] *= 0.7
    frame["magnetite_wt_pct"] = np.where(late, 30.0, 0.0)
    _, resid = mineralogy_to_blend(frame[[*wt, "magnetite_wt_pct"]], component_ores(scene))
    table = pd.DataFrame({"time_h": frame.index, "history_fit_residual_wt_pct": resid})
    (warning,) = fit_warnings(table, models.components)
    assert "not a mix of the ores A, B, C, D" in warning and "from 1 h" in warning


def test_a_recorded_texture_the_ores_mix_does_not_have_is_a_warning(tmp_path):
    """A mineralogy history's texture columns (and feed.history_texture) were range-checked and then
    read by nothing: grain 20 um or 125 um replayed to the same digits, and nothing said so. The mix's
    textural index is now compared with the recorded one's: the shipped day's within 1.18x (no
    warning), a 20-um intergrown feed's 2.7x off (a warning naming the ratio)."""
    from scenarios.run.feed import TEXTURE_RATIO_WARN, feed_schedule, fit_warnings
    from scenarios.run.models import build_models
    from scenarios.scene.loader import scene_from_dict
    from twin.ore.mineralogy import Texture

    scene = load_scene(ROOT / "scenarios" / "replay_day.toml")
    models = build_models(scene)
    times = scene.time_grid_h()[:21]  # one hour
    feed, notes = feed_schedule(scene, models.components, times)
    ratio = feed["history_textural_index_ratio"].to_numpy()
    assert np.all(np.abs(np.log(ratio)) < np.log(1.2)) and fit_warnings(feed, models.components) == []
    assert any("the recorded texture enters through the ores' own" in n for n in notes)
    frame = pd.read_csv(ROOT / "scenarios" / "data" / "sample_history.csv", comment="#").iloc[:61]
    frame = frame.assign(mean_grain_um=20.0, uniformity=0.1, association_entropy=1.0)
    hist = tmp_path / "fine.csv"
    frame.to_csv(hist, index=False)
    data = scene.model_dump(exclude_none=True)
    data["feed"]["history"] = str(hist)
    data["scene"]["duration_h"] = 1.0
    fine = scene_from_dict(data, scene.source_path)
    feed2, _ = feed_schedule(fine, models.components, times)
    # the same mineralogy, so the same mix: the ratio moves by the recorded textures' indices alone
    recorded = feed_table(scene, times)
    shipped_ti = [Texture(*row).textural_index
                  for row in recorded[["mean_grain_um", "uniformity", "association_entropy"]].itertuples(index=False)]
    fine_ti = Texture(20.0, 0.1, 1.0).textural_index
    head = slice(0, 20)  # the last sample holds the cut history's last row, not the day's next minutes
    assert feed2["history_textural_index_ratio"].to_numpy()[head] == pytest.approx(
        (ratio * np.array(shipped_ti) / fine_ti)[head], rel=1e-12)
    (warning,) = fit_warnings(feed2, models.components)
    worst = feed2["history_textural_index_ratio"].min()
    assert worst < 1 / TEXTURE_RATIO_WARN
    assert f"the mix's textural index {worst:.3g}x the recorded, beyond 1.5x either way" in warning
    assert "from 0 h" in warning


def test_replay_reads_the_given_history_not_the_scenes_own(tmp_path, capsys):
    """`replay` validated the scene as written first: a scene copied away from its data/ folder was
    refused for its own feed.history ("file not found"), and a --duration-h the history cannot
    cover was blamed on scene.duration_h. The given history replaces the scene's unread, and
    --duration-h is named as such."""
    from tests.scenarios.test_cli import grindtwin

    text = (ROOT / "scenarios" / "replay_day.toml").read_text().replace('kind = "nmpc"', 'kind = "none"')
    assert 'history = "data/sample_history.csv"' in text and 'kind = "none"' in text
    scene = tmp_path / "elsewhere" / "day.toml"
    scene.parent.mkdir()
    scene.write_text(text)
    hist = tmp_path / "hour.csv"
    pd.read_csv(ROOT / "scenarios" / "data" / "sample_history.csv", comment="#").iloc[:31].to_csv(hist, index=False)
    out = tmp_path / "out"
    assert grindtwin(["replay", scene, "--history", hist, "--duration-h", "0.75", "--out", out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"duration_h (--duration-h) 0.75: the history {hist} covers 0.5 h; allowed: up to 0.55 h" in err
    assert "scene.duration_h" not in err and "sample_history.csv" not in err and not out.exists()
    assert grindtwin(["replay", scene, "--history", hist, "--duration-h", "0.07", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "(--duration-h) 0.07: must be a whole number of the scene's sample periods (0.05 h)" in err
    from scenarios import replay_scene  # the Python API: the reason was "a whole number of periods"
    with pytest.raises(SceneError, match=r"duration_h \(--duration-h\) -1: must be > 0 h"):
        replay_scene(scene, hist, progress=False, duration_h=-1.0)
    assert grindtwin(["replay", scene, "--history", hist, "--duration-h", "0.5", "--out", out, "--quiet",
                      "--no-plots"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["replay"]["history"] == str(hist.resolve())
    assert len(pd.read_parquet(out / "timeseries.parquet")) == 11  # 0.5 h of 3-minute samples, both ends
    # a Scene object whose history needed a texture takes the given history's texture columns too
    from scenarios.run import replay_scene
    from scenarios.scene.loader import scene_from_dict

    data = read_toml(scene)
    bare = tmp_path / "bare.csv"
    pd.read_csv(hist).drop(columns=["mean_grain_um", "uniformity", "association_entropy"]).to_csv(bare, index=False)
    data["feed"] |= {"history": str(bare), "history_texture": {"mean_grain_um": 125.0, "uniformity": 0.6,
                                                               "association_entropy": 0.55}}
    data["scene"]["duration_h"] = 0.5
    res = replay_scene(scene_from_dict(data, scene), hist, progress=False, duration_h=0.5)
    assert "history_textural_index_ratio" in res.frame


def test_one_minute_records_with_time_in_six_decimals_are_regular(tmp_path):
    """time_h written to 6 decimals (0.016667, 0.033333, ...) was reported as "irregular records
    (intervals 1 to 1 min)"; half a minute among them still is irregular."""
    t = np.round(np.arange(31) / 60, 6)
    path = tmp_path / "six.csv"
    pd.DataFrame({"time_h": t, "ore_B_frac": 1.0}).to_csv(path, index=False)
    assert not any("irregular" in line for line in read_history(path, DT).report)
    t[10] -= 0.5 / 60
    pd.DataFrame({"time_h": t, "ore_B_frac": 1.0}).to_csv(path, index=False)
    assert any("irregular records (intervals 0.5 to 1.5" in line for line in read_history(path, DT).report)


def test_a_shortened_replay_says_how_much_of_the_history_it_runs():
    """A 2-hour replay of the one-day history said only "1440 records resampled to 480 samples every 3 min"."""
    from scenarios.run.feed import feed_schedule
    from scenarios.run.models import component_ores

    scene = load_scene(Path(__file__).resolve().parents[2] / "scenarios" / "replay_day.toml")
    ores = component_ores(scene)
    times = np.arange(5) * scene.scene.sample_period_h
    _, notes = feed_schedule(scene, list(ores), times, ores)
    assert any(n.endswith("1440 records resampled to 480 samples every 3 min") for n in notes), notes
    assert "history sample_history.csv: the run replays its first 5 samples (0.2 of 23.9833 h)" in notes
    _, notes = feed_schedule(scene, list(ores), np.arange(480) * scene.scene.sample_period_h, ores)
    assert not any("the run replays its first" in n for n in notes)


def test_a_trailing_delimiter_and_missing_value_words_read_as_the_plain_file(tmp_path):
    """Exports that end every row with a delimiter made pandas take the time column as the index and
    blame the time; blank, NA and null cells are missing values (held), comment lines are skipped."""
    plain = read_history(write(tmp_path, GOOD_ROWS), DT).frame
    trailing = "\n".join(line + "," for line in GOOD_ROWS.splitlines()) + "\n"
    assert read_history(write(tmp_path, trailing, "t.csv"), DT).frame.equals(plain)
    words = "# exported 2026-01-15\n" + GOOD_ROWS.replace("0.0166667,60,40,30", "0.0166667,60,40,NA").replace(
        "0.0333333,60,40,30", "0.0333333,60,40,null")
    h = read_history(write(tmp_path, words, "w.csv"), DT)
    assert h.frame.equals(plain) and "2 missing values held from the previous row (max gap 10 min)" in h.changes


def test_local_timestamps_repeating_the_hour_the_clock_goes_back_are_refused(tmp_path):
    """Naive local times across the end of daylight-saving time record 02:00-02:59 twice: the first copy was
    dropped as duplicates (an hour of records), said only in summary.json's notes."""
    times = [f"2025-10-26T0{h}:{m:02d}:00" for h, m in [(1, 0), (1, 30), (2, 0), (2, 30), (2, 0), (2, 30), (3, 0)]]
    text = "timestamp,quartz_wt_pct,kaolinite_wt_pct\n" + "".join(f"{t},60,40\n" for t in times)
    with pytest.raises(SceneError, match=r"data row 5 \(2025-10-26T02:00:00\) steps back about an hour .* UTC"):
        read_history(write(tmp_path, text), 0.5, max_gap_h=1.0)
    offsets = ["+02:00"] * 4 + ["+01:00"] * 3  # the same hour with its offsets: one clock, nothing dropped
    text = "timestamp,quartz_wt_pct,kaolinite_wt_pct\n" + "".join(f"{t}{o},60,40\n" for t, o in zip(times, offsets))
    h = read_history(write(tmp_path, text, "utc.csv"), 0.5, max_gap_h=1.0)
    assert h.span_h == pytest.approx(3.0) and h.changes == []


@pytest.mark.parametrize("stamp, shown", [("15/01/2026 00:00", "'15/01/2026 00:00'"), ("1768435200", "'1768435200'")])
def test_an_unreadable_time_shows_what_was_read_and_what_is_taken(tmp_path, stamp, shown):
    text = f"timestamp,quartz_wt_pct,kaolinite_wt_pct\n{stamp},60,40\n"
    with pytest.raises(SceneError, match=f"timestamp: unreadable or missing time in data rows 1 \\(e.g. {shown}\\); "
                                         "allowed: ISO 8601"):
        read_history(write(tmp_path, text), DT)


@pytest.mark.parametrize("factor, unit", [(1 / 3.6, "kg/s"), (1 / 24, "kt/d")])
def test_a_feed_recorded_in_another_unit_is_refused_against_the_mills_nominal(tmp_path, factor, unit):
    """A feed in kg/s (8.3 for 30 t/h) ran at 20 kWh/t, exit 0, no warning: only feeds above 10x nominal
    were refused. A stop (zeros) and a start-up do not move the median of the rows above 0."""
    rows = GOOD_ROWS.replace(",30,", f",{30 * factor:.4g},")
    with pytest.raises(SceneError, match=r"column feed_tph: median .* below 30% of the mill's nominal 30 t/h \(kg/s"):
        read_history(write(tmp_path, rows), DT, feed_nominal_tph=30.0)
    stop = GOOD_ROWS.replace("0.0,60,40,30", "0.0,60,40,0").replace("0.0166667,60,40,30", "0.0166667,60,40,5")
    assert read_history(write(tmp_path, stop, "stop.csv"), DT, feed_nominal_tph=30.0).frame["feed_tph"].iloc[0] == 0


def test_a_replay_warns_of_what_reading_its_history_changed_and_records_the_plant_clock(tmp_path):
    """Rows dropped as duplicates and values held were notes inside summary.json only; the output had
    no trace of the plant's clock (time_h counts from the first record)."""
    from scenarios.run import replay_scene
    from tests.scenarios.test_runner import short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    raw = pd.read_csv(ROOT / "scenarios" / "data" / "sample_history.csv", comment="#").iloc[:20]
    raw.loc[5, "feed_tph"] = np.nan
    raw = pd.concat([raw.iloc[:8], raw.iloc[7:8], raw.iloc[8:]])  # row 8 logged twice
    hist = tmp_path / "plant.csv"
    raw.to_csv(hist, index=False)
    res = replay_scene(scene, hist, progress=False)
    warned = "\n".join(res.summary["warnings"])
    assert "history plant.csv: 1 row repeats the time of an earlier row" in warned
    assert "history plant.csv: 1 missing values held from the previous row" in warned
    assert res.summary["replay"]["history_start"] == pd.Timestamp(raw["timestamp"].iloc[0]).isoformat()


def test_a_recorded_p80_is_the_reading_shown_at_each_sample_and_inputs_the_mean_of_the_sample(tmp_path):
    """Rule 7: 20-second records on a 3-minute grid. The feed, held by the run over the sample ahead, is that
    sample's mean; the P80, an analyser's reading, is the last reading at or before the sample time (the mean of
    the sample ahead set it 80 s early: 200 + 60 t plus 1.3 um here)."""
    t = np.arange(0, 0.5 + 1e-9, 20 / 3600)
    path = tmp_path / "fine.csv"
    pd.DataFrame({"time_h": t, "ore_B_frac": 1.0, "feed_tph": 30.0 + 36.0 * t, "p80_um": 200.0 + 60.0 * t}).to_csv(
        path, index=False)
    dt = 0.05
    frame = read_history(path, dt).frame
    grid = frame.index.to_numpy()
    np.testing.assert_allclose(frame["p80_um"], 200.0 + 60.0 * grid, rtol=1e-12)
    rounded = tmp_path / "rounded.csv"  # times to 6 decimals of an hour (3.6 ms): still each sample's own reading
    pd.read_csv(path).to_csv(rounded, index=False, float_format="%.6f")
    np.testing.assert_allclose(read_history(rounded, dt).frame["p80_um"], 200.0 + 60.0 * grid, rtol=1e-6)
    inside = grid < grid[-1]  # the last sample holds the last record
    mean_ahead = 30.0 + 36.0 * (grid[inside] + (dt - 20 / 3600) / 2)  # the mean of the 9 records in [t_k, t_k + dt)
    np.testing.assert_allclose(frame["feed_tph"].to_numpy()[inside], mean_ahead, rtol=1e-12)


def _hourly_day(times, feed) -> pd.DataFrame:
    return pd.DataFrame({"timestamp": times, "ore_B_frac": 1.0, "feed_tph": feed})


def test_records_missing_are_said_as_missing_values_are(tmp_path):
    """50 minutes of rows deleted were held without a word while the same gap as blank cells was a warning."""
    t = pd.date_range("2026-01-15T00:00", periods=180, freq="min")
    keep = np.r_[0:60, 110:180]
    path = tmp_path / "gap.csv"
    _hourly_day(t[keep].strftime("%Y-%m-%dT%H:%M:%S"), 30.0).to_csv(path, index=False)
    h = read_history(path, DT, max_gap_h=1.5)
    assert any("records missing once" in c and "the longest 51 min after data row 60" in c for c in h.changes)
    outage = tmp_path / "outage.csv"  # an hour and a minute without records at 09:59 in June: no clock change
    june = pd.date_range("2026-06-15T08:00", periods=240, freq="min")
    _hourly_day(june[np.r_[0:120, 180:240]].strftime("%Y-%m-%dT%H:%M:%S"), 30.0).to_csv(outage, index=False)
    assert any("the longest 61 min" in c for c in read_history(outage, DT, max_gap_h=1.5).changes)
    whole = tmp_path / "whole.csv"
    _hourly_day(t.strftime("%Y-%m-%dT%H:%M:%S"), 30.0).to_csv(whole, index=False)
    assert not any("missing" in c for c in read_history(whole, DT).changes)


@pytest.mark.parametrize("change", ["spring", "autumn"])
def test_a_daylight_saving_change_in_local_times_is_refused_in_any_order(tmp_path, change):
    """Naive local times over the spring change skip 02:00-03:00: that hour was held as recorded, 28 t of feed
    invented in 3 h, every later record an hour late. Over the autumn change, sorted by local time (a historian's
    export), 02:00-02:59 comes twice and the first copy was dropped as duplicates (40 t of 120 lost). Both are
    refused; the same records with their UTC offsets are read, every record kept."""
    day = "2026-03-29T00:00" if change == "spring" else "2026-10-25T00:00"
    real = pd.date_range(day, periods=240, freq="min", tz="Europe/Berlin")  # 4 h as they happened
    feed = np.where(np.arange(240) < 150, 40.0, 20.0)
    local = pd.Series(real.tz_localize(None))
    order = np.argsort(local.to_numpy(), kind="stable")
    naive = tmp_path / "naive.csv"
    _hourly_day(local.dt.strftime("%Y-%m-%dT%H:%M:%S").to_numpy()[order], feed[order]).to_csv(naive, index=False)
    with pytest.raises(SceneError, match="daylight-saving time"):
        read_history(naive, DT)
    offset = tmp_path / "offset.csv"
    _hourly_day([ts.isoformat() for ts in real], feed).to_csv(offset, index=False)
    h = read_history(offset, DT)
    assert h.span_h == pytest.approx(239 / 60)
    fed = h.frame["feed_tph"].to_numpy()[:-1].sum() * DT
    assert fed == pytest.approx(feed[:-1].sum() / 60)


def test_an_export_that_repeats_an_hour_with_the_same_values_keeps_one_copy(tmp_path):
    """Two exports overlapping by an hour repeat the same records (times with their offset: no clock change):
    one copy kept, said."""
    t = pd.date_range("2026-01-15T00:00", periods=180, freq="min").strftime("%Y-%m-%dT%H:%M:%S+00:00")
    feed = 30.0 + np.arange(180) / 60
    both = pd.concat([_hourly_day(t[:120], feed[:120]), _hourly_day(t[60:], feed[60:])])
    path = tmp_path / "overlap.csv"
    both.to_csv(path, index=False)
    h = read_history(path, DT)
    assert any("60 rows repeat the time of an earlier row" in c for c in h.changes)
    np.testing.assert_allclose(h.frame["feed_tph"].to_numpy(), feed)


@pytest.mark.parametrize("sep,name", [(";", "semicolon"), ("\t", "tab")])
def test_a_history_split_by_semicolons_or_tabs_is_refused_naming_the_delimiter(tmp_path, sep, name):
    """Excel's CSV where the comma is the decimal separator (byte-order mark, ";", decimal commas, CRLF) was read as
    one column: pandas warned that data would be lost and the time column was reported missing."""
    rows = [line.split(",") for line in GOOD_ROWS.splitlines()]
    text = "\r\n".join(sep.join(cell.replace(".", ",") for cell in row) for row in rows) + "\r\n"
    path = tmp_path / "excel.csv"
    path.write_bytes(b"\xef\xbb\xbf" + text.encode())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # refused before pandas reads it
        with pytest.raises(SceneError, match=rf"the header row is {name}-separated \('time_h.*quartz_wt_pct.*"
                                             r"allowed: a comma-separated file with decimal points"):
            read_history(path, DT)


def test_a_history_with_some_texture_columns_is_refused_naming_the_missing_ones(tmp_path):
    """A history recording mean_grain_um alone needed feed.history_texture, whose constant then replaced the
    recorded column in the feed table, unsaid: the texture warning compared the ores' mix with the scene's texture,
    not with the recording."""
    from scenarios.scene.loader import scene_from_dict

    text = GOOD_ROWS.replace("speed_frac_critical\n", "speed_frac_critical,mean_grain_um\n").replace(
        ",0.72\n", ",0.72,400\n")
    path = write(tmp_path, text)
    message = (r"texture column mean_grain_um without uniformity, association_entropy; allowed: all three texture "
               r"columns, or none \(and the scene's feed.history_texture\)")
    with pytest.raises(SceneError, match=message):
        read_history(path, DT)
    data = read_toml(ROOT / "scenarios" / "replay_day.toml")
    data["scene"] |= {"duration_h": 0.05, "sample_period_h": 0.05}
    data["feed"] |= {"history": str(path), "history_texture": {"mean_grain_um": 125.0, "uniformity": 0.6,
                                                               "association_entropy": 0.55}}
    with pytest.raises(SceneError, match="feed.history: .*" + message):
        scene_from_dict(data, ROOT / "scenarios" / "replay_day.toml")


def test_an_ore_fraction_historys_recorded_texture_is_compared_with_the_ores_mix(tmp_path):
    """Texture columns beside ore fractions were read and then ignored, unsaid (a mineralogy history's are compared
    with its ores' mix since the last round): an ore-fraction history recording B's own texture gives a ratio of 1
    and no warning; one recording a 20-um intergrown feed, the same ratio as that texture's index over B's, and
    the warning."""
    from scenarios.run.feed import feed_schedule, fit_warnings
    from scenarios.scene.loader import scene_from_dict
    from twin import load_ore

    scene = load_scene(ROOT / "scenarios" / "reference_transition.toml")
    b = load_ore("B").texture
    t = np.arange(31) / 60
    feeds = {}
    for name, texture in (("own", (b.mean_grain_um, b.uniformity, b.association_entropy)), ("fine", (20.0, 0.1, 1.0))):
        hist = tmp_path / f"{name}.csv"
        pd.DataFrame({"time_h": t, **{f"ore_{o}_frac": float(o == "B") for o in ("B", "D")},
                      **dict(zip(("mean_grain_um", "uniformity", "association_entropy"), texture))}).to_csv(
            hist, index=False)
        data = scene.model_dump(exclude_none=True)
        data["feed"] = {k: v for k, v in data["feed"].items() if k not in ("schedule", "blend")} | {"history": str(hist)}
        data["scene"]["duration_h"] = 0.5
        s = scene_from_dict(data, scene.source_path)
        feeds[name] = feed_schedule(s, ["B", "D"], s.time_grid_h())
    own, notes = feeds["own"]
    assert own["history_textural_index_ratio"].to_numpy() == pytest.approx(1.0, rel=1e-12)
    assert any("the recorded texture enters through the ores' own" in n for n in notes)
    assert fit_warnings(own, ["B", "D"]) == []
    fine, _ = feeds["fine"]
    from twin.ore.mineralogy import Texture

    assert fine["history_textural_index_ratio"].to_numpy() == pytest.approx(
        b.textural_index / Texture(20.0, 0.1, 1.0).textural_index, rel=1e-12)
    (warning,) = fit_warnings(fine, ["B", "D"])
    assert "the recorded texture is not that of the mix of the ores" in warning


def test_a_history_rewritten_during_a_replay_is_warned_and_the_run_records_what_it_was_fed(tmp_path, monkeypatch):
    """summary.json named the history by its path alone, and the plant's clock at time 0 was read again after
    the run: a file rewritten meanwhile (an export of another day to the same name) gave the other day's clock to
    this run, with no warning. The run now records the SHA-256 of the bytes it was fed, its clock is theirs, and a
    file changed by the run's end is warned of."""
    import hashlib
    import os

    import scenarios.run.runner as runner
    from scenarios.run import replay_scene
    from tests.scenarios.test_runner import short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    raw = pd.read_csv(ROOT / "scenarios" / "data" / "sample_history.csv", comment="#").iloc[:20]
    hist = tmp_path / "plant.csv"
    raw.to_csv(hist, index=False)
    fed = hashlib.sha256(hist.read_bytes()).hexdigest()
    other = raw.assign(timestamp=(pd.to_datetime(raw["timestamp"]) + pd.Timedelta(days=17)).astype(str))

    def rewritten(run):
        def during(*args, **kwargs):
            other.to_csv(hist, index=False)
            os.utime(hist, (hist.stat().st_atime + 10, hist.stat().st_mtime + 10))
            return run(*args, **kwargs)
        return during

    monkeypatch.setattr(runner, "run_open_loop", rewritten(runner.run_open_loop))
    monkeypatch.setattr(runner, "run_closed", rewritten(runner.run_closed))
    res = replay_scene(scene, hist, progress=False)
    assert res.summary["replay"]["history_start"] == pd.Timestamp(raw["timestamp"].iloc[0]).isoformat()
    assert res.summary["history_file"] == {"path": str(hist.resolve()), "sha256": fed}
    (changed,) = [w for w in res.summary["warnings"] if "changed during the run" in w]
    assert str(hist) in changed and fed[:12] in changed
    assert hashlib.sha256(hist.read_bytes()).hexdigest()[:12] in changed


def test_a_runs_history_file_and_its_hash_are_shown_in_its_report_and_workbook(tmp_path):
    """The report and the workbook's summary named the replayed history by its path alone."""
    import hashlib

    from scenarios.output.report import write_report
    from scenarios.run import replay_scene
    from tests.scenarios.test_runner import short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    hist = tmp_path / "plant.csv"
    pd.read_csv(ROOT / "scenarios" / "data" / "sample_history.csv", comment="#").iloc[:20].to_csv(hist, index=False)
    out = tmp_path / "run"
    replay_scene(scene, hist, out_dir=out, progress=False, plots=False, xlsx=True)
    shown = f"{hist.resolve()} (sha256 {hashlib.sha256(hist.read_bytes()).hexdigest()[:12]})"
    assert f"<th>history file</th><td>{shown}</td>" in write_report(out).read_text(encoding="utf-8")
    book = pd.read_excel(out / "run.xlsx", sheet_name="summary")
    assert book.loc[book["item"] == "history file", "value"].tolist() == [shown]


def test_a_row_split_by_a_decimal_comma_is_refused_naming_its_line_in_the_file(tmp_path):
    """A decimal comma in one cell of a comma-separated file gives its row a cell more than the header; pandas'
    refusal named the line counted without the file's comment lines ("line 8" here, a good row), and not why."""
    text = MESSY.replace("2026-01-15T00:05:00,49.5,49.5,34", "2026-01-15T00:05:00,49,5,49.5,34")
    with pytest.raises(SceneError) as err:
        read_history(write(tmp_path, text), DT)
    said = str(err.value)
    assert "line 9 has 5 cells, the header 4 ('2026-01-15T00:05:00,49,5,49.5,34')" in said
    assert "decimal comma" in said and "decimal point (30.4)" in said


def test_a_history_rewritten_after_the_scenes_check_is_read_by_the_run_with_the_same_ranges(tmp_path, monkeypatch):
    """The scene's check reads its history against the mill's nominal feed (a feed in kg/h refused); the run read it
    again, cached by its modification time, without: a file rewritten in between (an export of the same name, here in
    kg/h) was run at 30000 t/h, with exit 0."""
    import os

    import scenarios.run.runner as runner
    from scenarios.run import replay_scene
    from tests.scenarios.test_runner import _history_csv, short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    hist = _history_csv(tmp_path)
    in_kg_h = pd.read_csv(hist).assign(feed_tph=lambda f: f["feed_tph"] * 1000)
    build = runner.build_models

    def rewritten(*args, **kwargs):  # after the check, before the run reads the file
        in_kg_h.to_csv(hist, index=False)
        os.utime(hist, (hist.stat().st_atime + 10, hist.stat().st_mtime + 10))
        return build(*args, **kwargs)

    monkeypatch.setattr(runner, "build_models", rewritten)
    with pytest.raises(SceneError, match=r"column feed_tph: feed 30000 t/h is more than 10 x the mill's nominal"):
        replay_scene(scene, hist, progress=False)


def test_the_sample_history_script_does_not_overwrite_a_file_it_did_not_write(tmp_path):
    """`make_sample_history.py --out plant.csv` replaced a plant's own history by the made-up day, exit 0; it now
    refuses any file that does not start as its output does, and rewrites its own."""
    script = [sys.executable, str(ROOT / "scenarios" / "data" / "make_sample_history.py"), "--out"]
    env = {"PYTHONPATH": str(ROOT), "PATH": ""}
    plant = tmp_path / "plant.csv"
    plant.write_text("timestamp,quartz_wt_pct\n2026-01-15T00:00:00,100\n", encoding="utf-8")
    kept = plant.read_bytes()
    done = subprocess.run([*script, str(plant)], cwd=ROOT, capture_output=True, text=True, env=env)
    assert done.returncode == 2 and f"refusing to overwrite {plant}" in done.stderr
    assert plant.read_bytes() == kept
    ours = tmp_path / "sample.csv"
    for _ in range(2):  # written, then rewritten
        subprocess.run([*script, str(ours)], check=True, cwd=ROOT, capture_output=True, env=env)
    assert ours.read_bytes() == (ROOT / "scenarios" / "data" / "sample_history.csv").read_bytes()


def test_a_replay_parses_its_history_once_with_the_checks_ranges_and_once_without(tmp_path, monkeypatch):
    """A replay read the whole file five times (the scene's check twice, the replay's span twice, the run): a
    day of one-second records took most of a short replay's time. Each read is now shared while the file stays
    as it was; a file changed between two reads is read again (its modification time or size)."""
    import scenarios.scene.history as history_module
    from scenarios.scene import read_history_once
    from tests.scenarios.test_cli import grindtwin

    reads = []
    real = history_module.read_history
    monkeypatch.setattr(history_module, "read_history", lambda *a, **k: reads.append(a[0]) or real(*a, **k))
    history_module._read_cached.cache_clear()
    scene = tmp_path / "day.toml"
    scene.write_text((ROOT / "scenarios" / "replay_day.toml").read_text().replace('kind = "nmpc"', 'kind = "none"'))
    hist = tmp_path / "hour.csv"
    pd.read_csv(ROOT / "scenarios" / "data" / "sample_history.csv", comment="#").iloc[:31].to_csv(hist, index=False)
    assert grindtwin(["replay", scene, "--history", hist, "--duration-h", "0.5", "--out", tmp_path / "out",
                      "--quiet", "--no-plots"]) == 0
    assert len(reads) == 2 and {Path(p).resolve() for p in reads} == {hist.resolve()}
    old = read_history_once(hist, 0.05).frame
    data = pd.read_csv(hist)
    data["feed_tph"] += 1.0  # a new export to the same file: read again, not the old one's
    data.to_csv(hist, index=False)
    reads.clear()
    new = read_history_once(hist, 0.05).frame
    assert len(reads) == 1 and np.allclose(new["feed_tph"], old["feed_tph"] + 1.0, rtol=0, atol=1e-12)


def test_a_feed_screen_analysis_is_recorded_by_its_hash_as_a_history_is(tmp_path, monkeypatch):
    """feed.psd_csv took no comment lines (a history does) and its bytes were not recorded: summary.json, the
    report and the workbook named the history file by its SHA-256 and the screen analysis not at all. Now it
    is read as a history is (comments, read once), recorded and shown the same way, and a file rewritten during
    the run is warned of."""
    import hashlib

    import scenarios.run.runner as runner
    from scenarios.output.report import write_report
    from scenarios.run import run_scene
    from tests.scenarios.test_runner import short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    text = scene.read_text()
    assert "\np80_um = 3200.0\n" in text
    scene.write_text(text.replace("\np80_um = 3200.0\n", '\npsd_csv = "screen.csv"\n'))
    screen = tmp_path / "screen.csv"
    screen.write_text("# feed belt screen, 2026-12-01\nsize_um,passing_pct\n500,20\n1000,45\n# re-weighed\n"
                      "2000,70\n4000,90\n6700,100\n")
    fed = hashlib.sha256(screen.read_bytes()).hexdigest()

    def rewritten(run):
        def during(*args, **kwargs):
            screen.write_text(screen.read_text().replace("500,20", "500,25"))
            return run(*args, **kwargs)
        return during

    monkeypatch.setattr(runner, "run_open_loop", rewritten(runner.run_open_loop))
    out = tmp_path / "run"
    res = run_scene(scene, out_dir=out, progress=False, plots=False, xlsx=True)
    assert res.summary["psd_file"] == {"path": str(screen.resolve()), "sha256": fed}
    (changed,) = [w for w in res.summary["warnings"] if "changed during the run" in w]
    assert "screen analysis (feed.psd_csv)" in changed and fed[:12] in changed
    shown = f"{screen.resolve()} (sha256 {fed[:12]})"
    assert f"<th>feed screen analysis file</th><td>{shown}</td>" in write_report(out).read_text(encoding="utf-8")
    book = pd.read_excel(out / "run.xlsx", sheet_name="summary")
    assert book.loc[book["item"] == "feed screen analysis file", "value"].tolist() == [shown]


def test_a_line_starting_with_an_excel_error_value_is_a_row_not_a_comment(tmp_path):
    """A record whose first cell is Excel's #N/A was read as a comment line and dropped without a word; it is a
    row, refused where a number is due, as an #N/A in any other cell is."""
    text = MESSY.replace("2026-01-15T00:05:00,", "#N/A,", 1)
    assert text != MESSY
    with pytest.raises(SceneError, match="N/A"):
        read_history(write(tmp_path, text), DT)


def _long_history(path: Path, rows: int) -> Path:
    """A synthetic history of ``rows`` records every 10 s under a comment line."""
    rng = np.random.default_rng(7)
    quartz, kaolinite = np.round(60 + rng.standard_normal(rows), 3), np.round(25 + rng.standard_normal(rows), 3)
    stamps = pd.date_range("2026-01-01", periods=rows, freq="10s").strftime("%Y-%m-%dT%H:%M:%S")
    table = pd.DataFrame({"timestamp": stamps, "quartz_wt_pct": quartz, "kaolinite_wt_pct": kaolinite,
                          "calcite_wt_pct": np.round(100 - quartz - kaolinite, 3),
                          "feed_tph": np.round(30 + rng.standard_normal(rows), 2)})
    path.write_text("# synthetic\n" + table.to_csv(index=False, lineterminator="\n"), encoding="utf-8")
    return path


def test_reading_a_long_history_takes_a_few_times_the_files_size_in_memory_not_many(tmp_path):
    """The file's bytes, its text, its lines and a text buffer alive at once, and copies of the table kept to the end,
    took many times the file's size (benchmarks/scenarios_history_memory.py): a year of 10 s records did not fit."""
    import tracemalloc

    path = _long_history(tmp_path / "long.csv", 50_000)
    read_history(path, DT)  # imports and caches first: not the read's own
    tracemalloc.start()
    try:
        history = read_history(path, DT)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert history.report[-1] == f"50000 records resampled to {len(history.frame)} samples every 1 min"
    assert peak < 5.5 * path.stat().st_size


def test_a_history_read_a_piece_at_a_time_is_read_as_one_piece(tmp_path, monkeypatch):
    """Comment lines, a byte-order mark and an Excel error value where the file is cut into pieces (after a line
    feed) are blanked, dropped and kept as when it is read whole."""
    import scenarios.scene.history as history_module

    text = MESSY.replace("2026-01-15T00:05:00", "  # a comment between rows\n2026-01-15T00:05:00")
    path = tmp_path / "history.csv"
    path.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    whole = read_history(path, DT)
    for piece in (1, 7, 40):
        monkeypatch.setattr(history_module, "CSV_PIECE_BYTES", piece)
        cut = read_history(path, DT)
        assert cut.report == whole.report and cut.sha256 == whole.sha256
        pd.testing.assert_frame_equal(cut.frame, whole.frame)
    path.write_bytes(text.replace("2026-01-15T00:06:00,50", "#N/A,50").encode("utf-8"))
    with pytest.raises(SceneError, match="unreadable or missing time in data rows 8"):
        read_history(path, DT)
