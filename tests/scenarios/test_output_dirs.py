"""Output folders: nothing a user has is deleted or mixed with; a bad --out is refused before
any work; a previous grindtwin result is replaced as a whole."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from scenarios.errors import SceneError
from scenarios.output.write import write_run
from scenarios.run.runner import RunResult
from tests.scenarios.test_cli import grindtwin
from tests.scenarios.test_runner import LIBRARY, short_pyrite_scene


def tiny_result(seed: int = 7) -> RunResult:
    t = np.linspace(0, 1, 5)
    frame = pd.DataFrame({"time_h": t, "feed_tph": 30.0, "speed_frac_critical": 0.7, "p80_um": 250.0,
                          "power_kw": 300.0, "load_frac": 1.0})
    return RunResult(frame, {"scene": "tiny", "seed": seed, "kpis": {}, "target_p80_um": None})


def test_a_folder_with_the_users_files_is_refused_and_left_alone(tmp_path, capsys, no_run):
    """The issue's reproduction: the scene and a note in p/, then run --out p."""
    p = tmp_path / "p"
    p.mkdir()
    (p / "notes.txt").write_text("x\n")
    shutil.copy(LIBRARY / "pyrite_surge.toml", p)
    assert grindtwin(["run", p / "pyrite_surge.toml", "--out", p, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "grindtwin did not write" in err and "Traceback" not in err
    assert sorted(x.name for x in p.iterdir()) == ["notes.txt", "pyrite_surge.toml"]
    assert (p / "notes.txt").read_text() == "x\n"
    assert not (tmp_path / "p.partial").exists() and not (tmp_path / "p.lock").exists()


def test_the_scene_folder_and_the_current_folder_are_refused(tmp_path, monkeypatch, capsys, no_run):
    scene = short_pyrite_scene(tmp_path)
    monkeypatch.chdir(tmp_path)
    for out in (".", str(tmp_path)):
        assert grindtwin(["run", scene, "--out", out, "--quiet"]) == 2
        assert "Traceback" not in capsys.readouterr().err
    sub = tmp_path / "sub"
    sub.mkdir()
    monkeypatch.chdir(sub)
    assert grindtwin(["run", scene, "--out", "..", "--quiet"]) == 2  # a parent of the current folder
    assert "current folder or one of its parents" in capsys.readouterr().err
    assert scene.exists() and sorted(x.name for x in tmp_path.iterdir()) == ["short.toml", "sub"]


def test_an_empty_folder_or_a_previous_run_is_replaced_as_a_whole(tmp_path):
    from scenarios.output.write import MANIFEST

    out = tmp_path / "run"
    out.mkdir()
    assert write_run(tiny_result(1), out, plots=False) == out
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["written_by"] == "grindtwin" and "summary.json" in manifest["files"]
    from scenarios.output.report import write_report
    write_report(out)  # grindtwin report's file, untouched: ours too
    write_run(tiny_result(2), out, plots=False)
    assert json.loads((out / "summary.json").read_text())["seed"] == 2
    assert not (out / "report.html").exists()  # the old result went as a whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no .old, .partial or .lock left


def test_a_previous_run_with_a_file_added_by_the_user_is_refused(tmp_path):
    out = tmp_path / "run"
    write_run(tiny_result(1), out, plots=False)
    (out / "my_analysis.xlsx").write_text("precious")
    with pytest.raises(SceneError, match=r"holds files grindtwin did not write \(my_analysis.xlsx\)"):
        write_run(tiny_result(2), out, plots=False)
    assert (out / "my_analysis.xlsx").read_text() == "precious"
    assert json.loads((out / "summary.json").read_text())["seed"] == 1


def test_a_previous_runs_file_edited_since_is_the_users_and_refused(tmp_path):
    """A time series annotated by hand in a result folder was replaced by the next run --out there
    without a word (the manifest had its sha256; only report.html was checked against it)."""
    out = tmp_path / "run"
    write_run(tiny_result(1), out, csv=True, plots=False)
    edited = (out / "timeseries.csv").read_text() + "# checked by J. against the plant log\n"
    (out / "timeseries.csv").write_text(edited)
    with pytest.raises(SceneError, match=r"holds files grindtwin did not write \(timeseries.csv\); timeseries.csv is "
                                         r"not the one grindtwin last wrote \(edited since, or yours\), so it is kept"):
        write_run(tiny_result(2), out, csv=True, plots=False)
    assert (out / "timeseries.csv").read_text() == edited
    assert json.loads((out / "summary.json").read_text())["seed"] == 1


def test_a_file_of_that_name_is_refused(tmp_path):
    target = tmp_path / "results"
    target.write_text("not a folder")
    with pytest.raises(SceneError, match="a file of that name exists"):
        write_run(tiny_result(), target, plots=False)
    assert target.read_text() == "not a folder"


def test_a_second_run_to_a_locked_folder_is_refused_at_once(tmp_path, capsys, no_run):
    """Two runs to one --out cannot mix: while one holds DIR.lock another is refused before it
    starts (flock: a separate open file description conflicts even in the same process)."""
    from scenarios.output.write import MANIFEST, OutputClaim

    out = tmp_path / "out"
    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    with OutputClaim(out) as first:
        assert grindtwin(["run", scene, "--out", out, "--quiet"]) == 2
        assert f"another grindtwin run or report (grindtwin lock pid {os.getpid()})" in capsys.readouterr().err
        first.commit(lambda folder: (folder / "summary.json").write_text("{}"))
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "summary.json"]


def test_a_lock_file_holds_its_tag_from_its_first_instant(tmp_path, monkeypatch):
    """A run's DIR.lock is never seen empty: a second run opening it between the first run's
    create and its write used to find no tag and refuse with "not grindtwin's" (a wrong reason).
    Every open of the lock name must find the tag, and no temporary file is left beside it."""
    import scenarios.output.write as write
    from scenarios.output.write import LOCK_TAG, OutputClaim

    seen, real_open = [], os.open

    def watching_open(path, flags, *args):
        fd = real_open(path, flags, *args)
        if Path(path).name == "out.lock":
            seen.append(Path(path).read_text())
        return fd

    monkeypatch.setattr(write.os, "open", watching_open)
    with OutputClaim(tmp_path / "out") as claim:
        claim.commit(lambda folder: (folder / "summary.json").write_text("{}"))
    assert seen and all(text.startswith(LOCK_TAG) for text in seen), seen
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_users_lock_file_beside_out_is_refused_and_kept(tmp_path, capsys, no_run):
    """``--out uv`` beside a project's ``uv.lock``: grindtwin's lock name is taken by a file it did
    not write, so the run is refused before any work and the file is left as it was (it was
    emptied and deleted before)."""
    lock = tmp_path / "uv.lock"
    lock.write_text("version = 1\n")
    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    assert grindtwin(["run", scene, "--out", tmp_path / "uv", "--quiet"]) == 2
    assert "uv.lock beside it is not grindtwin's" in capsys.readouterr().err
    assert lock.read_text() == "version = 1\n" and not (tmp_path / "uv").exists()


def test_an_out_that_is_a_symbolic_link_is_refused_before_the_run(tmp_path, capsys, no_run):
    """A link to an empty folder failed after the run ('Not a directory', nothing saved); a link
    to an earlier result was renamed away and replaced by a folder. Both refused first, link kept."""
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    assert grindtwin(["run", scene, "--out", tmp_path / "link", "--quiet"]) == 2
    assert "symbolic link" in capsys.readouterr().err
    assert (tmp_path / "link").is_symlink() and not any((tmp_path / "real").iterdir())


def test_a_signal_a_solver_swallowed_still_stops_the_commit(tmp_path, no_run):
    """SIGTERM landing inside a CasADi call can come out of it swallowed: the run went on and
    wrote its results with exit 0 (seen once in the suite). The handler's record stops the commit."""
    from scenarios.errors import RECEIVED_SIGNALS, Interrupted
    from scenarios.output.write import OutputClaim

    RECEIVED_SIGNALS[:] = [15]
    try:
        with pytest.raises(Interrupted), OutputClaim(tmp_path / "out") as claim:
            claim.commit(lambda folder: (folder / "summary.json").write_text("{}"))
    finally:
        RECEIVED_SIGNALS.clear()
    assert list(tmp_path.iterdir()) == []


def test_a_lock_left_by_a_killed_run_is_taken_over(tmp_path, no_run):
    """A run killed with -9 leaves its DIR.lock (no flock held any more): the next run takes it."""
    from scenarios.output.write import LOCK_TAG, OutputClaim

    (tmp_path / "out.lock").write_text(f"{LOCK_TAG} pid 1\n")
    with OutputClaim(tmp_path / "out") as claim:
        claim.commit(lambda folder: (folder / "summary.json").write_text("{}"))
    assert not (tmp_path / "out.lock").exists() and (tmp_path / "out" / "summary.json").exists()


def _read_only_place(tmp_path) -> Path:
    """A folder nobody may create entries in (chmod 555; root ignores modes, so /sys for root)."""
    if os.geteuid() == 0:
        return Path("/sys/kernel/grindtwin-test-out")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    return ro / "out"


def test_an_unwritable_out_is_refused_before_the_run(tmp_path, capsys, no_run):
    out = _read_only_place(tmp_path)
    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    assert grindtwin(["run", scene, "--out", out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "cannot write there" in err and "Traceback" not in err


def test_a_stale_partial_folder_is_removed_by_name_only(tmp_path):
    out = tmp_path / "run"
    stale = tmp_path / "run.partial"  # a run killed with SIGKILL leaves this
    stale.mkdir()
    (stale / "_INCOMPLETE").write_text("")
    (stale / "timeseries.parquet").write_text("")
    write_run(tiny_result(), out, plots=False)
    assert not stale.exists() and (out / "summary.json").exists()
    stale.mkdir()
    (stale / "thesis.docx").write_text("not ours")
    with pytest.raises(SceneError, match="run.partial is left from an earlier run"):
        write_run(tiny_result(), out, plots=False)
    assert (stale / "thesis.docx").read_text() == "not ours"
    (stale / "thesis.docx").unlink()
    stale.rmdir()
    stale.write_text("a user's file")  # it was said to hold "files grindtwin did not write"
    with pytest.raises(SceneError, match="run.partial is a file, not grindtwin's; it is where this run writes"):
        write_run(tiny_result(), out, plots=False)
    assert stale.read_text() == "a user's file"


def test_sweep_out_follows_the_same_rules(tmp_path, capsys):
    out = tmp_path / "sweep"
    out.mkdir()
    (out / "sweep.csv").write_text("my own table\n")  # same name, but not written by grindtwin
    scene = short_pyrite_scene(tmp_path, duration_h=0.25)
    assert grindtwin(["sweep", scene, "--vary", "feed.feed_tph=24,30", "--workers", "1", "--out", out,
                      "--quiet"]) == 2
    assert "grindtwin did not write" in capsys.readouterr().err
    assert (out / "sweep.csv").read_text() == "my own table\n"


def test_a_refused_folder_is_named_for_the_python_caller_too(tmp_path):
    """run_scene(out_dir=...) refused a folder "--out ...: ... (e.g. --out runs/NAME)", an option
    a Python caller never gave: the message names both, and says nothing was run."""
    from scenarios.run.runner import run_scene

    p = tmp_path / "p"
    p.mkdir()
    (p / "notes.txt").write_text("x\n")
    with pytest.raises(SceneError, match=r"^The output folder .*p \(--out; out_dir in Python\): .*nothing was run"):
        run_scene(short_pyrite_scene(tmp_path), out_dir=p, progress=False)
    assert sorted(x.name for x in p.iterdir()) == ["notes.txt"]
