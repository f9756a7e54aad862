"""What a run folder shows is the run's: the report says when its folder is not as the run left
it (files missing or changed, an earlier manifest, another version), a share just short of 1 is
never shown as 100 %, an undefined KPI is never an unexplained empty cell, and a summary that is
not a run's is refused naming the file and the field before anything is written."""

from __future__ import annotations

import json
import re

import numpy as np
import openpyxl
import pandas as pd
import pytest

from mpc import outside_band_frac, within_band_frac
from scenarios.errors import SceneError
from scenarios.output.report import RunFolderWarning, render_report, write_report
from scenarios.output.workbook import UNDEFINED_NOTE
from scenarios.output.write import MANIFEST, file_sha256, write_run
from scenarios.run.runner import RunResult
from tests.scenarios.test_cli import grindtwin
from tests.scenarios.test_report import fake_run


def _warnings_box(text: str) -> str:
    found = re.search(r'<div class="warnings">(.*?)</div>', text, re.S)
    return found.group(1) if found else ""


def _edit_summary(run, **changes) -> None:
    summary = json.loads((run / "summary.json").read_text())
    summary.update(changes)
    (run / "summary.json").write_text(json.dumps(summary))


def test_manifest_records_the_sha256_of_every_file_it_lists(tmp_path):
    run = fake_run(tmp_path)
    manifest = json.loads((run / MANIFEST).read_text())
    assert manifest["sha256"] == {name: file_sha256(run / name) for name in manifest["files"]}
    assert "summary.json" in manifest["sha256"] and "p80.png" in manifest["sha256"]


def test_report_of_an_untouched_run_has_no_folder_warning(tmp_path):
    assert _warnings_box(render_report(fake_run(tmp_path))) == ""


def test_report_names_a_hand_edited_summary_and_a_missing_plot(tmp_path):
    """A KPI edited by hand in summary.json and a plot deleted: the report was written with exit 0
    showing the edited number and without the plot, without a word. Now both open the page and
    reach stderr."""
    run = fake_run(tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    summary["kpis"]["p80_iae_um_h"] = 1.0
    (run / "summary.json").write_text(json.dumps(summary))
    (run / "p80.png").unlink()
    box = _warnings_box(render_report(run))
    assert "summary.json" in box and "changed since the run wrote them" in box
    assert "missing: p80.png" in box
    with pytest.warns(RunFolderWarning) as caught:
        out = write_report(run)
    said = " | ".join(str(w.message) for w in caught)
    assert "summary.json" in said and "p80.png" in said
    text = out.read_text(encoding="utf-8")
    assert text.index("changed since") < text.index("Key performance indicators")


def test_report_says_an_earlier_manifest_cannot_be_checked_and_another_version_wrote_it(tmp_path):
    run = fake_run(tmp_path)
    manifest = json.loads((run / MANIFEST).read_text())
    del manifest["sha256"]  # as an earlier grindtwin wrote it
    (run / MANIFEST).write_text(json.dumps(manifest))
    box = _warnings_box(render_report(run))
    assert "records no checksums" in box and "version" not in box  # the same version wrote it
    _edit_summary(run, versions={"grindtwin": "0.0.1-old", "git": None, "git_source": None})
    assert "written by grindtwin 0.0.1-old" in _warnings_box(render_report(run))


def _shares_run(tmp_path) -> tuple:
    """A run whose P80 leaves the target's band on one sample in 4001 and whose load leaves its band
    on one: both shares are computed by the KPIs' own functions."""
    t = np.linspace(0.0, 40.0, 4001)
    p80 = np.full(t.size, 210.0)
    p80[2000] = 230.0
    load = np.ones(t.size)
    load[10] = 1.5
    frame = pd.DataFrame({"time_h": t, "feed_tph": 30.0, "speed_frac_critical": 0.7, "p80_um": p80,
                          "power_kw": 300.0, "load_frac": load})
    kpis = {"p80_within_10um_frac": within_band_frac(p80, 210.0),
            "load_outside_band_frac": outside_band_frac(load, (0.8, 1.2)),
            "p80_iae_um_h": float("nan")}
    summary = {"scene": "shares", "kpis": kpis, "target_p80_um": 210.0, "load_band_frac": [0.8, 1.2]}
    return write_run(RunResult(frame, summary), tmp_path / "run", plots=False, xlsx=True), kpis


def _shown_percent(text: str, key: str) -> str:
    return re.search(rf"<code>{key}</code>.*?<td class=\"num\">([^<]*)</td>", text).group(1)


def test_a_share_just_short_of_one_or_above_zero_is_never_shown_as_100_or_0_percent(tmp_path):
    run, kpis = _shares_run(tmp_path)
    assert 0.0 < kpis["load_outside_band_frac"] < 1e-3 < 1.0 - 1e-3 < kpis["p80_within_10um_frac"] < 1.0
    text = render_report(run)
    book = openpyxl.load_workbook(run / "run.xlsx")
    cells = {row[0].value: row[2] for row in list(book["KPIs"].iter_rows())[1:]}
    for key in ("p80_within_10um_frac", "load_outside_band_frac"):
        value = kpis[key]
        shown = _shown_percent(text, key)
        assert shown not in ("100.0%", "0.0%")
        decimals = len(shown.rstrip("%").split(".")[1])
        assert float(shown.rstrip("%")) == pytest.approx(100 * value, abs=0.5 * 10 ** -decimals)
        # the workbook keeps the fraction and shows it with as many decimals as the report
        cell = cells[key]
        assert cell.value == pytest.approx(value, rel=1e-12)
        assert cell.number_format == "0." + "0" * decimals + "%"
        assert round(100 * value, decimals) not in (0.0, 100.0)


def test_workbook_says_why_a_kpi_cell_is_empty(tmp_path):
    run, kpis = _shares_run(tmp_path)
    book = openpyxl.load_workbook(run / "run.xlsx", read_only=True)
    rows = list(book["KPIs"].values)
    header, rows = rows[0], {r[0]: r for r in rows[1:]}
    assert header[3] == "note"
    assert np.isnan(kpis["p80_iae_um_h"])
    assert rows["p80_iae_um_h"][2] is None and rows["p80_iae_um_h"][3] == UNDEFINED_NOTE
    assert rows["p80_within_10um_frac"][3] is None


@pytest.mark.parametrize("summary, field", [
    ([1, 2], "JSON object"), ({"scene": "x", "kpis": None}, "'kpis'"), ({"scene": "x", "kpis": [1.0]}, "'kpis'"),
    ({"scene": "x", "kpis": {}, "replay": [1]}, "'replay'"),
    ({"scene": "x", "kpis": {}, "versions": "1.0"}, "'versions'"),
    ({"scene": "x", "kpis": {}, "effects": 3}, "'effects'"),
    ({"scene": "x", "kpis": {}, "warnings": "w"}, "'warnings'"),
    ({"scene": "x", "kpis": {}, "replay": {"run_minus_recorded": 2}}, "'replay.run_minus_recorded'")])
def test_a_summary_that_is_not_a_runs_is_refused_naming_the_file_and_field(tmp_path, capsys, summary, field):
    run = fake_run(tmp_path)
    (run / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(SceneError, match=re.escape(field)):
        render_report(run)
    assert grindtwin(["report", run]) == 2
    err = capsys.readouterr().err
    assert "summary.json" in err and "Traceback" not in err
    assert not (run / "report.html").exists() and not (run / "report.html.partial").exists()


def test_a_sweep_folder_is_named_as_such(tmp_path):
    from scenarios.output.write import OutputClaim

    with OutputClaim(tmp_path / "sweep") as claim:
        out = claim.commit(lambda folder: (folder / "sweep.csv").write_text("case\n1\n"), kind="sweep")
    with pytest.raises(SceneError, match="a grindtwin sweep folder, not a run's"):
        render_report(out)


def _lines(fig) -> dict:
    return {line.get_label(): np.asarray(line.get_ydata(), float) for ax in fig.axes for line in ax.get_lines()}


def test_estimates_plot_draws_the_estimate_of_the_plants_p80_not_the_model_before_its_bias():
    """With a P80 bias estimated (disturbance_model "hardness+p80_bias") the estimator's belief of
    the plant's P80 is ``p80_est_um``; the plot drew the model's ``p80_model_um`` alone under
    a caption saying it shows the estimator's P80 beside the plant's."""
    from scenarios.output.plots import _plt, plot_estimates

    t = np.linspace(0.0, 1.0, 21)
    model = 205.0 + t
    frame = pd.DataFrame({"time_h": t, "p80_um": 210.0 + t, "p80_model_um": model, "p80_bias_est_um": 4.0,
                          "p80_est_um": model + 4.0, "hardness_scale": 1.0, "hardness_est": 0.98})
    plt = _plt()
    fig = plot_estimates(plt, RunResult(frame, {"scene": "bias"}))
    lines = _lines(fig)
    np.testing.assert_array_equal(lines["estimate of the plant's P80"], frame["p80_est_um"].to_numpy())
    np.testing.assert_array_equal(lines["estimator's model, before its P80 bias"], model)
    plt.close(fig)


def test_a_batch_p80_plot_does_not_call_the_mill_content_the_product():
    from scenarios.output.plots import _plt, plot_p80

    t = np.linspace(0.0, 0.5, 11)
    frame = pd.DataFrame({"time_h": t, "content_p80_um": 3000.0 - 5000.0 * t, "holdup_t": 0.012})
    plt = _plt()
    fig = plot_p80(plt, RunResult(frame, {"scene": "batch", "mode": "batch", "target_p80_um": None}))
    assert fig.axes[0].get_ylabel() == "P80 of the mill content [µm]"
    np.testing.assert_array_equal(_lines(fig)["P80 of the mill content (batch)"], frame["content_p80_um"])
    plt.close(fig)


def test_a_workbook_no_sheet_holds_is_refused_before_the_run_not_after_it(tmp_path, capsys, no_run):
    """A year at 28.8 s samples is 1,098,001 rows, more than an Excel sheet holds: the workbook is
    written last, so --xlsx failed after the whole run and took every file of it along."""
    from scenarios.output.workbook import EXCEL_MAX_ROWS
    from tests.scenarios.test_runner import short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=8784.0)
    text = scene.read_text()
    assert "sample_period_h = " in text
    scene.write_text(re.sub(r"sample_period_h = [0-9./]+", "sample_period_h = 0.008", text))
    n = int(round(8784.0 / 0.008)) + 1
    assert n + 1 > EXCEL_MAX_ROWS
    out = tmp_path / "year"
    assert grindtwin(["run", scene, "--out", out, "--xlsx", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--xlsx" in err and f"{n:,} samples" in err and "Traceback" not in err
    assert not out.exists() and not (tmp_path / "year.partial").exists()


def test_a_report_that_cannot_be_put_in_place_leaves_no_half_written_page(tmp_path, capsys):
    run = fake_run(tmp_path)
    (run / "report.html").mkdir()  # the rename onto it fails
    (run / "report.html" / "keep.txt").write_text("x")
    assert grindtwin(["report", run]) == 1
    assert "report.html" in capsys.readouterr().err
    assert not (run / "report.html.partial").exists()
    assert (run / "report.html" / "keep.txt").read_text() == "x"


def test_workbook_summary_names_the_calibration_and_sets_the_warnings_apart(tmp_path):
    """The report shows the calibration that ran and opens with the run's warnings; the workbook's
    summary sheet had neither (its warnings sat among the notes as 'note N')."""
    from scenarios.output.labels import calibration_text

    run = fake_run(tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    warning = "the plant's hold-up exceeds what its mill holds filled to its shell"
    summary |= {"warnings": [warning], "notes": summary["notes"] + [warning],
                "calibration": {"name": "dem", "path": "/x/dem.json", "sha256": "cd" * 32}}
    frame = pd.read_parquet(run / "timeseries.parquet")
    out = write_run(RunResult(frame, summary), tmp_path / "again", plots=False, xlsx=True)
    book = openpyxl.load_workbook(out / "run.xlsx", read_only=True)
    rows = dict(list(book["summary"].values)[1:])
    assert rows["calibration"] == calibration_text(summary["calibration"]) and "/x/dem.json" in rows["calibration"]
    assert rows["warning 1"] == warning
    notes = [v for k, v in rows.items() if k.startswith("note ")]
    assert notes == [n for n in summary["notes"] if n != warning]


def test_a_sweep_whose_traces_no_sheet_holds_is_refused_before_any_case(tmp_path, capsys, monkeypatch):
    """sweep --xlsx wrote its workbook after every case had run: a year at 28.8 s samples then
    failed at the end. It is refused before the first case, naming the samples."""
    import scenarios.cli.commands as commands
    from tests.scenarios.test_runner import short_pyrite_scene

    scene = short_pyrite_scene(tmp_path, duration_h=8784.0)
    scene.write_text(re.sub(r"sample_period_h = [0-9./]+", "sample_period_h = 0.008", scene.read_text()))
    monkeypatch.setattr(commands, "sweep_case", lambda s: pytest.fail("a case ran although the sweep is refused"))
    out = tmp_path / "sweep"
    assert grindtwin(["sweep", scene, "--vary", "feed.feed_tph=0.03,0.031", "--out", out, "--xlsx", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--xlsx" in err and f"{int(round(8784.0 / 0.008)) + 1:,} samples" in err
    assert not out.exists()


def test_the_terminal_shows_a_share_short_of_one_as_a_percentage_and_an_undefined_value_as_n_a():
    """run/replay printed shares with 4 significant digits: 0.99996 of the samples in the band
    printed as "1"; a NaN difference of a replay printed "nan"."""
    import io

    from scenarios.cli.commands import _print_kpis, _value_text

    out = io.StringIO()
    _print_kpis({"scene": "s", "kpis": {"p80_within_10um_frac": 0.99996, "p80_iae_um_h": float("nan"),
                                        "specific_energy_kwh_t": 6.6031}}, out)
    lines = out.getvalue().splitlines()
    assert lines[1].split() == ["p80_within_10um_frac", "99.996%"]
    assert lines[2].split() == ["p80_iae_um_h", "n/a"] and lines[3].split() == ["specific_energy_kwh_t", "6.603"]
    assert _value_text("p80_iae_um_h", None) == "n/a" and _value_text("p80_iae_um_h", float("nan")) == "n/a"


def test_the_report_and_workbook_name_the_plants_effects_when_they_are_not_the_scenes(tmp_path):
    """The report's effects row showed the scene's (the controller's model) as if the plant had run
    them; a [plant] table that runs others is now named apart. One row when they are the same."""
    run = fake_run(tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    frame = pd.read_parquet(run / "timeseries.parquet")
    plant = ["breakage", "transport", "holdup"]
    apart = write_run(RunResult(frame, {**summary, "plant_effects": plant}), tmp_path / "apart", plots=False,
                      xlsx=True)
    text = render_report(apart)
    assert "<th>effects (controller&#x27;s model)</th><td>breakage, transport</td>" in text
    assert "<th>plant effects</th><td>breakage, transport, holdup</td>" in text
    book = openpyxl.load_workbook(apart / "run.xlsx", read_only=True)
    rows = {r[0]: r[1] for r in book["summary"].values if r and r[0]}
    assert rows["plant effects"] == "breakage, transport, holdup"
    same = write_run(RunResult(frame, {**summary, "plant_effects": ["transport", "breakage"]}), tmp_path / "same",
                     plots=False)
    text = render_report(same)
    assert "<th>effects</th><td>breakage, transport</td>" in text and "plant effects" not in text


def test_an_undefined_number_is_written_nan_in_every_csv_and_na_in_the_workbook_and_reads_back(tmp_path):
    """The P80 of an empty mill is NaN (undefined): every CSV wrote it as an empty cell, which
    an engineer cannot tell from a sample lost. Now ``NaN`` (read back as NaN, with every other
    number exact) and Excel's #N/A in the workbook's tables of numbers."""
    t = np.linspace(0.0, 1.0, 5)
    p80 = np.array([np.nan, 0.1 + 0.2, 250.0 / 3.0, np.nan, 1e-300])
    frame = pd.DataFrame({"time_h": t, "feed_tph": 30.0, "p80_um": p80, "load_frac": 1.0})
    psd = pd.DataFrame([[1.0, np.nan], [1.0, 0.4]], index=pd.Index([0.0, 1.0], name="time_h"),
                       columns=[1000.0, 50.0])
    streams = pd.DataFrame({"size_um": [1000.0, 50.0], "product_tph": [np.nan, 2.0 / 3.0]}).set_index("size_um")
    result = RunResult(frame, {"scene": "empty mill", "kpis": {"p80_iae_um_h": float("nan")}}, psd=psd,
                       streams={"end": streams})
    run = write_run(result, tmp_path / "run", csv=True, plots=False, xlsx=True)
    text = (run / "timeseries.csv").read_text()
    assert text.splitlines()[1].split(",")[2] == "NaN" and ",," not in text
    back = pd.read_csv(run / "timeseries.csv")
    np.testing.assert_array_equal(back["p80_um"].to_numpy(), p80)  # NaN where NaN, every other number exact
    assert "NaN" in (run / "product_psd.csv").read_text()
    assert np.isnan(pd.read_csv(run / "product_psd.csv", index_col=0).iloc[0, 1])
    streams_back = pd.read_csv(run / "streams.csv", index_col=0)
    assert np.isnan(streams_back["product_tph"].iloc[0]) and streams_back["product_tph"].iloc[1] == 2.0 / 3.0
    book = openpyxl.load_workbook(run / "run.xlsx")
    cells = [c for c in book["time series"]["C"]][1:]
    assert [(c.value, c.data_type) for c in cells][0] == ("#N/A", "e") and cells[1].data_type == "n"
    assert np.isnan(pd.read_excel(run / "run.xlsx", sheet_name="time series")["p80_um"].iloc[3])
    kpis = list(book["KPIs"].values)[1]
    assert kpis[2] is None and kpis[3] == UNDEFINED_NOTE  # the KPI sheet keeps its empty cell and its note


def test_a_plot_copied_into_a_run_folder_is_not_shown_as_the_runs(tmp_path):
    """A run written with --no-plots, then a p80.png of another run copied into its folder: the report embedded
    that plot under this run's caption, with exit 0 and no warning. Now it is left out and named."""
    run = fake_run(tmp_path, plots=False)
    other = fake_run(tmp_path / "other", scene="another scene")
    (run / "p80.png").write_bytes((other / "p80.png").read_bytes())
    text = render_report(run)
    assert "data:image/png" not in text
    assert "plots the run did not write are in its folder (copied in?): p80.png" in _warnings_box(text)
    with pytest.warns(RunFolderWarning, match="p80.png"):
        write_report(run)
