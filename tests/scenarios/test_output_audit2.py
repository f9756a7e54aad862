"""What a user could lose or get silently wrong in a run folder: a size column whose header names
another sieve, an infinity written as "undefined", a report mixed into a folder a run is
replacing, a previous result lost when its replacement cannot be put in place, and a file of the
user's taken by a fixed scratch name."""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np
import openpyxl
import pandas as pd
import pytest

from scenarios.errors import SceneError
from scenarios.output.report import render_report, write_report
from scenarios.output.workbook import UNDEFINED_NOTE, write_workbook
from scenarios.output.write import INCOMPLETE_MARKER, OutputClaim, write_run
from scenarios.run.runner import RunResult
from tests.scenarios.test_cli import grindtwin
from tests.scenarios.test_report import fake_run

HEADER = "cumulative % passing "


def _result(kpis=None, sizes=(1000.0, 250.0)) -> RunResult:
    t = np.linspace(0.0, 1.0, 3)
    frame = pd.DataFrame({"time_h": t, "feed_tph": 30.0, "p80_um": 250.0, "load_frac": 1.0})
    psd = pd.DataFrame([np.linspace(1.0, 0.2, len(sizes))] * 2, index=pd.Index([0.0, 1.0], name="time_h"),
                       columns=list(sizes))
    return RunResult(frame, {"scene": "audit", "kpis": kpis or {}}, psd=psd)


def _sizes(headers) -> list[float]:
    return [float(h[len(HEADER):-len(" µm")]) for h in headers]


def test_every_size_header_names_its_sieve_exactly_and_no_two_share_one(tmp_path):
    """``:g`` kept six digits: the default grid's 4737.6154 µm sieve was headed "4737.62 µm", and
    sieves of 6699.991 and 6699.994 µm both "6699.99 µm" (a reader maps columns to sizes by header)."""
    sizes = (6700.0, 6699.994, 6699.991, 4737.6154, 0.1 + 0.2)
    run = write_run(_result(sizes=sizes), tmp_path / "run", plots=False, xlsx=True)
    csv_headers = list(pd.read_csv(run / "product_psd.csv", index_col=0).columns)
    assert _sizes(csv_headers) == list(sizes) and len(set(csv_headers)) == len(sizes)
    assert csv_headers[0] == HEADER + "6700 µm"  # no trailing ".0" on a whole size
    sheet = [c.value for c in openpyxl.load_workbook(run / "run.xlsx")["PSD product"][1]][1:]
    assert sheet == csv_headers


def test_summary_json_tells_an_infinity_from_an_undefined_number(tmp_path):
    """summary.json wrote an infinite KPI as null, the mark of an undefined one (NaN); the
    workbook's KPI sheet called it "not defined" and the report "n/a". Now "inf" / "-inf" (what
    the CSVs write; ``float`` reads it back), null for NaN alone."""
    kpis = {"p80_iae_um_h": math.inf, "specific_energy_kwh_t": -math.inf, "mass_balance_error": math.nan}
    run = write_run(_result(kpis), tmp_path / "run", plots=False, xlsx=True)
    back = json.loads((run / "summary.json").read_text())["kpis"]
    assert back == {"p80_iae_um_h": "inf", "specific_energy_kwh_t": "-inf", "mass_balance_error": None}
    assert float(back["p80_iae_um_h"]) == math.inf and float(back["specific_energy_kwh_t"]) == -math.inf
    rows = {r[0]: r[2:] for r in list(openpyxl.load_workbook(run / "run.xlsx")["KPIs"].values)[1:]}
    assert rows == {"p80_iae_um_h": ("inf", None), "specific_energy_kwh_t": ("-inf", None),
                    "mass_balance_error": (None, UNDEFINED_NOTE)}
    cells = _report_cells(render_report(run))
    assert cells["p80_iae_um_h"] == "inf" and cells["specific_energy_kwh_t"] == "-inf"
    assert "n/a" in cells["mass_balance_error"]


def _report_cells(text: str) -> dict[str, str]:
    """KPI key -> the report's value cell."""
    return dict(re.findall(r'<tr><td><code>(\w+)</code></td><td>[^<]*</td><td class="num">(.*?)</td></tr>', text))


def test_a_report_waits_for_no_run_replacing_its_folder(tmp_path, capsys):
    """``grindtwin report DIR`` took no lock: while ``run --out DIR`` replaced the folder, the
    report of the old run could land in the new run's folder (and be recorded there as its
    report). Now it holds DIR.lock as a run does: refused at once, nothing written."""
    run = fake_run(tmp_path)
    with OutputClaim(run) as claim:  # a run writing its new result into the folder
        with pytest.raises(SceneError, match="another grindtwin run or report .* is writing to this folder"):
            write_report(run)
        assert grindtwin(["report", str(run)]) == 2
        assert "no report was written" in capsys.readouterr().err
        claim.commit(lambda folder: (folder / "summary.json").write_text(json.dumps({"kpis": {}})))
    assert not (run / "report.html").exists()
    assert write_report(run) == run / "report.html"  # once the run is done
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # the lock is gone with the report


def test_a_users_file_named_like_the_old_aside_name_is_kept_and_the_run_is_written(tmp_path):
    """A previous result was moved aside to the fixed name DIR.replaced-PID: a file of the user's
    of that name made the run fail after all its work (results lost), an empty folder of theirs
    was replaced. Now the previous result goes aside into a fresh folder nobody holds."""
    out = tmp_path / "out"
    write_run(_result(), out, plots=False)
    theirs = tmp_path / f"out.replaced-{os.getpid()}"
    theirs.write_text("my notes\n")
    write_run(_result({"p80_iae_um_h": 1.0}), out, plots=False)
    assert json.loads((out / "summary.json").read_text())["kpis"] == {"p80_iae_um_h": 1.0}
    assert theirs.read_text() == "my notes\n" and sorted(p.name for p in tmp_path.iterdir()) == ["out", theirs.name]


def test_a_result_that_cannot_be_put_in_place_leaves_the_previous_one_where_it_was(tmp_path, monkeypatch):
    """The previous result was renamed away before the new one was put in place; when that
    second rename failed, DIR was gone (its result under another name) and the new one removed."""
    out = tmp_path / "out"
    write_run(_result({"p80_iae_um_h": 1.0}), out, plots=False)
    real = Path.rename

    def failing(self, target):
        if self.name == "out.partial":
            raise OSError(5, "Input/output error")
        return real(self, target)

    monkeypatch.setattr(Path, "rename", failing)
    with pytest.raises(OSError):
        write_run(_result({"p80_iae_um_h": 2.0}), out, plots=False)
    monkeypatch.undo()
    assert json.loads((out / "summary.json").read_text())["kpis"] == {"p80_iae_um_h": 1.0}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_workbook_leaves_a_users_file_named_like_its_scratch_file_alone(tmp_path):
    """The workbook was written to the fixed name ``PATH.partial`` and renamed: a user's
    ``book.xlsx.partial`` beside ``book.xlsx`` was overwritten and then gone."""
    theirs = tmp_path / "book.xlsx.partial"
    theirs.write_text("mine\n")
    write_workbook(_result(), tmp_path / "book.xlsx")
    assert theirs.read_text() == "mine\n" and sorted(p.name for p in tmp_path.iterdir()) == ["book.xlsx",
                                                                                           theirs.name]


def test_a_workbook_scratch_file_left_by_a_killed_run_does_not_refuse_the_next_run(tmp_path):
    """A run killed while it wrote its workbook leaves DIR.partial (marked) with the workbook's
    scratch file: the next run takes the folder over rather than call that file the user's."""
    stale = tmp_path / "out.partial"
    stale.mkdir()
    (stale / INCOMPLETE_MARKER).write_text("")
    (stale / "summary.json").write_text("{}")
    (stale / ".run.xlsx.k2j4x9.partial").write_bytes(b"PK")
    run = write_run(_result(), tmp_path / "out", plots=False, xlsx=True)
    assert (run / "run.xlsx").is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_the_size_distributions_name_the_streams_sizes_exactly(write_scene, tmp_path):
    """product_psd.csv's sizes were rounded to 4 decimals (4737.6154 where streams.csv holds
    4737.615433...): a join of the two on size found nothing."""
    from tests.scenarios.conftest import open_loop

    text = open_loop()
    for old, new in (("duration_h = 8.0", "duration_h = 0.5"),
                     ("at_h = 2.0", "at_h = 0.2"), ("ramp_h = 1.0", "ramp_h = 0.2")):
        text = text.replace(old, new)
    out = tmp_path / "run"
    assert grindtwin(["run", str(write_scene(text)), "--out", str(out), "--no-plots"]) == 0
    streams = set(pd.read_csv(out / "streams.csv")["size_upper_um"])
    for name in ("product_psd.csv", "mill_psd.csv"):
        assert set(_sizes(pd.read_csv(out / name, index_col=0).columns)) == streams, name
    final = json.loads((out / "summary.json").read_text())["final_psd"]["size_um"]
    assert set(final) == streams


def test_a_users_partial_file_in_a_run_folder_is_never_taken(tmp_path):
    """The report and the manifest's rewrite went through the fixed names report.html.partial and
    grindtwin-manifest.json.partial, and a later run counted those names as its own: a user's file
    of that name was overwritten by the report, then removed with the folder. They now go through
    names no one holds, and a file of the user's by those names is theirs: kept, the folder refused."""
    run = fake_run(tmp_path)
    mine = run / "report.html.partial"
    mine.write_text("my notes")
    write_report(run)
    assert mine.read_text() == "my notes" and (run / "report.html").is_file()
    with pytest.raises(SceneError, match="report.html.partial"):
        OutputClaim(run).__enter__()
    assert mine.read_text() == "my notes"
    mine.unlink()
    (run / ".report.html.x1y2.partial").write_text("<html")  # left by a report killed while writing
    with OutputClaim(run):
        pass  # a later run may replace the folder: the leftover is grindtwin's
