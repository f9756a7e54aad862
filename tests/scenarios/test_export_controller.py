"""grindtwin export-controller: the reference scene's NMPC and EKF as C, compiled with gcc and
replayed over the scene's first hour against the Python controller's moves (1e-9 relative),
with no allocation in the steps; the out-dir rules (a foreign or non-empty folder refused,
nothing written)."""

import json
import os
import shutil
import stat
import subprocess
from pathlib import Path

import numpy as np
import pytest

from mpc import codegen
from scenarios.cli import main
from scenarios.errors import RunError
from scenarios.run import closed_loop, run_scene
from scenarios.scene import load_scene
from twin import file_sha256

REFERENCE = Path(__file__).parents[2] / "scenarios" / "reference_transition.toml"


class FirstHourDone(Exception):
    """Ends the recorded closed loop after its first hour."""


class Recording:
    """Wraps the closed loop's EKF or NMPC and logs its calls as gt_replay lines; the NMPC ends
    the loop after ``n_steps`` steps."""

    def __init__(self, inner, log, kind, n_steps=None):
        self._inner, self._log, self._kind, self._n = inner, log, kind, n_steps
        self.moves, self.statuses, self.passing_end = [], [], []
        self.estimates = 0

    def __getattr__(self, name):
        return getattr(self._inner, name)

    def make_step(self, *args, **kwargs):
        out = self._inner.make_step(*args, **kwargs)
        if self._kind == "E":
            y, u, d = args
            # the loop estimates once a sample from the warm-up on: the estimate's time, samples counted
            t_h, self.estimates = self.estimates * self._inner.dt_h, self.estimates + 1
            vals = [t_h, *y, *u, *np.asarray(d)[: self._inner.nd - 1]]
            self._log.append("E " + " ".join(repr(float(v)) for v in vals))
        else:
            if len(self.moves) == self._n:
                raise FirstHourDone()
            _, preview, u_prev = args[:3]
            blend = np.asarray(preview)[:-1, :].ravel(order="F")
            self._log.append("C " + " ".join(repr(float(v)) for v in [*u_prev, *blend]))
            self.moves.append(np.asarray(out.u_applied, float))
            self.statuses.append(out.status)
            self.passing_end.append(self._inner.last_info.get("passing_end", np.nan))
        return out


def _replay_first_hour(scene_path: Path, out: Path, monkeypatch):
    """Export the scene's controller to ``out``, build it, record the Python closed loop's first
    hour (on the same compiled C) and replay it through gt_replay; ``(python moves, C moves, C
    statuses, allocations in estimate/step, gt_replay's answers to a NaN and an out-of-bounds input,
    the Python controller's recording: its statuses and plans' passing fractions at the horizon end)``."""
    cc = codegen.find_compiler()
    if cc is None or shutil.which("make") is None:
        pytest.skip("no C compiler or make on this machine")
    assert main(["export-controller", str(scene_path), "--out", str(out)]) == 0
    build = subprocess.run(["make", "-j2", "-C", str(out), "CFLAGS=-O1", f"CC={cc}"], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-2000:]

    log, rec = [], {}
    real = closed_loop.nmpc_parts

    def recording(*a, **k):
        est, ctrl = real(*a, **k)
        rec["E"], rec["C"] = Recording(est, log, "E"), Recording(ctrl, log, "C", n_steps=21)
        return rec["E"], rec["C"]

    monkeypatch.setenv(codegen.MODE_ENV, "on")  # the Python controller on the same compiled C
    monkeypatch.setattr(closed_loop, "nmpc_parts", recording)
    with pytest.raises(RunError, match="FirstHourDone"):  # the first hour: 21 samples of 3 min
        run_scene(load_scene(scene_path), progress=False)
    py = np.array(rec["C"].moves)
    assert len(py) == 21 and sum(line[0] == "E" for line in log) >= 40  # warm-up + loop

    env = dict(os.environ, LD_PRELOAD=str(out / "gt_malloc_count.so"))
    run = subprocess.run([str(out / "gt_replay")], input="\n".join(log) + "\n", capture_output=True,
                         text=True, env=env, check=True)
    lines = run.stdout.split("\n")
    moves = np.array([[float(v) for v in ln.split()[2:4]] for ln in lines if ln.startswith("U ")])
    status = [int(ln.split()[1]) for ln in lines if ln.startswith("U ")]
    allocs = [int(ln.split()[1]) for ln in lines if ln.startswith("M ")]
    # a NaN input, and an applied input outside the bounds (as after a manual period): refused
    # with its own status (the C returned NaN moves), and planned from the projection
    c_line = next(ln for ln in log if ln.startswith("C "))
    blend = c_line.split()[3:]
    bad = [*log[:log.index(c_line)], " ".join(["C", "nan", "0.7", *blend]), " ".join(["C", "1000", "5.0", *blend])]
    odd = subprocess.run([str(out / "gt_replay")], input="\n".join(bad) + "\n", capture_output=True, text=True,
                         check=True).stdout.split("\n")
    return py, moves, status, allocs, [ln.split() for ln in odd if ln.startswith("U ")], rec["C"]


@pytest.mark.slow
def test_exported_controller_replays_the_reference_hour_like_python(tmp_path, monkeypatch):
    out = tmp_path / "ctl"
    py, moves, status, allocs, odd, python = _replay_first_hour(REFERENCE, out, monkeypatch)
    assert status == [0] * len(py) == _c_statuses(python.statuses)
    assert odd[0][1] == "4"  # GT_STEP_BAD_INPUT
    lo, hi = [20.0, 0.6], [45.0, 0.85]  # the reference scene's controller bounds
    # solved, planned from the projection onto the bounds (45 t/h, 0.85 of critical): 6,
    # GT_STEP_INPUT_PROJECTED (said before that plan's miss of the target at the horizon end)
    assert odd[1][1] == "6" and all(a <= float(v) <= b for a, v, b in zip(lo, odd[1][2:4], hi))
    assert len(odd[1]) == 8 and odd[1][7] == "0"  # the QP status, 0: solved
    unknown = subprocess.run([str(out / "gt_replay")], input="X 1 2\n", capture_output=True, text=True)
    assert unknown.returncode == 1 and "unknown line" in unknown.stderr  # it was skipped silently
    assert moves.shape == py.shape
    assert np.max(np.abs(moves / py - 1.0)) <= 1e-9
    assert np.ptp(py[:, 0]) > 1e-3  # the hour moves the feed: the comparison can fail
    assert allocs == [0]  # no heap in estimate and step (counted by the LD_PRELOAD shim)

    # a second export replaces the first and its build (all ours); a user's file stops a third
    # (a user's folder named like a scratch folder beside it is left alone)
    written = _export_files(out)
    assert (out / "gt_replay").exists()
    theirs = out.with_name(out.name + ".partial")
    theirs.mkdir()
    (theirs / "keep.txt").write_text("mine")
    before = sorted(p.name for p in out.parent.iterdir())
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(written)
    assert (theirs / "keep.txt").read_text() == "mine" and sorted(p.name for p in out.parent.iterdir()) == before
    (out / "mine.c").write_text("/* a user's file */")
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 2
    assert (out / "mine.c").exists()


def _c_statuses(python_statuses) -> list[int]:
    """The exported step's status for each of the Python controller's (all solved here):
    GT_STEP_TARGET_UNREACHABLE (5) for its target_unreachable, else GT_STEP_OK (0)."""
    assert all(st.startswith(("rti", "target_unreachable (rti")) for st in python_statuses), python_statuses
    return [5 if st.startswith("target_unreachable") else 0 for st in python_statuses]


@pytest.mark.slow
def test_the_exported_step_says_target_unreachable_when_python_does(tmp_path, monkeypatch):
    """The exported step said ok where the Python controller says target_unreachable (its plan's
    passing fraction at the horizon end misses 0.80 by more than unreachable_tol_frac). Over the
    reference hour the two now give the same status on every step. The tolerance is set between the
    misses of a first recording of the hour (the plans do not depend on it), inside their middle
    half, so that a quarter of the steps at least take each answer: the comparison can fail either
    way, whatever the model's misses are."""
    import dataclasses

    from mpc.nmpc import PASSING_TARGET

    with monkeypatch.context() as first_pass:
        *_, first = _replay_first_hour(REFERENCE, tmp_path / "first", first_pass)
    miss = np.sort(np.abs(np.array(first.passing_end) - PASSING_TARGET))
    quarter = len(miss) // 4
    j = quarter + int(np.argmax(np.diff(miss[quarter:len(miss) - quarter])))  # the widest gap there
    tol = 0.5 * (miss[j] + miss[j + 1])
    assert miss[j + 1] - miss[j] > 1e-9  # no plan at the threshold (rounding could not tip one)
    settings = closed_loop.nmpc_settings
    monkeypatch.setattr(closed_loop, "nmpc_settings",
                        lambda scene: dataclasses.replace(settings(scene), unreachable_tol_frac=tol))
    py, moves, status, allocs, _, python = _replay_first_hour(REFERENCE, tmp_path / "ctl", monkeypatch)
    assert python.passing_end == pytest.approx(first.passing_end, rel=1e-12)  # the same plans
    assert status == _c_statuses(python.statuses)
    assert quarter <= status.count(5) <= len(status) - quarter
    manifest = json.loads((tmp_path / "ctl" / "grindtwin_export.json").read_text())
    assert manifest["unreachable_tol_frac"] == tol and manifest["step_status"]["5"].startswith("target_unreachable: ")
    assert np.max(np.abs(moves / py - 1.0)) <= 1e-9 and allocs == [0]


def _export_files(out: Path) -> list[str]:
    return json.loads((out / "grindtwin_export.json").read_text())["files"]


def test_export_refuses_a_foreign_folder_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "theirs"
    out.mkdir()
    (out / "notes.txt").write_text("not ours")
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 2
    assert "not empty" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert not (tmp_path / "theirs.partial").exists()


def test_export_into_an_empty_folder_keeps_its_permissions(tmp_path, capsys):
    """An existing empty folder, which the README and --help allow ("DIR new, empty or a previous export"),
    was refused as "not empty and holds no grindtwin_export.json" (exit 2). Now it is filled, its permissions
    (0750 here) kept, and nothing is left beside it."""
    out = tmp_path / "ctl"
    out.mkdir()
    out.chmod(0o750)
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 0, capsys.readouterr().err
    assert (out / "grindtwin_export.json").is_file() and (out / "gt_controller.h").is_file()
    assert stat.S_IMODE(out.stat().st_mode) == 0o750
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ctl"]


def test_export_refuses_a_link_a_file_in_the_path_and_a_foreign_manifest(tmp_path, capsys):
    """A symbolic link to a folder (export failed after the build, leaving a hidden partial
    folder), a file where a parent folder should be (failed after the build), and a manifest that
    is not an export's (a traceback): each refused first, with exit 2, and nothing written."""
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    (tmp_path / "afile").write_text("x")
    (tmp_path / "odd").mkdir()
    (tmp_path / "odd" / "grindtwin_export.json").write_text("{not json")
    before = sorted(p.name for p in tmp_path.iterdir())
    for out, words in ((tmp_path / "link", "symbolic link"), (tmp_path / "afile" / "x", "is not a folder"),
                       (tmp_path / "odd", "not one this export wrote")):
        assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before and not any((tmp_path / "real").iterdir())


def test_export_refuses_a_controller_it_cannot_export(tmp_path, capsys):
    scene = tmp_path / "pi.toml"
    scene.write_text(REFERENCE.read_text().replace('kind = "nmpc"', 'kind = "pi"'))
    assert main(["export-controller", str(scene), "--out", str(tmp_path / "x")]) == 2
    assert "controller.kind" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_exported_controller_with_a_p80_bias_and_gain_replays_like_python(tmp_path, monkeypatch):
    """The disturbance model hardness+p80_bias and an estimator P80 gain (as the le Roux case's
    matched twin has): the C controller moves the passing weights to target - bias as Python
    does, every step (a bias of 0 would leave them, and the comparison could not fail)."""
    from mpc.estimator import Ekf

    scene = tmp_path / "biased.toml"
    text = REFERENCE.read_text()
    assert 'disturbance_model = "hardness"\n' in text
    scene.write_text(text.replace('disturbance_model = "hardness"\n', 'disturbance_model = "hardness+p80_bias"\n'))
    target = load_scene(scene).controller.target_p80_um
    init = Ekf.__init__

    def with_gain(self, *a, **k):  # the export and the recorded loop build their EKF through this
        init(self, *a, **{**k, "p80_gain": 1.4, "p80_reference_um": target})

    monkeypatch.setattr(Ekf, "__init__", with_gain)
    biases = []
    bias_of = Ekf.controller_p80_bias_um
    monkeypatch.setattr(Ekf, "controller_p80_bias_um", lambda self, t: biases.append(bias_of(self, t)) or biases[-1])
    py, moves, status, allocs, _, python = _replay_first_hour(scene, tmp_path / "ctl", monkeypatch)
    assert status == [0] * len(py) == _c_statuses(python.statuses) and allocs == [0]
    assert np.max(np.abs(moves / py - 1.0)) <= 1e-9
    assert min(abs(b) for b in biases[-len(py):]) > 1e-3  # the weights moved on every step


def test_an_export_prints_its_own_line_and_no_qpoases_banner(tmp_path, capfd):
    """Every export printed qpOASES's copyright notice (the controller it builds makes the
    interpreted condensed QP's qpOASES, which prints it when made, printLevel "none" or not)."""
    out = tmp_path / "ctl"
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 0
    printed = capfd.readouterr()
    assert "qpOASES" not in printed.out + printed.err
    n = len(_export_files(out))
    assert printed.out == f"{n} files in {out}: build with `make -C {out}`; API in gt_controller.h\n"


@pytest.mark.filterwarnings("always::mpc.OutsideModelsWarning")
def test_an_export_allowed_to_centrifuge_notes_it_and_exports(tmp_path, capsys):
    """A controller allowed 0.99 of critical was exported without a word, though the twin's
    models do not describe a centrifuging charge; the twin notes such a speed and goes on, so the
    export does too: warned (key, value, limit) and in the manifest's notes. The shipped bounds
    have none."""
    from twin import CENTRIFUGING_FRAC_CRITICAL

    text = REFERENCE.read_text()
    assert text.count("speed_max = 0.85\n") == 1
    scene = tmp_path / "fast.toml"
    scene.write_text(text.replace("speed_max = 0.85\n", "speed_max = 0.99\n"))
    assert main(["export-controller", str(scene), "--out", str(tmp_path / "fast")]) == 0
    err = capsys.readouterr().err
    assert "speed_max = 0.99: the controller may plan speeds" in err
    assert f"beyond {CENTRIFUGING_FRAC_CRITICAL} where the charge centrifuges" in err
    notes = json.loads((tmp_path / "fast" / "grindtwin_export.json").read_text())["notes"]
    assert len(notes) == 1 and f"grindtwin: warning: {notes[0]} (OutsideModelsWarning)" in err
    assert main(["export-controller", str(REFERENCE), "--out", str(tmp_path / "shipped")]) == 0
    assert "warning" not in capsys.readouterr().err
    assert json.loads((tmp_path / "shipped" / "grindtwin_export.json").read_text())["notes"] == []


def test_the_manifests_step_statuses_are_the_c_headers():
    """The export's manifest names gt_controller_step's statuses as gt_controller.h numbers them."""
    import re

    from mpc.export import STEP_STATUS

    header = (codegen.C_DIR / "gt_controller.h").read_text()
    enum = {int(v): name.lower() for name, v in re.findall(r"GT_STEP_(\w+) = (\d+)", header)}
    assert enum == {k: text.split(":")[0] for k, text in STEP_STATUS.items()} and 5 in enum


# --------------------------------------------------------------------------- export-controller --check
@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The reference scene exported (not built): the folder."""
    out = tmp_path_factory.mktemp("check") / "ctl"
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 0
    return out


def _listing(folder: Path) -> dict:
    return {p.name: p.stat().st_mtime_ns for p in folder.parent.iterdir()} | {
        p.name: p.stat().st_mtime_ns for p in folder.iterdir()}


def test_check_says_an_export_is_current_and_writes_nothing(exported, capsys):
    """Nothing compared an export with its scene: a user who re-calibrated or edited the scene kept running a
    controller built from the old ones with no word. `--check DIR` answers 0 for an export that is what
    the scene exports now, and writes nothing (neither in the folder nor a lock beside it)."""
    before = _listing(exported)
    assert main(["export-controller", str(REFERENCE), "--check", str(exported)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{exported}: current")
    assert all(line.startswith("  note: ") for line in out.splitlines()[1:])  # nothing stale among them
    assert _listing(exported) == before


def _edit_once(source, target, old: str, new: str) -> None:
    """``target`` written as ``source`` with its one ``old`` replaced by ``new`` (a test of an edit must edit)."""
    text = source.read_text()
    assert text.count(old) == 1
    target.write_text(text.replace(old, new))


def test_check_names_an_edited_target(exported, tmp_path, capsys):
    """The scene's target edited after the export: stale (exit 1), the scene item and the exported constant
    each named with the recorded and the current value, and how to export again."""
    scene = tmp_path / "edited.toml"
    _edit_once(REFERENCE, scene, "target_p80_um = 210.0\n", "target_p80_um = 200.0\n")
    assert main(["export-controller", str(scene), "--check", str(exported)]) == 1
    out = capsys.readouterr().out
    assert out.startswith(f"{exported}: stale")
    assert "  built_from.scene_as_loaded.controller.target_p80_um: recorded 210.0, now 200.0\n" in out
    assert "  gt_controller_config.h GT_TARGET_P80_UM: recorded 210.0, now 200.0\n" in out
    assert f"  built_from.scene.sha256: recorded {file_sha256(REFERENCE)}, now {file_sha256(scene)}\n" in out
    assert f"export again: grindtwin export-controller {scene} --out {exported}" in out


def test_check_names_a_recalibration(tmp_path, capsys):
    """The scene's calibration file made again (one fitted number other) after the export, the scene file
    unchanged: stale, the calibration's sha256 named, and the exported numbers it moved."""
    from twin.calibration import load_calibration
    from twin.calibration.files import write_calibration

    record = {**load_calibration("dem").record, "name": "mine"}
    write_calibration(tmp_path / "mine.json", record)
    scene = tmp_path / "scene.toml"
    scene.write_text('calibration = "mine.json"\n' + REFERENCE.read_text())
    out = tmp_path / "ctl"
    assert main(["export-controller", str(scene), "--out", str(out)]) == 0
    assert main(["export-controller", str(scene), "--check", str(out)]) == 0
    old = file_sha256(tmp_path / "mine.json")
    name, value = "cushioning_rate_coeff", 1.1 * record["coefficients"]["cushioning_rate_coeff"]
    again = json.loads(json.dumps(record))  # as a new fit would record it: the value, its fit's and its coefficient
    again["coefficients"][name] = again["fitted"][name]["value"] = again["fit"]["values"][name] = value
    write_calibration(tmp_path / "mine.json", again)
    capsys.readouterr()
    assert main(["export-controller", str(scene), "--check", str(out)]) == 1
    text = capsys.readouterr().out
    stale = [ln for ln in text.splitlines() if ln.startswith("  ") and not ln.startswith("  note: ")]
    assert f"  built_from.calibration.sha256: recorded {old}, now {file_sha256(tmp_path / 'mine.json')}" in stale
    assert not any(ln.startswith("  built_from.scene") for ln in stale)  # the scene file is the same
    assert any(ln.startswith("  gt_controller_config.h gt_") for ln in stale)


def test_check_names_a_constant_that_changed_with_the_same_inputs(exported, monkeypatch, capsys):
    """The export's numbers changed while every recorded input is the same (here grindtwin's passing target,
    as a code change would): the header regenerated in memory names the constant."""
    from mpc import export

    monkeypatch.setattr(export, "PASSING_TARGET", 0.75)
    assert main(["export-controller", str(REFERENCE), "--check", str(exported)]) == 1
    assert "  gt_controller_config.h GT_PASSING_TARGET: recorded 0.8, now 0.75\n" in capsys.readouterr().out


def test_check_refuses_a_folder_without_an_export_or_without_built_from(exported, tmp_path, capsys):
    """A folder with no export, a missing one, and an export whose manifest predates built_from: bad input
    (exit 2), said, with the command that exports; nothing written."""
    (tmp_path / "empty").mkdir()
    old = tmp_path / "old"
    shutil.copytree(exported, old)
    manifest = json.loads((old / "grindtwin_export.json").read_text())
    del manifest["built_from"]
    (old / "grindtwin_export.json").write_text(json.dumps(manifest, indent=2) + "\n")
    before = _listing(old)
    for folder, words in ((tmp_path / "empty", "holds no grindtwin_export.json"),
                          (tmp_path / "missing", "no such folder"),
                          (old, "does not record what the export was built from")):
        assert main(["export-controller", str(REFERENCE), "--check", str(folder)]) == 2
        err = capsys.readouterr().err
        assert words in err and f"grindtwin export-controller {REFERENCE} --out {folder}" in err, err
        assert "Traceback" not in err
    assert _listing(old) == before and not any((tmp_path / "empty").iterdir())


def test_check_names_a_file_edited_in_the_folder(exported, tmp_path, capsys):
    """A constant of gt_controller_config.h edited in the folder after the export: stale, the file named with
    its recorded and its present sha256, and the constant by name."""
    out = tmp_path / "ctl"
    shutil.copytree(exported, out)
    cfg = out / "gt_controller_config.h"
    _edit_once(cfg, cfg, "#define GT_TOL 1e-06\n", "#define GT_TOL 0.001\n")
    assert main(["export-controller", str(REFERENCE), "--check", str(out)]) == 1
    got = capsys.readouterr().out
    recorded = json.loads((out / "grindtwin_export.json").read_text())["sha256"]["gt_controller_config.h"]
    assert (f"  gt_controller_config.h in the folder (sha256; changed since the export): recorded {recorded}, "
            f"now {file_sha256(cfg)}\n") in got
    assert "  gt_controller_config.h (as edited in the folder) GT_TOL: recorded 0.001, now 1e-06\n" in got
