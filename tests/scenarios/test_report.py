"""grindtwin report: one self-contained HTML file with the KPI table and the plots inline."""

from __future__ import annotations

import base64
import html
import json
import re

import numpy as np
import pandas as pd
import pytest

from scenarios.errors import SceneError
from scenarios.output.write import write_run
from scenarios.output.plots import plot_caption
from scenarios.output.report import render_report, write_report
from scenarios.run.runner import RunResult


def fake_run(tmp_path, plots=True, **summary_changes):
    """A run directory written from a small hand-made result (no simulation needed)."""
    t = np.linspace(0, 1, 11)
    frame = pd.DataFrame({"time_h": t, "feed_tph": 30.0, "speed_frac_critical": 0.7,
                          "p80_um": 250 - 20 * t, "power_kw": 300.0, "specific_energy_kwh_t": 10.0,
                          "load_frac": 1.0, "holdup_t": 10.0, "fed_t": 30 * t, "produced_t": 30 * t})
    psd = pd.DataFrame([[1.0, 0.8, 0.3], [1.0, 0.9, 0.4]], index=pd.Index([0.0, 1.0], name="time_h"),
                       columns=[1000.0, 250.0, 50.0])
    summary = {"scene": "tiny <demo>", "description": "a & b", "seed": 7, "controller": "none",
               "mode": "open_loop", "target_p80_um": 240.0, "load_band_frac": [0.8, 1.2],
               "effects": ["breakage", "transport"], "components": ["B"],
               "kpis": {"p80_iae_um_h": 4.5, "specific_energy_kwh_t": 10.0, "throughput_t": 30.0,
                        "solve_time_median_s": float("nan"), "mass_balance_error": 1e-12},
               "plant_model": "Model: 2 effect(s), plant", "controller_model": "Model: 3 effect(s), <coarse>",
               "notes": ["started at steady state"],
               "versions": {"numpy": np.__version__, "git": "0123456789ab", "git_source": "checkout"}}
    summary.update(summary_changes)
    return write_run(RunResult(frame, summary, psd=psd), tmp_path / "run", plots=plots)


def test_report_is_self_contained_with_kpi_table_and_images(tmp_path):
    run = fake_run(tmp_path)
    out = write_report(run)
    assert out == run / "report.html"
    text = out.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>") and text.rstrip().endswith("</html>")
    assert '<table class="kpis">' in text
    row = re.search(r"<code>specific_energy_kwh_t</code>.*?</tr>", text).group(0)
    assert ">10<" in row
    assert re.search(r"<code>solve_time_median_s</code>.*?n/a", text)  # null KPI shown as n/a
    images = re.findall(r'<img [^>]*src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    assert len(images) == 5  # p80, inputs, energy, load, psd
    assert all(base64.b64decode(b)[:8] == b"\x89PNG\r\n\x1a\n" for b in images)
    # nothing external: no links to files, no scripts; user text is escaped
    assert "<script" not in text and 'src="p80.png"' not in text
    assert "tiny &lt;demo&gt;" in text and "a &amp; b" in text


def test_report_refuses_what_is_not_a_complete_run(tmp_path):
    with pytest.raises(SceneError, match="not found"):
        render_report(tmp_path / "nowhere")
    (tmp_path / "a_file").write_text("{}")
    with pytest.raises(SceneError, match="a file, not a run directory"):  # it said 'not found' of a file there
        render_report(tmp_path / "a_file")
    with pytest.raises(SceneError, match="no summary.json"):
        render_report(tmp_path)
    (tmp_path / "_INCOMPLETE").write_text("")
    with pytest.raises(SceneError, match="incomplete"):
        render_report(tmp_path)


def test_a_hand_edited_summary_field_of_the_wrong_type_is_refused_naming_it(tmp_path):
    """A summary.json whose description was a number raised AttributeError (exit 1, a traceback);
    components that are numbers, TypeError. Now the field is named, and nothing is written."""
    run = fake_run(tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    (run / "summary.json").write_text(json.dumps({**summary, "description": 42}))
    with pytest.raises(SceneError, match=r"'description' must be a JSON string, got 42"):
        write_report(run)
    assert not (run / "report.html").exists()
    (run / "summary.json").write_text(json.dumps({**summary, "components": [1, 2]}))
    assert "<th>components</th><td>1, 2</td>" in render_report(run)


def test_report_never_replaces_a_users_report_html(tmp_path, capsys):
    """A folder of the user's with a summary.json and a report.html of their own (no manifest of
    grindtwin's): refused, exit 2, their report untouched; a folder grindtwin wrote is reported."""
    from scenarios.cli import main as grindtwin

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "summary.json").write_text(json.dumps({"scene": "mine", "kpis": {}}))
    (mine / "report.html").write_text("<p>my notes</p>")
    assert grindtwin(["report", str(mine)]) == 2
    assert "written by grindtwin" in capsys.readouterr().err
    assert (mine / "report.html").read_text() == "<p>my notes</p>"
    assert sorted(p.name for p in mine.iterdir()) == ["report.html", "summary.json"]
    assert write_report(fake_run(tmp_path)).is_file()


def test_report_shows_plant_beside_controller_units_and_commit(tmp_path):
    text = render_report(fake_run(tmp_path))
    models = re.search(r'<div class="models">(.*?)</div></div>', text, re.S).group(1)
    plant, ctl = re.findall(r"<h3>(.*?)</h3><pre>(.*?)</pre>", models)
    assert plant == ("Plant (simulated)", "Model: 2 effect(s), plant")
    assert ctl == ("Controller&#x27;s model", "Model: 3 effect(s), &lt;coarse&gt;")
    assert "throughput [t]<" not in text and "product discharged over the run (a batch: its charge) [t]" in text
    assert "git commit <code>0123456789ab</code> (checkout)" in text


@pytest.mark.parametrize("fast", [False, True])
def test_report_says_when_the_calibration_was_a_fast_check(tmp_path, fast):
    run = fake_run(tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    summary["calibration"] = {"name": "dem", "path": "/x/calibration-dem.json", "sha256": "ab" * 32,
                              **({"fast": True} if fast else {})}
    (run / "summary.json").write_text(json.dumps(summary))
    text = render_report(run)
    assert "/x/calibration-dem.json, sha256 abababababab" in text
    assert ("made with --fast" in text) is fast and ("not a calibration" in text) is fast


def test_open_loop_report_says_there_is_no_controller(tmp_path):
    import json

    run = fake_run(tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    summary.update(controller_model=None, versions={"git": None, "git_source": "installed package"})
    (run / "summary.json").write_text(json.dumps(summary))
    text = render_report(run)
    assert "none: open loop" in text and "no git commit (installed package)" in text


def test_git_commit_of_an_install_is_the_checkouts_only_when_every_file_matches(tmp_path):
    """An install (files copied from a checkout) is that checkout's HEAD only if every tracked
    source file is HEAD's version; one changed byte and it is not."""
    import subprocess
    import tarfile
    from pathlib import Path

    from scenarios.run.summary import PACKAGES, _installed_matches_head

    repo = Path(__file__).resolve().parents[2]
    archive = tmp_path / "head.tar"
    subprocess.run(["git", "archive", "-o", str(archive), "HEAD", *PACKAGES], cwd=repo, check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(tmp_path / "site", filter="data")
    assert _installed_matches_head(repo, tmp_path / "site")
    target = tmp_path / "site" / "scenarios" / "run" / "summary.py"
    target.write_bytes(target.read_bytes() + b"\n")
    assert not _installed_matches_head(repo, tmp_path / "site")


def test_warnings_open_the_report_before_the_numbers_they_qualify(tmp_path):
    """A run's warnings (summary.json ``warnings``, also among its notes) stand in their own
    section before the KPI table, escaped, and are not repeated among the notes at the end."""
    run = fake_run(tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    warning = "the plant's hold-up exceeds what its mill holds filled to its shell (26.8 t) <here>"
    summary["warnings"] = [warning]
    summary["notes"] = summary["notes"] + [warning]
    (run / "summary.json").write_text(json.dumps(summary))
    text = render_report(run)
    escaped = html.escape(warning)
    assert "&lt;here&gt;" in escaped
    assert text.count(escaped) == 1
    assert text.index("<h2>Warnings</h2>") < text.index(escaped) < text.index("Key performance indicators")
    assert "started at steady state" in text[text.index("<h2>Notes</h2>"):]
    assert "<h2>Warnings</h2>" not in render_report(fake_run(tmp_path / "calm"))


def test_captions_say_what_this_runs_plots_draw(tmp_path):
    """Fixed captions promised a target band to runs without a target and a product P80 to a batch."""
    text = render_report(fake_run(tmp_path))
    assert "product P80 against time, with the target and its ±10 µm band" in text
    assert "mill load (hold-up / nominal) against time, with the stable band" in text
    assert plot_caption("p80.png", {"mode": "open_loop"}) == "product P80 against time"
    assert plot_caption("p80.png", {"mode": "batch"}).startswith("P80 of the mill content")
    assert plot_caption("load.png", {"mode": "batch", "load_band_frac": [0.8, 1.2]}) == (
        "the batch mill's hold-up [kg] against time")
    assert plot_caption("load.png", {"mode": "closed_loop"}) == "mill load (hold-up / nominal) against time"


def test_a_report_without_plots_says_why_and_a_replay_names_its_history(tmp_path):
    replay = {"history": "/plant/day.csv", "history_start": "2026-11-30T06:00:00", "run_minus_recorded": {}}
    text = render_report(fake_run(tmp_path, plots=False, replay=replay))
    assert "None in the run folder (a run written with --no-plots has none)" in text
    assert "/plant/day.csv" in text and "2026-11-30T06:00:00" in text
