"""What a user opens after ``grindtwin run SCENE --out DIR``, checked from the outside: every KPI of
summary.json recomputed with numpy from the written time series by the definitions of
:mod:`scenarios.run.kpis`, the columns' units by their cross-relations (power / feed = specific
energy, cyclone water and solids), the stream and size files against the time series, and the
workbook and report against summary.json."""

from __future__ import annotations

import html
import json
import math
import re
from pathlib import Path

import numpy as np
import openpyxl
import pandas as pd
import pytest

from scenarios.output.labels import kpi_text
from scenarios.output.report import write_report
from tests.scenarios.test_cli import grindtwin
from tests.scenarios.test_outputs import CYCLONE_SCENE
from tests.scenarios.test_runner import _controlled, short_pyrite_scene

#: Relative agreement of a KPI recomputed here with summary.json's (round-off of the sums only).
RTOL = 1e-12
#: Density of water [t/m3], to put the cyclone's water flows [m3/h] beside its solids [t/h].
WATER_T_PER_M3 = 1.0
REPLAY_SCENE = Path(__file__).resolve().parents[2] / "scenarios" / "replay_day.toml"


def _run(tmp: Path, scene: Path, *extra) -> Path:
    """``grindtwin run SCENE --out DIR --csv --xlsx`` and ``grindtwin report DIR``, as a user runs them."""
    out = tmp / "out"
    assert grindtwin(["run", scene, "--out", out, "--csv", "--xlsx", "--quiet", *extra]) == 0
    write_report(out)
    return out


@pytest.fixture(scope="module")
def open_dir(tmp_path_factory):
    """The shortened pyrite surge (0.5 h, two blend steps), open loop, target 250 um."""
    tmp = tmp_path_factory.mktemp("open")
    return _run(tmp, short_pyrite_scene(tmp, 0.5))


@pytest.fixture(scope="module")
def pi_dir(tmp_path_factory):
    """The same under the PI baseline: the feed rate moves every sample."""
    tmp = tmp_path_factory.mktemp("pi")
    return _run(tmp, _controlled(short_pyrite_scene(tmp, 0.5), "pi"))


@pytest.fixture(scope="module")
def cyclone_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cyclone")
    scene = tmp / "cyclone.toml"
    scene.write_text(CYCLONE_SCENE)
    return _run(tmp, scene, "--no-plots")


def _read(run: Path):
    summary = json.loads((run / "summary.json").read_text())
    return summary, pd.read_csv(run / "timeseries.csv")


def _trapezoid(t, y) -> float:
    y = np.asarray(y, float)
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def recomputed_kpis(summary: dict, ts: pd.DataFrame) -> dict:
    """summary.json's KPIs from the written time series, by their definitions (scenarios.run.kpis):
    integrals of outputs trapezoidal, the fed tonnage the plant's tally, shares over the samples."""
    t = ts["time_h"].to_numpy(float)
    p80 = ts["p80_um"].to_numpy(float)
    err = np.abs(p80 - summary["target_p80_um"])
    lo, hi = summary["load_band_frac"]
    load = ts["load_frac"].to_numpy(float)
    fed = float(ts["fed_t"].iloc[-1] - ts["fed_t"].iloc[0])
    energy = _trapezoid(t, ts["power_kw"])
    holdup = ts["holdup_t"].to_numpy(float)
    balance = ts["fed_t"] - ts["produced_t"] - (holdup - holdup[0])
    k = {"p80_iae_um_h": _trapezoid(t, err), "p80_within_10um_frac": float(np.mean(err <= 10.0)),
         "specific_energy_kwh_t": energy / fed, "throughput_t": float(ts["produced_t"].iloc[-1]),
         "throughput_tph": float(ts["produced_t"].iloc[-1]) / (t[-1] - t[0]),
         "load_outside_band_frac": float(np.mean((load < lo) | (load > hi))),
         "mass_balance_error": float(np.max(np.abs(balance)) / (fed + holdup[0])),
         "start_p80_um": p80[0], "p80_final_um": p80[-1], "p80_mean_um": float(np.mean(p80)),
         "energy_kwh": energy, "fed_t": fed, "duration_h": t[-1]}
    if "solve_time_s" in ts:
        k["solve_time_median_s"] = float(np.median(ts["solve_time_s"]))
        k["solve_time_p95_s"] = float(np.percentile(ts["solve_time_s"], 95))
    return k


@pytest.mark.parametrize("which", ["open_dir", "pi_dir"])
def test_every_kpi_follows_from_the_written_time_series(which, request):
    """Each KPI of summary.json is its definition applied to timeseries.csv; the window is the
    whole run from t = 0 (the closed loop's estimator warm-up is not in it), one row per sample."""
    summary, ts = _read(request.getfixturevalue(which))
    k = summary["kpis"]
    t = ts["time_h"].to_numpy(float)
    dt = 0.5 / (len(t) - 1)
    np.testing.assert_allclose(t, np.arange(len(t)) * dt, rtol=0, atol=1e-12)  # 0 to 0.5 h, every sample
    for key, value in recomputed_kpis(summary, ts).items():
        assert k[key] == pytest.approx(value, rel=RTOL, abs=1e-15), key
    # the fed tonnage, which the KPIs take from the plant's tally, is the feed column held sample to sample
    held = float(np.sum(ts["feed_tph"].to_numpy(float)[:-1] * np.diff(t)))
    assert k["fed_t"] == pytest.approx(held, rel=1e-9)
    if summary["mode"] == "closed_loop":
        assert (k["controller_failed_steps"], k["controller_fallback_steps"]) == (
            int((~ts["success"].astype(bool)).sum()), int(ts["fallback"].notna().sum()))
    else:
        assert k["start_feed_tph"] == ts["feed_tph"].iloc[0] and k["solve_time_median_s"] is None


def test_csv_reads_back_the_parquet_time_series_exactly(open_dir):
    ts, pq = pd.read_csv(open_dir / "timeseries.csv"), pd.read_parquet(open_dir / "timeseries.parquet")
    assert list(ts.columns) == list(pq.columns)
    pd.testing.assert_frame_equal(ts, pq, check_dtype=False, rtol=0, atol=0)


def test_a_closed_loop_row_holds_the_plant_before_its_move(pi_dir):
    """A closed loop's row k holds the plant measured at t_k, under the input applied over the sample before,
    and the move the controller made at t_k (feed_tph, speed_frac_critical, held to the next row), as README
    says: row k's specific energy is its power over row k-1's feed (the first row's over the start state's)."""
    summary, ts = _read(pi_dir)
    feed_before = np.r_[summary["kpis"]["start_feed_tph"], ts["feed_tph"].to_numpy()[:-1]]
    np.testing.assert_allclose(ts["specific_energy_kwh_t"], ts["power_kw"] / feed_before, rtol=1e-12)
    # the PI moves the feed, so the row's own feed does not give it (the convention shows)
    assert not np.allclose(ts["specific_energy_kwh_t"], ts["power_kw"] / ts["feed_tph"], rtol=1e-6)


def test_column_units_hold_their_cross_relations(open_dir):
    """Open loop every column is at its sample's instant: specific energy [kWh/t] = power [kW] /
    feed [t/h] in the same row, the mill holds t (not kg), the P80s are um of a product finer than
    the feed (3200 um), the blend and load are fractions, not percentages."""
    _, ts = _read(open_dir)
    np.testing.assert_allclose(ts["specific_energy_kwh_t"], ts["power_kw"] / ts["feed_tph"], rtol=1e-12)
    blend = ts.filter(regex=r"^blend_.*_frac$")
    np.testing.assert_allclose(blend.sum(axis=1), 1.0, rtol=1e-12)
    assert ts["p80_um"].between(20.0, 3200.0).all() and ts["content_p80_um"].gt(ts["p80_um"]).all()
    assert ts["load_frac"].between(0.1, 3.0).all() and ts["holdup_t"].between(0.5, 100.0).all()
    # the rate columns are what the cumulative tonnages grow by
    t = ts["time_h"].to_numpy(float)
    produced = np.concatenate([[0.0], np.cumsum(0.5 * (ts["throughput_tph"].to_numpy()[1:]
                                                       + ts["throughput_tph"].to_numpy()[:-1]) * np.diff(t))])
    np.testing.assert_allclose(ts["produced_t"], produced, atol=1e-3 * ts["produced_t"].iloc[-1])


def test_cyclone_columns_balance_water_and_solids_in_their_units(cyclone_dir):
    """The cyclone's solids [t/h] (streams.csv) and water [m3/h] (time series) close: overflow
    solids share = product / (product + overflow water), circulating load = underflow / fresh
    feed, water bypass = underflow water / feed water; sump + mill water = overflow water."""
    _, ts = _read(cyclone_dir)
    last = ts.iloc[-1]
    st = pd.read_csv(cyclone_dir / "streams.csv", index_col=0)
    feed, under, product = (st[f"{s}_tph"].sum() for s in ("cyclone_feed", "cyclone_underflow", "product"))
    water_over = last["overflow_water_m3_h"] * WATER_T_PER_M3
    water_feed = feed * (1 / last["cyclone_feed_solids_frac"] - 1)
    water_under = water_feed - water_over
    assert last["overflow_solids_frac"] == pytest.approx(product / (product + water_over), rel=1e-9)
    assert last["underflow_solids_frac"] == pytest.approx(under / (under + water_under), rel=1e-9)
    assert last["circulating_load_frac"] == pytest.approx(under / st["fresh_feed_tph"].sum(), rel=1e-9)
    assert last["cyclone_water_bypass_frac"] == pytest.approx(water_under / water_feed, rel=1e-9)
    assert last["sump_water_m3_h"] + last["mill_water_m3_h"] == pytest.approx(last["overflow_water_m3_h"], rel=1e-9)
    assert last["throughput_tph"] == pytest.approx(product, rel=1e-12)
    assert last["discharge_tph"] == pytest.approx(feed, rel=1e-12)


def _p80_from_passing(sizes_um, passing_frac) -> float:
    """The size 80 % passes, linear in log size between sieves."""
    order = np.argsort(sizes_um)
    return float(np.exp(np.interp(0.8, passing_frac[order], np.log(sizes_um[order]))))


@pytest.mark.parametrize("which", ["open_dir", "pi_dir"])
def test_stream_and_size_files_agree_with_the_time_series(which, request):
    """streams.csv at the end carries the last row's product rate and hold-up; product_psd.csv's
    P80 at each of its times is the time series' p80_um then; summary.json's final PSD is its last row."""
    run = request.getfixturevalue(which)
    summary, ts = _read(run)
    last = ts.iloc[-1]
    st = pd.read_csv(run / "streams.csv", index_col=0)
    assert st["product_tph"].sum() == pytest.approx(last["throughput_tph"], rel=1e-12)
    assert st["mill_content_t"].sum() == pytest.approx(last["holdup_t"], rel=1e-12)
    np.testing.assert_allclose(st["product_retained_pct"].sum(), 100.0, rtol=1e-12)
    psd = pd.read_csv(run / "product_psd.csv", index_col=0)
    sizes = np.array([float(re.search(r"passing (\S+) µm", c).group(1)) for c in psd.columns])
    for time_h, row in psd.iterrows():
        k = int(np.argmin(np.abs(ts["time_h"] - time_h)))
        assert ts["time_h"].iloc[k] == pytest.approx(time_h, abs=1e-12)
        assert _p80_from_passing(sizes, row.to_numpy(float) / 100) == pytest.approx(ts["p80_um"].iloc[k], rel=1e-9)
    np.testing.assert_allclose(summary["final_psd"]["passing_frac"], psd.iloc[-1].to_numpy(float) / 100, rtol=1e-12)
    np.testing.assert_allclose(st["product_passing_pct"], psd.iloc[-1].to_numpy(float), rtol=1e-12)


@pytest.mark.parametrize("which", ["open_dir", "pi_dir"])
def test_workbook_and_report_show_summary_jsons_numbers(which, request):
    """The workbook's KPI sheet holds summary.json's values (16 digits) and the time series; the
    report shows each KPI as its label's format rounds summary.json's value, n/a where it is null."""
    run = request.getfixturevalue(which)
    summary, ts = _read(run)
    book = openpyxl.load_workbook(run / "run.xlsx", read_only=True)
    rows = {r[0]: r[2] for r in list(book["KPIs"].values)[1:]}
    assert list(rows) == list(summary["kpis"])
    for key, value in summary["kpis"].items():
        assert rows[key] is None if value is None else rows[key] == pytest.approx(value, rel=1e-15), key
    sheet = list(book["time series"].values)
    xlsx = pd.DataFrame(sheet[1:], columns=sheet[0])
    for col in ("time_h", "feed_tph", "power_kw", "p80_um", "fed_t", "produced_t", "holdup_t"):
        np.testing.assert_allclose(xlsx[col].to_numpy(float), ts[col].to_numpy(float), rtol=1e-15)
    page = (run / "report.html").read_text(encoding="utf-8")
    shown = dict(re.findall(r'<tr><td><code>(\w+)</code></td><td>.*?</td><td class="num">(.*?)</td></tr>', page))
    for key, value in summary["kpis"].items():
        text = html.unescape(shown[key])
        assert text == ('<span class="na">n/a</span>' if value is None else kpi_text(key, value)), key
        if value is not None and math.isfinite(value) and not text.endswith("%"):
            assert float(text) == pytest.approx(value, rel=5e-3), key


def test_a_replays_workbook_holds_its_run_minus_recorded_as_summary_json(tmp_path):
    """A replay's summary.json and report give the run minus the recorded inputs and P80 (means
    of the differences over the samples, recomputed here from the CSV); the workbook had no place
    for them, so the engineer who opened run.xlsx never saw how far the twin ran from the plant."""
    scene = tmp_path / "replay.toml"
    history = REPLAY_SCENE.parent / "data" / "sample_history.csv"
    scene.write_text(REPLAY_SCENE.read_text().replace('kind = "nmpc"', 'kind = "none"')
                     .replace('"data/sample_history.csv"', json.dumps(str(history))))
    out = tmp_path / "out"
    assert grindtwin(["replay", scene, "--history", history, "--duration-h", 0.6, "--out", out, "--csv", "--xlsx",
                      "--quiet", "--no-plots"]) == 0
    summary, ts = _read(out)
    diffs = summary["replay"]["run_minus_recorded"]
    for col, run in (("feed_tph", "feed_tph"), ("speed_frac_critical", "speed_frac_critical"),
                     ("p80_um", "p80_as_recorded_um")):  # the P80 as the analyser reads it, as recorded
        d = ts[run] - ts[f"recorded_{col}"]
        assert diffs[f"{col}_mean_diff"] == pytest.approx(d.mean(), rel=1e-12, abs=1e-12)
        assert diffs[f"{col}_mean_abs_diff"] == pytest.approx(d.abs().mean(), rel=1e-12, abs=1e-12)
    book = openpyxl.load_workbook(out / "run.xlsx", read_only=True)
    assert "replay" in book.sheetnames
    rows = {r[0]: r[2] for r in list(book["replay"].values)[1:]}
    assert rows == pytest.approx(diffs, rel=1e-15)
    facts = dict(list(book["summary"].values)[1:])
    assert facts["replayed history"] == summary["replay"]["history"]
