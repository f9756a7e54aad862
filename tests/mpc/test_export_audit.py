"""The exported C controller as a user builds and calls it (gcc, make), against the Python
controller and estimator it was exported from: what it refuses (a preview that is not a blend, a
non-finite input to the estimate, NULL, a replay line of another length), what its statuses mean
in the header and the manifest, the Makefile (an edited header rebuilds, `make clean` leaves a
user's objects), and the out-dir rules (the current folder, an edited export, a user's folder of
a listed name, an unsupported solver refused before any work, no folder left by a failed export)."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from mpc import codegen
from mpc.errors import MpcInputError
from scenarios.cli import main
from tests.conftest import strict_json
from tests.mpc.conftest import c_tools
from scenarios.run import closed_loop

REFERENCE = Path(__file__).parents[2] / "scenarios" / "reference_transition.toml"


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The reference scene exported and built (make, -O1), with the Python EKF and NMPC the export
    was made from: ``(folder, estimator, controller, config)``."""
    cc = c_tools()
    out = tmp_path_factory.mktemp("export") / "ctl"
    parts = {}
    real = closed_loop.nmpc_parts

    def keep(*a, **k):
        parts["est"], parts["ctrl"] = real(*a, **k)
        return parts["est"], parts["ctrl"]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(closed_loop, "nmpc_parts", keep)
        assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 0
    build = subprocess.run(["make", "-j2", "-C", str(out), "CFLAGS=-O1", f"CC={cc}"], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-2000:]
    config = {k: float(v) for k, v in re.findall(r"#define (GT_\w+) ([-0-9.e]+)\n",
                                                 (out / "gt_controller_config.h").read_text())}
    return out, parts["est"], parts["ctrl"], config


def _replay(out: Path, lines) -> subprocess.CompletedProcess:
    return subprocess.run([str(out / "gt_replay")], input="\n".join(lines) + "\n", capture_output=True, text=True)


def _c_line(u, preview) -> str:
    return "C " + " ".join(repr(float(v)) for v in [*u, *np.asarray(preview, float).ravel(order="F")])


def test_a_preview_that_is_not_a_blend_is_refused_as_python_refuses_it(built):
    """A preview of [5, -4] (sum 1), of fractions summing to 0.5, or with a negative fraction was
    planned on and answered with moves (status ok, target_unreachable or shifted_plan); the Python
    controller raises on each. Now the C step refuses exactly the previews Python refuses
    (GT_STEP_BAD_INPUT, no move); fractions within BLEND_SUM_TOL of 1 pass in both."""
    out, _, ctrl, cfg = built
    n, nb = int(cfg["GT_N"]), int(cfg["GT_NB"])
    assert cfg["GT_PREVIEW"] == 1 and nb == 2
    h = ctrl.model.d_vector([1.0, 0.0])[-1]
    good = np.tile([[1.0], [0.0]], (1, n))
    cases = {"good": good, "five_minus_four": np.tile([[5.0], [-4.0]], (1, n)),
             "half": np.tile([[0.5], [0.0]], (1, n)), "late_negative": good.copy(),
             "rounded": np.tile([[0.6004], [0.4]], (1, n)), "late_sum_off": good.copy()}
    cases["late_negative"][:, -1] = [1.1, -0.1]
    cases["late_sum_off"][:, 3] = [0.7, 0.4]
    python_refuses = {}
    for name, blend in cases.items():
        try:
            ctrl._d_traj(np.vstack([blend, np.full((1, n), h)]))
            python_refuses[name] = False
        except MpcInputError:
            python_refuses[name] = True
    assert sum(python_refuses.values()) == 4  # both answers are taken: the comparison can fail
    run = _replay(out, [line for i, blend in enumerate(cases.values())  # an estimate before each step
                        for line in (f"E {i * cfg['GT_DT_H']!r} nan nan nan 27 0.7 1 0", _c_line([27.0, 0.70], blend))])
    assert run.returncode == 0, run.stderr
    rows = [ln.split() for ln in run.stdout.splitlines() if ln.startswith("U ")]
    for (name, refused), row in zip(python_refuses.items(), rows):
        assert (row[1] == "4") == refused, (name, row)
        assert (row[2] == "nan") == refused, (name, row)  # no move for a refused preview


def test_a_rounded_blend_is_rescaled_to_sum_to_one_in_c_as_in_python(built, tmp_path):
    """The C estimate and step took a blend within GT_BLEND_SUM_TOL of 1 as it was ([0.6004, 0.4]: 0.04 % more
    ore in the model than fed); Python rescales it to sum to 1 (the twin's normalised_blend), and so does C now:
    the estimate and the plan of the rounded blend are those of the rescaled one."""
    out, _, _, cfg = built
    assert int(cfg["GT_NB"]) == 2
    rows, z = _driver_rows(c_tools(), tmp_path, out, [out / "libgtcontroller.a"], ROUNDED_DRIVER)
    assert rows["rounded"][0] == rows["rescaled"][0] == "0"
    np.testing.assert_allclose(z["rounded"], z["rescaled"], rtol=1e-12, atol=1e-12 * np.abs(z["rescaled"]).max())
    assert rows["step_rounded"][0] in ("0", "5") and rows["step_rounded"][0] == rows["step_rescaled"][0]
    assert float(rows["step_rounded"][1]) == pytest.approx(float(rows["step_rescaled"][1]), rel=1e-12)


#: Estimates and a step of one blend given rounded ([0.6004, 0.4]) and rescaled to sum to 1, on new controllers.
ROUNDED_DRIVER = r"""
#include <math.h>
#include <stdio.h>
#include "gt_controller.h"
#include "gt_controller_config.h"

static void run(const char *tag, const char *step_tag, const double *blend) {
    gt_controller *c = gt_controller_new();
    double y[3] = {210.0, NAN, NAN}, u[2] = {27.0, 0.7}, preview[GT_NB * GT_N], move[2];
    const double *z;
    int i, st = gt_controller_estimate(c, 0.0, y, u, blend);
    z = gt_controller_estimate_state(c);
    printf("%s %d", tag, st);
    for (i = 0; i < GT_NZ; ++i) printf(" %.17g", z[i]);
    printf("\n");
    for (i = 0; i < GT_N; ++i) { preview[i * GT_NB] = blend[0]; preview[i * GT_NB + 1] = blend[1]; }
    st = gt_controller_step(c, preview, u, move);
    printf("%s %d %.17g\n", step_tag, st, gt_controller_passing_end(c));
    gt_controller_free(c);
}

int main(void) {
    double rounded[2] = {0.6004, 0.4}, rescaled[2] = {0.6004 / 1.0004, 0.4 / 1.0004};
    run("rounded", "step_rounded", rounded);
    run("rescaled", "step_rescaled", rescaled);
    return 0;
}
"""


DRIVER = r"""
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "gt_controller.h"
#include "gt_controller_config.h"

static void show(const char *tag, int st, gt_controller *c) {
    const double *z = gt_controller_estimate_state(c);
    int i;
    printf("%s %d", tag, st);
    for (i = 0; i < GT_NZ; ++i) printf(" %.17g", z[i]);
    printf("\n");
}

int main(void) {
    gt_controller *c = gt_controller_new();
    double y[3] = {210.0, NAN, NAN}, u[2] = {27.0, 0.7}, blend[GT_NB] = {1.0, 0.0};
    double bad_u[2] = {NAN, 0.7}, inf_blend[GT_NB] = {INFINITY, 0.0}, huge_u[2] = {1e300, 0.7};
    double neg_u[2] = {-100.0, 0.7}, fast_u[2] = {27.0, 5.0}, no_blend[GT_NB] = {5.0, -4.0};
    double preview[GT_NB * GT_N], move[2] = {-1.0, -1.0};
    int i;
    for (i = 0; i < GT_N; ++i) { preview[i * GT_NB] = 1.0; preview[i * GT_NB + 1] = 0.0; }
    show("start", 0, c);
    show("nan_u", gt_controller_estimate(c, 0.0, y, bad_u, blend), c);
    show("inf_blend", gt_controller_estimate(c, 0.0, y, u, inf_blend), c);
    show("null_y", gt_controller_estimate(c, 0.0, NULL, u, blend), c);
    show("neg_feed", gt_controller_estimate(c, 0.0, y, neg_u, blend), c);
    show("speed_5", gt_controller_estimate(c, 0.0, y, fast_u, blend), c);
    show("no_blend", gt_controller_estimate(c, 0.0, y, u, no_blend), c);
    show("ok", gt_controller_estimate(c, 0.0, y, u, blend), c);
    show("huge_u", gt_controller_estimate(c, GT_DT_H, y, huge_u, blend), c);
    printf("null_c_estimate %d\n", gt_controller_estimate(NULL, 0.0, y, u, blend));
    printf("null_c_step %d\n", gt_controller_step(NULL, preview, u, move));
    printf("null_preview %d %g\n", gt_controller_step(c, NULL, u, move), move[0]);
    printf("null_u %d\n", gt_controller_step(c, preview, u, NULL));
    printf("null_accessors %d %d %d %d\n", gt_controller_plan(NULL) == NULL,
           gt_controller_estimate_state(NULL) == NULL, gt_controller_qp_iterations(NULL),
           isnan(gt_controller_passing_end(NULL)));
    gt_controller_free(c);
    return 0;
}
"""


def _driver_rows(cc: str, folder: Path, include: Path, objects, source: str | None = None) -> tuple[dict, dict]:
    """``source`` (default DRIVER) built in ``folder`` against ``include``'s headers and ``objects``: its rows by
    tag, and the estimates they show."""
    folder.mkdir(exist_ok=True)
    (folder / "driver.c").write_text(DRIVER if source is None else source)
    exe = folder / "driver"
    build = subprocess.run([cc, "-O1", f"-I{include}", str(folder / "driver.c"), *map(str, objects), "-lm", "-o",
                            str(exe)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-2000:]
    rows = {ln.split()[0]: ln.split()[1:] for ln in subprocess.run([str(exe)], capture_output=True, text=True,
                                                                   check=True).stdout.splitlines()}
    return rows, {k: np.array(v[1:], float) for k, v in rows.items() if len(v) > 2}


def _library_with(cc: str, folder: Path, out: Path, macro: str, value: str) -> list[Path]:
    """The objects of the export in ``out`` with the scalar ``macro`` of gt_controller_config.h set to
    ``value`` in the header and in gt_exported.c alike (the library refuses a header that differs)."""
    folder.mkdir(exist_ok=True)
    for name in ("gt_controller.h", "gt_controller_config.h", "gt_controller.c"):
        shutil.copyfile(out / name, folder / name)
    cfg = folder / "gt_controller_config.h"
    text, n = re.subn(rf"#define {macro} \S+\n", f"#define {macro} {value}\n", cfg.read_text())
    assert n == 1, macro
    cfg.write_text(text)
    exported = (out / "gt_exported.c").read_text()
    listed = re.search(r"\{(.*)\}", exported).group(1).split(", ")
    scalars = re.search(r"#define GT_CONFIG_SCALARS \{(.*)\}", text).group(1).split(", ")
    listed[scalars.index(macro)] = value
    (folder / "gt_exported.c").write_text(exported.replace(re.search(r"\{(.*)\}", exported).group(1),
                                                           ", ".join(listed)))
    objs = []
    for name in ("gt_controller", "gt_exported"):
        objs.append(folder / f"{name}.o")
        run = subprocess.run([cc, "-O1", "-c", f"-I{folder}", f"-I{out}", str(folder / f"{name}.c"), "-o",
                              str(objs[-1])], capture_output=True, text=True)
        assert run.returncode == 0, run.stderr[-2000:]
    return [*objs, *(out / f"{name}.o" for name in ("gt_rti_data", "gt_ekf_data", "gt_qp", "gt_cond", "gt_rti"))]


def test_the_estimate_refuses_a_non_finite_input_and_resets_a_non_finite_estimate(built, tmp_path):
    """gt_controller_estimate returned nothing and took a NaN feed rate: the update's clipping
    turned the NaN masses into an empty mill, and the next step answered with moves and status
    ok. Now it returns a status: a NaN or infinite input or blend (the Python EKF raises) or a NULL
    argument is GT_ESTIMATE_BAD_INPUT with the estimate untouched, as is a feed of 1e300 (above the feed's
    physical limit); an update that leaves a non-finite covariance (that feed, on a library built without the
    limit) is GT_ESTIMATE_RESET, back to the exported initial
    estimate, where the scene's closed loop resets its EKF. The step and the accessors answer NULL
    with a status (or NULL, NaN, -1), not a crash."""
    out, est, _, _ = built
    cc = c_tools()
    rows, z = _driver_rows(cc, tmp_path, out, [out / "libgtcontroller.a"])
    np.testing.assert_array_equal(z["start"], est.z)  # the exported initial estimate is the EKF's
    # a feed of -100 t/h, a speed of 5 x critical and a blend [5, -4] were estimated with OK: an empty mill,
    # a hardness at its bound; now refused in C and in Python alike
    for name in ("nan_u", "inf_blend", "null_y", "neg_feed", "speed_5", "no_blend"):
        assert rows[name][0] == "1" and np.array_equal(z[name], z["start"]), name  # GT_ESTIMATE_BAD_INPUT
    for u, blend in (([np.nan, 0.7], [1.0, 0.0]), ([27.0, 0.7], [np.inf, 0.0]), ([-100.0, 0.7], [1.0, 0.0]),
                     ([27.0, 5.0], [1.0, 0.0]), ([27.0, 0.7], [5.0, -4.0])):
        with pytest.raises(MpcInputError):
            est.make_step([210.0, np.nan, np.nan], u, blend)
    # the Python EKF from the same state: the same update, then the reset the closed loop makes
    zn, _, _ = est.step_function(est.z, est.P, [27.0, 0.7], [1.0, 0.0], [210.0, 0, 0], [1.0, 0, 0])
    assert rows["ok"][0] == "0"
    np.testing.assert_allclose(z["ok"], np.asarray(zn, float).ravel(), rtol=1e-12, atol=1e-12 * np.abs(z["ok"]).max())
    assert not np.allclose(z["ok"], z["start"])
    counted = closed_loop.CountingEstimator(est)
    counted.ekf.z, counted.ekf.P = z["ok"].copy(), np.asarray(est.step_function(
        est.z, est.P, [27.0, 0.7], [1.0, 0.0], [210.0, 0, 0], [1.0, 0, 0])[1], float)
    counted.make_step([210.0, np.nan, np.nan], [1e300, 0.7], [1.0, 0.0])
    assert counted.resets == [1]  # Python resets here too
    # a feed of 1e300 is above the physical limit (GT_ESTIMATE_BAD_INPUT); the reset on a library without one
    assert rows["huge_u"][0] == "1" and np.array_equal(z["huge_u"], z["ok"])
    wide, wide_z = _driver_rows(cc, tmp_path / "wide", out, _library_with(cc, tmp_path / "wide", out,
                                                                           "GT_FEED_MAX_TPH", "INFINITY"))
    assert wide["huge_u"][0] == "2" and np.array_equal(wide_z["huge_u"], z["start"])  # GT_ESTIMATE_RESET
    est.reset()
    assert rows["null_c_estimate"] == ["1"] and rows["null_c_step"] == ["4"] and rows["null_u"] == ["4"]
    assert rows["null_preview"] == ["4", "-1"]  # u left as it was
    assert rows["null_accessors"] == ["1", "1", "-1", "1"]


def test_replay_refuses_a_line_of_another_length(built):
    """gt_replay read the numbers it needed and ignored the rest: a preview of another horizon (a log
    of another export) was replayed in part without a word. A line longer or shorter than its kind
    is now an error naming the line and the count; the exact length runs."""
    out, _, _, cfg = built
    n_c, n_e = 2 + int(cfg["GT_NB"] * cfg["GT_N"]), 6 + int(cfg["GT_NB"])
    c_ok = "C 27 0.7 " + " ".join(["1 0"] * int(cfg["GT_N"]))
    e_ok = "E 0 210 nan nan 27 0.7 1 0"
    assert len(c_ok.split()) == 1 + n_c and len(e_ok.split()) == 1 + n_e
    assert _replay(out, [e_ok, c_ok]).returncode == 0
    for lines, words in (([c_ok + " 1 0"], f"bad C line 1 (C and {n_c} numbers)"),
                         ([e_ok, e_ok + " 0.5"], f"bad E line 2 (E and {n_e} numbers)"),
                         ([c_ok.rsplit(" ", 2)[0]], "bad C line 1")):
        run = _replay(out, lines)
        assert run.returncode == 1 and words in run.stderr, (lines, run.stderr)


def test_the_status_tables_of_the_header_and_the_manifest_agree(built):
    """The manifest names gt_controller_estimate's statuses (new) and gt_controller_step's as the
    header numbers them; the exported header is the shipped one."""
    from mpc.export import ESTIMATE_STATUS, STEP_STATUS

    out = built[0]
    header = (out / "gt_controller.h").read_text()
    assert header == (codegen.C_DIR / "gt_controller.h").read_text()
    manifest = json.loads((out / "grindtwin_export.json").read_text())
    for prefix, table, key in (("GT_ESTIMATE_", ESTIMATE_STATUS, "estimate_status"), ("GT_STEP_", STEP_STATUS,
                                                                                        "step_status")):
        enum = {int(v): name.lower() for name, v in re.findall(prefix + r"(\w+) = (\d+)", header)}
        assert enum == {k: text.split(":")[0] for k, text in table.items()} and len(enum) >= 3
        assert manifest[key] == {str(k): v for k, v in table.items()}


def test_the_manifest_says_what_the_export_was_built_from(built):
    """The manifest's only trace of its origin was ``source``, the scene's path as typed (relative to
    wherever the export ran): an export of an edited scene, another calibration or another controller
    model could not be told from this one. Now ``built_from`` records the scene file (resolved, sha256)
    and the scene as loaded, the calibration (name, file, sha256), the controller model's effects and size
    grid, and the versions, as a run's summary.json does."""
    from scenarios.scene import load_scene
    from twin import file_sha256

    out, _, ctrl, _ = built
    made = json.loads((out / "grindtwin_export.json").read_text())["built_from"]
    assert made["scene"] == {"path": str(REFERENCE.resolve()), "sha256": file_sha256(REFERENCE)}
    scene = load_scene(REFERENCE)
    assert made["scene_as_loaded"]["controller"]["target_p80_um"] == scene.controller.target_p80_um
    cal = made["calibration"]
    cal_path = Path(cal["path"]) if Path(cal["path"]).is_absolute() else REFERENCE.parents[1] / cal["path"]
    assert cal["sha256"] == file_sha256(cal_path)
    assert sorted(made["controller_effects"]) == sorted(ctrl.model.effect_names) == sorted(scene.effects)
    assert made["controller_size_classes"] == {"top_um": 6700.0, "ratio": 2.5, "count": 7}  # the scene's [mill]
    assert made["versions"]["grindtwin"] and made["versions"]["casadi"]


def test_an_edited_config_header_is_rebuilt_and_make_clean_leaves_a_users_objects(built, tmp_path):
    """The Makefile's objects did not depend on the headers: a user who edited gt_controller_config.h
    and ran make got the old objects, silently. Now every object depends on every header (and the
    rebuilt library refuses the edit: test_export_abi); and `make clean` removed every *.o, a user's
    own too: now only what it built."""
    out = tmp_path / "ctl"
    shutil.copytree(built[0], out, copy_function=shutil.copy2)
    assert subprocess.run(["make", "-q", "-C", str(out), "CFLAGS=-O1"]).returncode == 0  # up to date
    config = out / "gt_controller_config.h"
    later = time.time() + 5
    os.utime(config, (later, later))
    plan = subprocess.run(["make", "-n", "-C", str(out), "CFLAGS=-O1"], capture_output=True, text=True).stdout
    rebuilt = set(re.findall(r"-c (\w+)\.c", plan))
    assert rebuilt == {"gt_rti_data", "gt_ekf_data", "gt_exported", "gt_qp", "gt_cond", "gt_rti", "gt_controller",
                       "gt_replay"}
    (out / "dcs_task.o").write_text("a user's object")
    assert subprocess.run(["make", "-s", "-C", str(out), "clean"]).returncode == 0
    from mpc.export import BUILD_PRODUCTS
    assert not any((out / name).exists() for name in BUILD_PRODUCTS)
    assert (out / "dcs_task.o").read_text() == "a user's object"


def test_a_build_that_drops_the_nan_checks_is_refused(built, tmp_path):
    """Built with CFLAGS=-Ofast (or -ffast-math, -ffinite-math-only: the compiler may take no value for NaN),
    the library estimated with a NaN feed (status implausible, not bad_input) and stepped on a NaN applied
    feed with status OK and both inputs at their upper bounds (45 t/h, 0.85). Now the Makefile refuses those
    flags before it builds anything (no object of theirs left for a later `make`), and gt_qp.h refuses them
    in any other build of gt_controller.c or gt_qp.c (#error)."""
    out = built[0]
    cc = c_tools()
    src = tmp_path / "src"
    src.mkdir()
    for name in json.loads((out / "grindtwin_export.json").read_text())["files"]:
        shutil.copyfile(out / name, src / name)
    for flags in ("-Ofast", "-O2 -ffast-math", "-O1 -ffinite-math-only"):
        run = subprocess.run(["make", "-C", str(src), f"CFLAGS={flags}", f"CC={cc}"], capture_output=True, text=True)
        assert run.returncode != 0 and "NaN" in run.stderr, flags
        assert not list(src.glob("*.o")), flags
        for name in ("gt_controller.c", "gt_qp.c"):
            run = subprocess.run([cc, *flags.split(), f"-I{src}", "-c", str(src / name), "-o", str(tmp_path / "x.o")],
                                 capture_output=True, text=True)
            assert run.returncode != 0 and "NaN" in run.stderr, (flags, name)


def test_a_re_export_keeps_a_users_edits_and_folders(tmp_path, capsys):
    """A re-export replaced the previous one whole: a tuned gt_controller_config.h was lost, and a
    folder of the user's under a name the export lists (gt_replay) was deleted with its files. Both
    now refuse the export (exit 2), naming the file, and leave everything as it was (an unchanged
    previous export is still replaced: tests/scenarios/test_export_controller.py)."""
    out = tmp_path / "ctl"
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 0
    config = out / "gt_controller_config.h"
    tuned = config.read_text().replace("#define GT_TOL", "/* tuned */\n#define GT_TOL")
    config.write_text(tuned)
    capsys.readouterr()
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 2
    assert "gt_controller_config.h changed since the export" in capsys.readouterr().err
    assert config.read_text() == tuned
    config.unlink()  # the user moved it away: a listed file missing is not theirs to lose
    (out / "gt_replay").mkdir()
    (out / "gt_replay" / "notes.txt").write_text("mine")
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 2
    assert "gt_replay" in capsys.readouterr().err
    assert (out / "gt_replay" / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ctl"]  # no partial or moved-aside folder


def test_the_current_folder_is_refused(tmp_path, monkeypatch, capsys):
    """`--out .` in an empty folder built the models, emptied the folder and failed to rename it
    (exit 1, "[Errno 22] Invalid argument: '.'"). It is now refused first (exit 2), as a run's
    --out is, and nothing is written beside it."""
    here = tmp_path / "here"
    here.mkdir()
    monkeypatch.chdir(here)
    for out in (".", str(tmp_path)):
        assert main(["export-controller", str(REFERENCE), "--out", out]) == 2
        assert "current folder or one of its parents" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["here"] and not any(here.iterdir())


@pytest.mark.parametrize("solver, qpsol, key", [("ipopt", None, "controller.solver = 'ipopt'"),
                                               ("rti", "hpipm", "controller.qpsol = 'hpipm'")])
def test_a_solver_it_does_not_export_is_refused_before_any_work(tmp_path, monkeypatch, capsys, solver, qpsol, key):
    """A scene with the default solver (IPOPT) built its models and its IPOPT controller (11 s)
    before the refusal, which named neither the key nor the file's setting. Now the scene's key
    and value are named and nothing is built."""
    import scenarios.run.models as models

    text = REFERENCE.read_text().replace('solver = "rti"', f'solver = "{solver}"', 1)
    text = text.replace('qpsol = "condensed"', f'qpsol = "{qpsol}"' if qpsol else "", 1)
    scene = tmp_path / "s.toml"
    scene.write_text(text)

    def no_build(*a, **k):
        raise AssertionError("the models were built before the refusal")

    monkeypatch.setattr(models, "build_models", no_build)
    assert main(["export-controller", str(scene), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert key in err and "controller.solver = 'rti' and controller.qpsol = 'condensed'" in err
    assert not (tmp_path / "x").exists()


def test_a_failed_export_leaves_no_folder_it_made(tmp_path, monkeypatch, capsys):
    """An export that fails while writing (here the code generation) removed its partial folder but
    left the parents of --out it had made (a/b for --out a/b/c). Now they go too."""
    import mpc.export as export

    def fail(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(export, "_generate", fail)
    assert main(["export-controller", str(REFERENCE), "--out", str(tmp_path / "a" / "b" / "c")]) == 1
    assert "No space left" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_an_estimator_with_a_change_detector_is_refused():
    """mpc.export_controller wrote the plain EKF for an Ekf with a ChangeDetector, without a word: after a P80
    step the C's hardness was the plain EKF's (1.2088), not the detector's (1.1991)."""
    from types import SimpleNamespace

    from mpc import ChangeDetector, MpcInputError
    from mpc.export import _check

    model = object()
    controller = SimpleNamespace(settings=SimpleNamespace(solver="rti", qpsol="condensed"), model=model)
    with pytest.raises(MpcInputError, match="not its change detector"):
        _check(controller, SimpleNamespace(model=model, change_detector=ChangeDetector()))


def _moves(out: Path, lines) -> tuple[list[list[str]], str]:
    """gt_replay's U rows (status, feed, speed) and its stderr for ``lines``."""
    run = _replay(out, lines)
    assert run.returncode == 0, run.stderr
    return [ln.split()[1:4] for ln in run.stdout.splitlines() if ln.startswith("U ")], run.stderr


def test_a_measurement_outside_its_physical_range_is_not_used_and_said(built):
    """The exported estimate took any finite measurement: a P80 in mm (0.21), a dead analyser's -5, a load
    in % (35) were estimated with status ok, and the P80 in mm drove the feed up at its rate limit each
    sample, as it once did in grindtwin serve, which judges its tags by their physical ranges. Now the
    export carries those ranges (gt_y_lo, gt_y_hi: the scene's, as serve's) and the estimate takes a value
    outside as absent, with GT_ESTIMATE_IMPLAUSIBLE (3): the next step's moves are those of no measurement."""
    from scenarios.scene import load_scene
    from scenarios.scene.physical import physical_limits

    out, scene = built[0], load_scene(REFERENCE)
    top, power_max = physical_limits("p80_um", scene)[1], physical_limits("power_kw", scene)[1]
    step = _c_line([23.64, 0.7], np.tile([[1.0], [0.0]], 10))  # near the start: no rate limit in the first move

    def after(y):
        return _moves(out, ["E " + " ".join(repr(float(v)) for v in [0.0, *y, 23.64, 0.7, 1.0, 0.0]), step])

    absent, err = after([np.nan, np.nan, np.nan])
    assert absent[0][0] in ("0", "5") and "status" not in err
    measured, err = after([210.0, np.nan, np.nan])
    assert measured != absent and "status" not in err  # a plausible P80 moves the plan: the test can fail
    power_w = 1000.0 * power_max / 2  # the most the mill draws, in W
    for y in ([0.21, np.nan, np.nan], [-5.0, np.nan, np.nan], [top, np.nan, np.nan], [np.nan, power_w, np.nan],
              [np.nan, np.nan, 35.0], [np.nan, -1.0, -0.1]):
        moves, err = after(y)
        assert moves == absent and "E line 1: gt_controller_estimate status 3" in err, (y, moves, err)
    ranges = json.loads((out / "grindtwin_export.json").read_text())["measurement_range"]
    assert ranges == {"p80_um": [1.0, float(np.nextafter(top, 0.0))], "power_kw": [0.0, power_max],  # top excluded
                      "load_frac": [0.0, physical_limits("load_frac", scene)[1]]}


def test_a_step_from_outside_the_input_bounds_says_so(built):
    """A step whose applied input lay outside the bounds (a feed in kg/s: 6.6 for 23.6 t/h) was planned from
    its projection and returned ok (or target_unreachable): the caller could not tell, while the Python
    controller's status says input_outside_bounds. Now GT_STEP_INPUT_PROJECTED (6); inside the bounds
    nothing changes."""
    out, est, ctrl, _ = built
    preview = np.tile([[1.0], [0.0]], 10)
    est.reset()
    d = np.vstack([preview, np.full((1, 10), est.hardness_est)])
    for u, c_status in (([23.6 / 3.6, 0.7], ("6",)), ([23.6, 70.0], ("6",)), ([23.6, 0.7], ("0", "5"))):
        ctrl.reset()
        moves, _ = _moves(out, ["E 0 nan nan nan 23.6 0.7 1 0", _c_line(u, preview)])
        assert moves[0][0] in c_status, (u, moves)
        outside = str(ctrl.make_step(est.x_est, d, u).status).startswith("input_outside_bounds")
        assert outside == (c_status == ("6",)), u


def test_export_refuses_limits_it_cannot_check(built, tmp_path):
    """``measurement_range`` is (low, high) of the 3 measurements, low <= high, no NaN, and ``feed_max_tph`` a
    number > 0: anything else is refused naming the parameter, nothing written."""
    from mpc import export_controller

    _, est, ctrl, _ = built
    for bad in ([[1.0, 0.0, 0.0]], [[1.0, 0.0, 0.0], [0.5, 10.0, 5.0]], [[np.nan] * 3, [1.0] * 3], "wide"):
        with pytest.raises(MpcInputError, match="'measurement_range' parameter of export_controller"):
            export_controller(ctrl, est, [23.6, 0.7], tmp_path / "ctl", measurement_range=bad, feed_max_tph=310.0)
    for bad in (0.0, -1.0, float("nan"), "310"):
        with pytest.raises(MpcInputError, match="'feed_max_tph' parameter of export_controller"):
            export_controller(ctrl, est, [23.6, 0.7], tmp_path / "ctl", measurement_range=[[0.0] * 3, [1.0] * 3],
                              feed_max_tph=bad)
    assert not (tmp_path / "ctl").exists()


def test_export_manifest_is_strict_json_without_limits(built, tmp_path):
    """``(-inf, inf)`` and ``feed_max_tph=inf`` check nothing: the manifest held the tokens -Infinity and
    Infinity, no JSON (many readers refuse the file). They are the text "-inf" / "inf", as in summary.json."""
    from mpc import check_export, export_controller

    _, est, ctrl, _ = built
    limits = {"measurement_range": [[-np.inf] * 3, [np.inf] * 3], "feed_max_tph": math.inf,
              "built_from": {"scene": "limits"}}
    export_controller(ctrl, est, [23.6, 0.7], tmp_path / "ctl", **limits)
    manifest = strict_json((tmp_path / "ctl" / "grindtwin_export.json").read_text(encoding="utf-8"))
    assert manifest["feed_max_tph"] == "inf"
    assert manifest["measurement_range"] == {name: ["-inf", "inf"] for name in ("p80_um", "power_kw", "load_frac")}
    # the check reads the export's "inf" as the writer writes it, not as stale against a float inf
    assert [d for d in check_export(tmp_path / "ctl", ctrl, est, [23.6, 0.7], **limits) if d.stale] == []


CXX_DRIVER = r"""
#include <cmath>
#include <cstdio>
#include "gt_controller.h"
int main() {
    int abi = -1;
    gt_controller *c = GT_CONTROLLER_NEW(&abi);
    double y[3] = {210.0, NAN, NAN}, u_applied[2] = {23.64, 0.7}, blend[GT_NB] = {1.0}, u[2];
    double preview[GT_PREVIEW_LEN] = {0};
    for (int k = 0; k < GT_N; ++k) preview[k * GT_NB] = 1.0;
    int es = gt_controller_estimate(c, 0.0, y, u_applied, blend);
    int st = gt_controller_step(c, preview, u_applied, u);
    std::printf("%d %d %d %.17g %.17g\n", abi, es, st, u[0], u[1]);
    gt_controller_free(c);
    return 0;
}
"""


def test_a_cxx_caller_links_the_library(built, tmp_path):
    """gt_controller.h declared its functions without extern "C": a C++ caller (a DCS's C++ block)
    compiled against it looked for mangled names and did not link. Now it does, and its step is the C
    harness's."""
    cxx = shutil.which("g++") or shutil.which("c++")
    if cxx is None:
        pytest.skip("no C++ compiler on this machine")
    out = built[0]
    (tmp_path / "driver.cpp").write_text(CXX_DRIVER)
    build = subprocess.run([cxx, "-O1", f"-I{out}", str(tmp_path / "driver.cpp"), str(out / "libgtcontroller.a"),
                            "-o", str(tmp_path / "driver")], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-2000:]
    abi, es, st, *u = subprocess.run([str(tmp_path / "driver")], capture_output=True, text=True,
                                     check=True).stdout.split()
    moves, _ = _moves(out, ["E 0 210 nan nan 23.64 0.7 1 0", "C 23.64 0.7 " + " ".join(["1 0"] * 10)])
    assert (abi, es) == ("0", "0") and [st, *u] == moves[0]


def test_the_estimate_refuses_a_feed_beyond_its_physical_limit(built):
    """The exported estimate took any feed >= 0: a feed in t/d (567 for 23.6 t/h) or kg/h was estimated with
    status ok. Now a feed above the scene's physical limit (10 x the mill's nominal, GT_FEED_MAX_TPH, the
    range grindtwin serve reads the weightometer in) is GT_ESTIMATE_BAD_INPUT; one at the limit is used."""
    from scenarios.scene import load_scene
    from scenarios.scene.physical import physical_limits

    out, cfg = built[0], built[3]
    limit = physical_limits("feed_tph", load_scene(REFERENCE))[1]
    lines = [f"E {i * cfg['GT_DT_H']!r} 210 nan nan {feed!r} 0.7 1 0"
             for i, feed in enumerate((45.0, limit, 23.64 * 24, 23640.0))]
    run = _replay(out, lines)
    assert "E line 3: gt_controller_estimate status 1" in run.stderr
    assert "E line 4: gt_controller_estimate status 1" in run.stderr and "E line 2" not in run.stderr
    assert run.returncode == 0 and run.stdout.splitlines()[-1] == "R 2", run.stdout
    assert json.loads((out / "grindtwin_export.json").read_text())["feed_max_tph"] == limit


#: Calls read from stdin, each answered on a line: "E t_h y0 y1 y2 u0 u1 b_1 .. b_NB" -> "E status z..." (the
#: estimate after it); "C u0 u1" -> "C status u0 u1" (a step on the last blend held over the horizon, u preset
#: to 123.25, -7.5: what the step left there); "R" -> gt_controller_reset. Built with -DGT_FAIL_QP and linked
#: with --wrap=gt_rti_step, "F u0 u1" is a step whose QPs fail (as tests/mpc/test_nmpc.py breaks the solver).
CALL_DRIVER = r"""
#include <stdio.h>
#include "gt_controller.h"

#ifdef GT_FAIL_QP
#include "gt_rti.h"
static int fail_qp;
int __real_gt_rti_step(gt_rti *r, const double *w, const double *p, double *w_out, int *iter);
int __wrap_gt_rti_step(gt_rti *r, const double *w, const double *p, double *w_out, int *iter) {
    return fail_qp ? -1 : __real_gt_rti_step(r, w, p, w_out, iter);
}
#endif

int main(void) {
    char kind[2];
    int abi, i;
    double t, y[3], u[2], b[GT_NB] = {0}, preview[GT_PREVIEW_LEN], move[2];
    gt_controller *c = GT_CONTROLLER_NEW(&abi);
    if (!c) return 1;
    b[0] = 1.0; /* the blend of a step before any estimate: the first component alone */
    while (scanf(" %1s", kind) == 1) {
        if (kind[0] == 'R') {
            gt_controller_reset(c);
            continue;
        }
        if (kind[0] == 'E') {
            if (scanf("%lf %lf %lf %lf %lf %lf", &t, y, y + 1, y + 2, u, u + 1) != 6) return 1;
            for (i = 0; i < GT_NB; ++i)
                if (scanf("%lf", b + i) != 1) return 1;
            printf("E %d", gt_controller_estimate(c, t, y, u, b));
            for (i = 0; i < GT_NZ; ++i) printf(" %.17g", gt_controller_estimate_state(c)[i]);
        } else {
            if (scanf("%lf %lf", u, u + 1) != 2) return 1;
            for (i = 0; i < GT_PREVIEW_LEN; ++i) preview[i] = b[i % GT_NB];
            move[0] = 123.25;
            move[1] = -7.5;
#ifdef GT_FAIL_QP
            fail_qp = kind[0] == 'F';
#else
            if (kind[0] == 'F') return 1;
#endif
            i = gt_controller_step(c, preview, u, move); /* before move is read */
            printf("C %d %.17g %.17g", i, move[0], move[1]);
        }
        printf("\n");
    }
    gt_controller_free(c);
    return 0;
}
"""


def _call_driver(out: Path, folder: Path, *flags: str):
    """CALL_DRIVER built in ``folder`` against the export in ``out`` (with ``flags``): a function of the call
    lines -> the answers' rows (split)."""
    (folder / "driver.c").write_text(CALL_DRIVER)
    exe = folder / "driver"
    build = subprocess.run([c_tools(), "-O1", "-Wall", *flags, f"-I{out}", str(folder / "driver.c"),
                            str(out / "libgtcontroller.a"), "-lm", "-o", str(exe)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-2000:]

    def run(lines):
        answer = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True, check=True)
        return [ln.split() for ln in answer.stdout.splitlines()]
    return run


@pytest.fixture(scope="module")
def calls(built, tmp_path_factory):
    """CALL_DRIVER built against the export."""
    return _call_driver(built[0], tmp_path_factory.mktemp("calls"))


@pytest.fixture(scope="module")
def failing_calls(built, tmp_path_factory):
    """CALL_DRIVER with "F" lines: steps whose QPs fail (GNU ld's --wrap)."""
    return _call_driver(built[0], tmp_path_factory.mktemp("failing_calls"), "-DGT_FAIL_QP",
                        "-Wl,--wrap=gt_rti_step")


def _e(t_h: float, y, u=(23.64, 0.7), blend=(1.0, 0.0)) -> str:
    return "E " + " ".join(repr(float(v)) for v in [t_h, *y, *u, *blend])


def _y_near(est) -> list[float]:
    """Plausible measurements of all three: the EKF's predicted outputs from its initial estimate, moved off
    them (the innovation of y = 0 is -prediction), so the update moves the estimate."""
    _, _, e = est.step_function(est.z, est.P, [23.64, 0.7], [1.0, 0.0], [0.0] * 3, [1.0] * 3)
    return list(-np.asarray(e, float).ravel() * [1.05, 1.03, 1.04])


def test_an_estimate_at_a_time_off_the_sample_grid_is_refused(built, calls):
    """The exported estimate took no time: it predicted one sample period per call, so a DCS task at 1 min
    for a 3-min export, or a second estimate in one sample, got a wrong estimate with status OK. Now
    gt_controller_estimate takes the caller's t_h: at t, t + dt, then t + dt/3 the third is
    GT_ESTIMATE_BAD_TIME (4) with the estimate unchanged, as is a time not later, not finite, off the grid by
    more than GT_DT_TOL, or more periods than GT_MAX_PREDICT_PERIODS on; within GT_DT_TOL of the grid (a
    task's jitter) it is estimated. The first estimate after new or reset takes any finite time."""
    out, est, _, cfg = built
    dt, tol, k_max = cfg["GT_DT_H"], cfg["GT_DT_TOL"], int(cfg["GT_MAX_PREDICT_PERIODS"])
    assert 0 < tol < 0.5 and k_max == cfg["GT_N"]
    y, t0 = _y_near(est), 1000.0  # hours on the caller's clock: any origin
    start = [_e(t0, y), _e(t0 + dt, y)]
    for t_bad in (t0 + dt + dt / 3, t0 + dt, t0, t0 + dt * (1.5 + tol), t0 + dt * (2 + 1.1 * tol),
                  t0 + dt * (2 + k_max), float("nan"), float("inf")):
        rows = calls([*start, _e(t_bad, y)])
        assert [r[1] for r in rows] == ["0", "0", "4"], (t_bad, rows)
        assert rows[2][2:] == rows[1][2:], t_bad  # the estimate unchanged, bit for bit
        # and the last time too: the next sample on the grid is estimated as one period
        assert calls([*start, _e(t_bad, y), _e(t0 + 2 * dt, y)])[3] == calls([*start, _e(t0 + 2 * dt, y)])[2]
    for t_ok in (t0 + dt * (2 - 0.9 * tol), t0 + dt * (2 + 0.9 * tol), t0 + dt * (1 + k_max)):
        assert calls([*start, _e(t_ok, y)])[2][1] == "0", t_ok
    assert calls([_e(float("nan"), y)])[0][1] == "4"
    # after a reset any finite time is the first again; a refused input is said before a refused time
    assert [r[1] for r in calls([*start, "R", _e(-5.0, y), _e(-5.0, [np.nan] * 3, u=(np.nan, 0.7))])] == \
        ["0", "0", "0", "1"]


def test_a_missed_cycle_predicts_the_periods_elapsed_as_python_would(built, calls):
    """A DCS task that missed a cycle (estimates at t and t + 2 dt) got one period's prediction for two. Now
    the estimate predicts each period elapsed: the same estimate, bit for bit, as an estimate at t + dt with
    every measurement absent (NaN) and then t + 2 dt, and the Python EKF's over those three samples
    (make_step with NaN for the sample missed) to round-off; a step of one period differs (the test can
    fail). The same for two missed cycles."""
    _, est, _, cfg = built
    dt, y, absent = cfg["GT_DT_H"], _y_near(est), [np.nan] * 3
    u, blend = [23.64, 0.7], [1.0, 0.0]
    for missed in (1, 2):
        gap = calls([_e(0.0, y), _e((missed + 1) * dt, y)])
        filled = calls([_e(0.0, y), *(_e(j * dt, absent) for j in range(1, missed + 1)), _e((missed + 1) * dt, y)])
        one = calls([_e(0.0, y), _e(dt, y)])
        assert gap[-1][1] == "0" and gap[-1][2:] == filled[-1][2:], missed
        z_gap = np.array(gap[-1][2:], float)
        assert not np.allclose(z_gap, np.array(one[-1][2:], float), rtol=1e-6)
        est.reset()
        for y_k in [y, *[absent] * missed, y]:
            est.make_step(y_k, u, blend)
        np.testing.assert_allclose(z_gap, est.z, rtol=1e-12, atol=1e-12 * np.abs(est.z).max())
    est.reset()


def _python_gap(est, ctrl, y, blend, gap: int, samples: int, fail: bool) -> list:
    """The Python EKF and NMPC over CALL_DRIVER's steps (``blend`` held over the horizon): two samples from the
    initial estimate, each estimated (``y``) and stepped, then ``gap`` periods with no step, the ``gap - 1``
    missed estimated with every measurement absent, and a step told ``samples`` (its QP failing if ``fail``)."""
    n, target = ctrl.settings.horizon_steps, ctrl.settings.target_p80_um

    def step(u_prev, k):
        d = np.vstack([np.tile(np.reshape(blend, (-1, 1)), (1, n)), np.full((1, n), est.hardness_est)])
        return ctrl.make_step(est.x_est, d, u_prev, p80_bias_um=est.controller_p80_bias_um(target), samples=k)

    est.reset()
    ctrl.reset()
    u, steps = [23.64, 0.7], []
    for y_k in ([y], [y], [[np.nan] * 3] * (gap - 1) + [y]):
        for y_j in y_k:
            est.make_step(y_j, u, blend)
        if len(steps) == 2 and fail:
            solver = ctrl._solver

            def broken(**kwargs):
                raise RuntimeError("forced failure")
            ctrl._solver = broken
            try:
                steps.append(step(u, samples))
            finally:
                ctrl._solver = solver
        else:
            steps.append(step(u, 1 if len(steps) < 2 else samples))
        u = list(steps[-1].u_applied)
    return steps


@pytest.mark.parametrize("gap, fail", [(2, False), (3, False), (2, True), ("horizon", True)])
def test_a_step_after_missed_periods_moves_the_plan_on_by_them_as_python_does(built, failing_calls, gap, fail):
    """After a gap of k periods with no step (a DCS task held, a link down) the exported step started its
    iteration from the last plan shifted by one and a failed step applied that plan's move one on, where the
    Python controller, told the samples since its last step (grindtwin serve passes them), moves both on by k:
    after a gap as long as the horizon it holds the input. Now the step moves on by the periods its estimates
    predicted since the last step, in one estimate k periods on or in k one period apart (the same estimate):
    its statuses and moves are Python's (1e-9 relative), solved or failed; by one they differ (checked here,
    so the comparison can fail)."""
    out, est, ctrl, cfg = built
    dt, y, blend = cfg["GT_DT_H"], _y_near(est), [1.0, 0.0]
    gap = int(cfg["GT_N"]) if gap == "horizon" else gap
    code = {None: None, "shifted_plan": "1", "hold_input": "2"}
    try:
        py = _python_gap(est, ctrl, y, blend, gap, gap, fail)
        by_one = _python_gap(est, ctrl, y, blend, gap, 1, fail)[-1]
        assert py[-1].fallback_used == ("hold_input" if gap == cfg["GT_N"] else "shifted_plan" if fail else None)
        assert by_one.fallback_used != py[-1].fallback_used or \
            np.max(np.abs(by_one.u_applied / py[-1].u_applied - 1.0)) > 1e-6
        u = [[23.64, 0.7], *([float(v) for v in r.u_applied] for r in py[:2])]
        first = [_e(0.0, y, u[0], blend), f"C {u[0][0]!r} {u[0][1]!r}", _e(dt, y, u[1], blend),
                 f"C {u[1][0]!r} {u[1][1]!r}"]
        last = f"{'F' if fail else 'C'} {u[2][0]!r} {u[2][1]!r}"
        at_once = failing_calls([*first, _e((1 + gap) * dt, y, u[2], blend), last])
        apart = failing_calls([*first, *(_e((1 + j) * dt, [np.nan] * 3, u[2], blend) for j in range(1, gap)),
                               _e((1 + gap) * dt, y, u[2], blend), last])
        assert apart[-1] == at_once[-1]
        assert [r[1] for r in at_once if r[0] == "E"] == ["0"] * 3
        for row, r in zip([r for r in at_once if r[0] == "C"], py, strict=True):
            solved = "5" if str(r.status).startswith("target_unreachable") else "0"
            assert row[1] == (code[r.fallback_used] or solved), (row, r.status)
            np.testing.assert_allclose(np.array(row[2:], float), r.u_applied, rtol=1e-9, atol=0.0)
    finally:
        est.reset()
        ctrl.reset()


def test_a_second_step_without_an_estimate_is_refused(calls):
    """gt_controller_step twice without an estimate between them planned twice from the same estimate, status
    OK; a step before any estimate planned from the exported initial one. Now both are GT_STEP_NO_ESTIMATE (7)
    with nothing written into u; an estimate (or a refused input's retry) lets the step plan again, a refused
    estimate does not."""
    e = _e(0.0, [np.nan] * 3)
    rows = calls(["C 23.64 0.7", e, "C 23.64 0.7", "C 23.64 0.7", "C nan 0.7", _e(0.05, [np.nan] * 3),
                  "C nan 0.7", "C 23.64 0.7", _e(0.06, [np.nan] * 3), "C 23.64 0.7", "R", "C 23.64 0.7"])
    steps = [r[1:] for r in rows if r[0] == "C"]
    untouched = ["123.25", "-7.5"]
    assert steps[0] == ["7", *untouched] and steps[1][0] in ("0", "5") and steps[1][1:] != untouched
    assert steps[2] == ["7", *untouched]
    assert steps[3] == ["4", *untouched]  # a refused input is said before the missing estimate
    assert steps[4] == ["4", *untouched] and steps[5][0] in ("0", "5")  # the estimate kept for the retry
    assert [r[1] for r in rows if r[0] == "E"] == ["0", "0", "4"]  # 0.06 h: off the grid, refused
    assert steps[6] == ["7", *untouched]  # a refused estimate is none
    assert steps[7] == ["7", *untouched]  # after a reset


def test_an_estimate_on_an_epoch_clock_or_one_set_back(built, calls):
    """gt_controller.h: any origin, a clock never set. Hours since 1970 (4.9e5 h) give the estimates of a clock
    from 0 bit for bit, the tolerance's edges where they are; a clock set back an hour refuses the estimates
    until it passes the last t_h, then predicts the time between as one period (the header says so)."""
    _, est, _, cfg = built
    dt, tol, y = cfg["GT_DT_H"], cfg["GT_DT_TOL"], _y_near(est)
    for t0 in (4.9e5, -4.9e5):
        assert calls([_e(t0 + j * dt, y) for j in range(3)]) == calls([_e(j * dt, y) for j in range(3)])
        assert [calls([_e(t0, y), _e(t0 + dt * (1 + f * tol), y)])[1][1] for f in (-1.1, -0.9, 0.9, 1.1)] == \
            ["4", "0", "0", "4"], t0
    back = [5.0, 5.0 + dt, *(5.0 + j * dt - 1.0 for j in range(2, 2 + round(1.0 / dt) + 1))]
    assert [r[1] for r in calls([_e(t, y) for t in back])] == ["0"] * 2 + ["4"] * round(1.0 / dt) + ["0"]
