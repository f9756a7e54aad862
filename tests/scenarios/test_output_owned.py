"""A file grindtwin wrote into a run folder and the user changed since is the user's: a
report.html edited by hand (or put there by the user) is never replaced by ``grindtwin report``
nor removed by a later ``grindtwin run --out`` to the same folder; one grindtwin wrote and nobody
touched is replaced as before."""

from __future__ import annotations

import json

import pytest

from scenarios.errors import SceneError
from scenarios.output.report import render_report, write_report
from scenarios.output.write import LATER_SHA256, MANIFEST, file_sha256, write_run
from tests.scenarios.test_cli import grindtwin
from tests.scenarios.test_output_dirs import tiny_result
from tests.scenarios.test_report import fake_run

EDITED = "<p>my notes on this run</p>"


def test_the_manifest_records_the_report_and_an_untouched_report_is_replaced(tmp_path):
    run = fake_run(tmp_path)
    out = write_report(run)
    manifest = json.loads((run / MANIFEST).read_text())
    assert manifest[LATER_SHA256] == {"report.html": file_sha256(out)}
    assert "report.html" not in manifest["files"]  # not a file of the run: its absence is no problem
    out.write_text("<p>an older page grindtwin wrote</p>")  # as if another version wrote it, then:
    manifest[LATER_SHA256]["report.html"] = file_sha256(out)
    (run / MANIFEST).write_text(json.dumps(manifest))
    assert write_report(run).read_text(encoding="utf-8") == render_report(run)
    assert sorted(p.name for p in run.iterdir() if "report" in p.name or "manifest" in p.name) == [
        MANIFEST, "report.html"]  # no temporary file left


def test_a_hand_edited_report_is_refused_naming_the_file_and_kept(tmp_path, capsys):
    """The audit's reproduction: grindtwin report, the user edits report.html, grindtwin report
    again replaced it without a word (exit 0)."""
    run = fake_run(tmp_path)
    write_report(run)
    (run / "report.html").write_text(EDITED)
    assert grindtwin(["report", run]) == 2
    err = capsys.readouterr().err
    assert str(run / "report.html") in err and "not the one grindtwin last wrote" in err
    assert "Move it out of the folder" in err and "Traceback" not in err
    assert (run / "report.html").read_text() == EDITED
    assert not (run / "report.html.partial").exists()
    (run / "report.html").rename(tmp_path / "my-report.html")  # as the message says: then it is written
    assert grindtwin(["report", run]) == 0
    assert (tmp_path / "my-report.html").read_text() == EDITED


@pytest.mark.parametrize("record", ["none", "another page's"])
def test_a_report_html_grindtwin_has_no_record_of_is_refused_unless_it_is_the_same_page(tmp_path, record):
    """A report.html of the user's in a run folder (or one a grindtwin that recorded nothing
    wrote): refused; the very page about to be written is no loss, so it is replaced."""
    run = fake_run(tmp_path)
    if record != "none":
        manifest = json.loads((run / MANIFEST).read_text())
        manifest[LATER_SHA256] = {"report.html": "0" * 64}
        (run / MANIFEST).write_text(json.dumps(manifest))
    (run / "report.html").write_text(EDITED)
    with pytest.raises(SceneError, match="report.html: this report.html is not the one grindtwin last wrote"):
        write_report(run)
    assert (run / "report.html").read_text() == EDITED
    (run / "report.html").write_text(render_report(run), encoding="utf-8")
    assert write_report(run).is_file()


def test_a_report_html_that_is_a_link_is_never_replaced(tmp_path):
    run = fake_run(tmp_path)
    write_report(run)
    target = tmp_path / "elsewhere.html"
    target.write_text((run / "report.html").read_text())  # the same bytes, but the link is the user's
    (run / "report.html").unlink()
    (run / "report.html").symlink_to(target)
    with pytest.raises(SceneError, match="not the one grindtwin last wrote"):
        write_report(tmp_path / "run")
    assert (run / "report.html").is_symlink()


def test_run_out_into_a_folder_whose_report_was_edited_is_refused_and_the_report_kept(tmp_path):
    out = tmp_path / "run"
    write_run(tiny_result(1), out, plots=False)
    write_report(out)
    (out / "report.html").write_text(EDITED)
    with pytest.raises(SceneError, match=r"did not write \(report.html\); report.html is not the one grindtwin "
                                         r"last wrote"):
        write_run(tiny_result(2), out, plots=False)
    assert (out / "report.html").read_text() == EDITED
    assert json.loads((out / "summary.json").read_text())["seed"] == 1
    (out / "report.html").unlink()
    write_report(out)  # untouched: the old result goes as a whole, its report with it
    write_run(tiny_result(3), out, plots=False)
    assert json.loads((out / "summary.json").read_text())["seed"] == 3
    assert not (out / "report.html").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_report_edited_while_a_run_computes_is_kept_with_the_run_beside_it(tmp_path):
    from scenarios.errors import RunError
    from scenarios.output.write import OutputClaim, write_files

    out = tmp_path / "run"
    write_run(tiny_result(1), out, plots=False)
    write_report(out)
    with OutputClaim(out) as claim:
        (out / "report.html").write_text(EDITED)  # during the run
        with pytest.raises(RunError, match="appeared in the folder during the run"):
            claim.commit(lambda folder: write_files(tiny_result(2), folder, plots=False))
    assert (out / "report.html").read_text() == EDITED
    assert json.loads((tmp_path / "run.partial" / "summary.json").read_text())["seed"] == 2
