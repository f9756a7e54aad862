"""What a run leaves for an engineer: size-by-size stream tables that balance, size
distributions in closed loop too, labelled PSD files, the Rosin-Rammler fit, plots that mark
transitions and bands, the run and sweep workbooks read back against the run's own numbers."""

from __future__ import annotations

import math

import numpy as np
import openpyxl
import pandas as pd
import pytest

from scenarios.output import psd_table, write_run
from mpc import kpis
from scenarios.output.plots import P80_BAND_UM, _plt, mark_transitions, plot_load, plot_p80
from scenarios.run import run_scene
from scenarios.run.streams import fit_rosin_rammler
from tests.scenarios.test_cli import grindtwin
from tests.scenarios.test_runner import _controlled, short_pyrite_scene

CYCLONE_SCENE = """\
effects = ["breakage", "transport", "holdup", "power", "classification"]
calibration_mismatch_ok = true  # a small, fast circuit: the mass balances hold on any calibration
[scene]
name = "cyclone"
duration_h = 0.2
sample_period_h = 0.05
[mill]
preset = "industrial"
n_mixers = 1
size_classes = { ratio = 2.0, count = 13 }
[ores.B]
type = "B"
[feed]
blend = { B = 1.0 }
feed_tph = 25.0
speed_frac_critical = 0.70
[effect_options.classification]
kind = "hydrocyclone"
"""


@pytest.fixture(scope="module")
def cyclone_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("cyclone") / "cyclone.toml"
    path.write_text(CYCLONE_SCENE)
    return run_scene(path, progress=False)


@pytest.fixture(scope="module")
def open_run(tmp_path_factory):
    return run_scene(short_pyrite_scene(tmp_path_factory.mktemp("open"), 0.5), progress=False)


def test_hydrocyclone_streams_balance_and_partition_meets_the_bypass(cyclone_run):
    """Per class, cyclone feed = underflow + overflow (the split conserves mass); at steady
    state the product carries what the fresh feed brings; the finest classes go to the
    underflow at Plitt's water bypass R_f, the coarsest all of them."""
    t = cyclone_run.streams["end"]
    np.testing.assert_allclose(t["cyclone_feed_tph"], t["cyclone_underflow_tph"] + t["product_tph"],
                               rtol=1e-12, atol=1e-12)
    assert t["product_tph"].sum() == pytest.approx(t["fresh_feed_tph"].sum(), rel=1e-6)  # steady state
    assert t["fresh_feed_tph"].sum() == pytest.approx(25.0)
    e = t["partition_to_underflow_frac"].to_numpy()
    bypass = cyclone_run.frame["cyclone_water_bypass_frac"].iloc[-1]  # Plitt's split at the run's own flow
    assert e[-1] == pytest.approx(float(bypass), rel=1e-3)
    assert e[0] == pytest.approx(1.0, abs=1e-6) and np.all(np.diff(e) <= 1e-12)  # coarse to underflow
    assert t["product_passing_pct"].iloc[0] == pytest.approx(100.0)
    assert {"cyclone_d50c_um", "circulating_load_frac"} <= set(cyclone_run.frame.columns)


def test_closed_loop_keeps_the_plant_sizes_aligned_with_its_rows(tmp_path, capsys):
    """The PSD snapshots of a closed loop come from the plant's recorded states: their P80 is
    the frame's plant P80 at the same sample (a shifted record would miss it); its progress bar
    reaches its end (16 of 16 samples, not 15)."""
    from twin import SizeGrid, pxx_um

    res = run_scene(_controlled(short_pyrite_scene(tmp_path, duration_h=0.25), "pi"), progress=True)
    assert "16/16" in capsys.readouterr().err
    assert res.psd is not None and res.mill_psd is not None and set(res.streams) == {"start", "end"}
    grid = SizeGrid(6700.0, 2.0, 13)
    fr = res.frame.set_index("time_h")
    for time_h, row in res.psd.iterrows():
        mass = -np.diff(np.r_[row.to_numpy(float), 0.0])  # passing -> mass fraction per class
        assert pxx_um(grid, mass) == pytest.approx(fr.loc[time_h, "p80_um"], rel=1e-9)


def test_rosin_rammler_fit_recovers_its_parameters():
    x = np.geomspace(5, 5000, 20)
    p = 1 - np.exp(-(x / 180.0) ** 0.9)
    x63, n = fit_rosin_rammler(x, p)
    assert x63 == pytest.approx(180.0, rel=1e-9) and n == pytest.approx(0.9, rel=1e-9)
    x63g, ng = fit_rosin_rammler(x, np.minimum(1, (x / 900.0) ** 0.8))  # not Rosin-Rammler:
    assert abs(ng - 0.8) > 0.05  # the fit does not fake it
    assert all(math.isnan(v) for v in fit_rosin_rammler(x[:3], [0.0, 0.0, 1.0]))


def test_psd_files_say_units_and_cumulative_percent_passing(open_run, tmp_path):
    out = write_run(open_run, tmp_path / "run", plots=False)
    back = pd.read_csv(out / "product_psd.csv", index_col=0)
    assert back.index.name == "time [h]"
    assert back.columns[0] == "cumulative % passing 6700 µm"
    np.testing.assert_allclose(back.to_numpy(), 100 * open_run.psd.to_numpy(), rtol=1e-12)
    assert (out / "mill_psd.csv").is_file() and (out / "streams.csv").is_file()
    streams = pd.read_csv(out / "streams.csv", index_col=0)
    assert streams["product_passing_pct"].iloc[-1] == pytest.approx(streams["product_retained_pct"].iloc[-1])


def _labels(fig) -> list[str]:
    return [t for ax in fig.axes for t in ax.get_legend_handles_labels()[1]]


def test_time_plots_mark_transitions_and_label_their_bands(open_run):
    plt = _plt()
    summary = dict(open_run.summary, preview_lead_h=0.25, target_p80_um=250.0,
                   schedule=[{"at_h": 0.3, "kind": "ramp", "ramp_h": 0.1, "blend": {"B": 0.6, "D": 0.4}}])
    result = type(open_run)(open_run.frame, summary)
    labels = _labels(plot_p80(plt, result))
    assert "feed ramp to 60 % B / 40 % D" in labels and "seen by the preview (0.25 h ahead)" in labels
    assert "target ± 10 µm" in labels and "target 250 µm" in labels
    # the band drawn is the KPI's (the plots do not import mpc, which loads CasADi, for one number)
    assert P80_BAND_UM == kpis.P80_BAND_UM
    assert "stable band 0.8-1.2" in _labels(plot_load(plt, result))
    fig, ax = plt.subplots()
    mark_transitions(ax, dict(summary, schedule=[{"at_h": 1.0, "kind": "step", "blend": {"B": 1.0}}]))
    assert [line.get_xdata()[0] for line in ax.lines] == [1.0, 0.75]  # the step, and the preview
    plt.close("all")


#: openpyxl writes numbers with 16 significant digits ("%.16g"): a relative error below 1e-15.
XLSX_RTOL = 1e-15


def _sheet(book, name) -> pd.DataFrame:
    rows = list(book[name].values)
    return pd.DataFrame(rows[1:], columns=rows[0])


def test_run_workbook_reads_back_the_runs_numbers(open_run, tmp_path):
    out = write_run(open_run, tmp_path / "run", plots=False, xlsx=True)
    book = openpyxl.load_workbook(out / "run.xlsx", read_only=True)
    assert {"summary", "KPIs", "time series", "streams at start", "streams at end", "PSD product",
            "PSD mill content", "models", "scene"} <= set(book.sheetnames)
    kpis = {row[0]: row[2] for row in list(book["KPIs"].values)[1:]}
    for key, value in open_run.kpis.items():
        assert (kpis[key] is None) if not math.isfinite(value) else kpis[key] == pytest.approx(value, rel=XLSX_RTOL)
    # a fraction whose label says [%] is shown as a percentage, as in the report
    formats = {row[0].value: (row[1].value, row[2].number_format) for row in list(openpyxl.load_workbook(
        out / "run.xlsx")["KPIs"].iter_rows())[1:]}
    label, fmt = formats["p80_within_10um_frac"]
    assert label.endswith("[%]") and fmt == "0.0%"
    assert formats["p80_iae_um_h"][1] == "General"
    ts = _sheet(book, "time series")
    for col in ("time_h", "p80_um", "power_kw", "load_frac", "fed_t", "blend_B_pyrite_frac"):
        np.testing.assert_allclose(ts[col].to_numpy(float), open_run.frame[col].to_numpy(float), rtol=XLSX_RTOL)
    end = _sheet(book, "streams at end")
    np.testing.assert_allclose(end["product_tph"].to_numpy(float),
                               open_run.streams["end"]["product_tph"].to_numpy(float), rtol=XLSX_RTOL)
    scene = _sheet(book, "scene").set_index("key")["value"]
    assert scene["feed.feed_tph"] == 30.0 and scene["feed.schedule[0].blend.B_pyrite"] == 1.0
    psd = _sheet(book, "PSD product").set_index("time [h]")
    np.testing.assert_allclose(psd.to_numpy(float), psd_table(open_run.psd).to_numpy(), rtol=XLSX_RTOL)


def test_sweep_writes_comparison_figure_traces_and_workbook(tmp_path, capsys):
    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    out = tmp_path / "sweep"
    assert grindtwin(["sweep", scene, "--vary", "feed.feed_tph=25,35", "--workers", "1", "--out", out,
                      "--xlsx", "--quiet"]) == 0
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table = pd.read_csv(out / "sweep.csv")
    assert "trace" not in table.columns
    traces = pd.read_csv(out / "sweep_traces.csv")
    assert traces.groupby("case").size().tolist() == [16, 16]  # 0.25 h at 1-minute samples
    assert traces.groupby("case")["feed_tph"].first().tolist() == [25.0, 35.0]
    book = openpyxl.load_workbook(out / "sweep.xlsx", read_only=True)
    cases = _sheet(book, "cases")
    np.testing.assert_allclose(cases["specific energy [kWh/t] (specific_energy_kwh_t)"], table["specific_energy_kwh_t"],
                               rtol=XLSX_RTOL)
    errors = [r[list(next(book["cases"].values)).index("error")] for r in list(book["cases"].values)[1:]]
    assert errors == [None, None]  # no error: an empty cell, not Excel's #N/A error value (a text column)
    wide = _sheet(book, "P80 traces")
    np.testing.assert_allclose(wide["case 1: p80_um"], traces.loc[traces["case"] == 1, "p80_um"], rtol=XLSX_RTOL)
    assert table["throughput_tph"].round(0).tolist() == [25.0, 35.0]  # steady open loop: product = feed


def test_sweep_cases_sheet_labels_its_kpis_and_shows_shares_as_percentages_as_the_kpi_sheet_does(tmp_path):
    """The sweep workbook's cases sheet headed its KPIs by their keys alone and showed a share of 0.9997 as
    0.9997: its KPI columns now carry the KPI sheet's meaning and unit (the key after it, as sweep.csv names the
    column) and a share labelled [%] has the KPI sheet's percentage format for its value; the other columns keep
    their names, an undefined KPI is #N/A and a case that ran has an empty error cell."""
    from scenarios.output.labels import KPI_LABELS
    from scenarios.output.workbook import kpi_rows, write_sweep_workbook

    share = "p80_within_10um_frac"
    table = pd.DataFrame({"case": [0, 1], "feed.feed_tph": [25.0, 35.0], share: [0.9997, 0.5],
                          "specific_energy_kwh_t": [10.5, math.nan], "error": [None, "the solver failed"]})
    path = write_sweep_workbook(table, None, None, tmp_path / "sweep.xlsx")
    rows = list(openpyxl.load_workbook(path)["cases"].iter_rows())
    header = [c.value for c in rows[0]]
    assert header == ["case", "feed.feed_tph", f"{KPI_LABELS[share][0]} ({share})",
                      "specific energy [kWh/t] (specific_energy_kwh_t)", "error"]
    assert header[2].endswith("[%] (p80_within_10um_frac)")
    for i, value in enumerate(table[share]):  # the KPI sheet's format of the same share
        (on_kpi_sheet,) = [f for _, _, f in kpi_rows({share: value}).attrs["percent_cells"]]
        assert rows[i + 1][2].value == value and rows[i + 1][2].number_format == on_kpi_sheet
    assert [r[2].number_format for r in rows[1:]] == ["0.00%", "0.0%"]  # 99.97 %, not 100.0 %
    assert [r[3].number_format for r in rows[1:]] == ["General", "General"] and rows[2][3].value == "#N/A"
    assert [r[4].value for r in rows[1:]] == [None, "the solver failed"]


def test_outputs_without_out_are_refused_and_a_run_says_nothing_was_written(tmp_path, capsys):
    scene = short_pyrite_scene(tmp_path, duration_h=0.1)
    assert grindtwin(["run", scene, "--xlsx", "--quiet"]) == 2
    assert "--xlsx write" in capsys.readouterr().err and not list(tmp_path.glob("*.xlsx"))
    assert grindtwin(["run", scene, "--quiet"]) == 0
    assert "no --out DIR given" in capsys.readouterr().err
