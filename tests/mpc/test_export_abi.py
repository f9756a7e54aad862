"""The exported C controller against a caller's build: a caller compiled with another export's
headers is refused with a named status (GT_ABI_SIZES_DIFFER, GT_ABI_LAYOUT_DIFFERS) before any call
could read past its buffers; the preview's lead (the scene's controller.preview_lead_h) is in the
exported header and manifest; what u holds after GT_STEP_BAD_INPUT (nothing written) and
GT_STEP_HOLD_INPUT (u_applied projected onto the bounds) is what the header says; and two exports
to one folder at once: the second is refused at once (a lock beside the folder, removed after)."""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios.cli import main
from tests.mpc.conftest import c_tools

REFERENCE = Path(__file__).parents[2] / "scenarios" / "reference_transition.toml"
HEADERS = ("gt_controller.h", "gt_controller_config.h")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The reference scene exported and built (make, -O1): ``(folder, config defines)``."""
    cc = c_tools()
    out = tmp_path_factory.mktemp("abi") / "ctl"
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 0
    build = subprocess.run(["make", "-j2", "-C", str(out), "CFLAGS=-O1", f"CC={cc}"], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-2000:]
    config = dict(re.findall(r"#define (GT_\w+) (\S+)\n", (out / "gt_controller_config.h").read_text()))
    return out, config


def _compile(cc: str, source: str, folder: Path, include: Path, objects) -> Path:
    """``source`` compiled in ``folder`` against the headers of ``include`` and linked with ``objects``."""
    (folder / "driver.c").write_text(source)
    exe = folder / "driver"
    run = subprocess.run([cc, "-O1", "-Wall", f"-I{include}", str(folder / "driver.c"), *map(str, objects), "-lm",
                          "-o", str(exe)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]
    return exe


ABI_DRIVER = r"""
#include <stdio.h>
#include "gt_controller.h"

int main(void) {
    int st = -1;
    gt_controller *c = GT_CONTROLLER_NEW(&st);
    printf("%d %d %d %lx\n", GT_CONTROLLER_CHECK_ABI(), st, c == NULL, gt_controller_abi_hash());
    gt_controller_free(c);
    return 0;
}
"""


def test_a_caller_compiled_with_another_exports_headers_is_refused(built, tmp_path):
    """A caller compiled against gt_controller.h of one export and linked with the library of
    another (another horizon, components, estimator) sized its buffers by its own GT_N, GT_NB,
    GT_NZ: the library read and wrote past them without a word. Now GT_CONTROLLER_NEW passes the
    caller's header values and the library refuses a mismatch: GT_ABI_SIZES_DIFFER (1) for a
    length, GT_ABI_LAYOUT_DIFFERS (2) for the same lengths with another GT_ABI_HASH (the
    components in another order); NULL, nothing allocated. The export's own headers pass (0)."""
    out, config = built
    cc = c_tools()
    library_hash = config["GT_ABI_HASH"]
    assert re.fullmatch(r"0x[0-9a-f]{8}UL", library_hash)
    variants = {"same": ({}, "0"), "horizon": ({"GT_N": str(int(config["GT_N"]) + 1)}, "1"),
                "components": ({"GT_NB": "3"}, "1"), "estimator": ({"GT_NZ": str(int(config["GT_NZ"]) + 1)}, "1"),
                "measurements": ({"GT_NY": "4"}, "1"),
                "layout": ({"GT_ABI_HASH": f"0x{int(library_hash[2:-2], 16) ^ 1:08x}UL"}, "2")}
    for name, (changes, status) in variants.items():
        hdr = tmp_path / name
        hdr.mkdir()
        for h in HEADERS:
            shutil.copyfile(out / h, hdr / h)
        text = (hdr / "gt_controller_config.h").read_text()
        for macro, value in changes.items():
            text, n = re.subn(rf"#define {macro} \S+\n", f"#define {macro} {value}\n", text)
            assert n == 1, macro
        (hdr / "gt_controller_config.h").write_text(text)
        exe = _compile(cc, ABI_DRIVER, hdr, hdr, [out / "libgtcontroller.a"])
        check, new_status, is_null, lib_hash = subprocess.run([str(exe)], capture_output=True, text=True,
                                                              check=True).stdout.split()
        assert (check, new_status, is_null) == (status, status, "0" if status == "0" else "1"), name
        assert f"0x{lib_hash}UL" == library_hash
    header = (out / "gt_controller.h").read_text()
    for named in ("GT_ABI_OK = 0", "GT_ABI_SIZES_DIFFER = 1", "GT_ABI_LAYOUT_DIFFERS = 2"):
        assert named in header


@pytest.mark.parametrize("changes", [
    {"\nsample_period_h = 0.05": "\nsample_period_h = 0.1", "p80_sample_period_h = 0.05": "p80_sample_period_h = 0.1",
     "rk4_substeps = 3": "rk4_substeps = 6"},
    {"preview_lead_h = 0.5": "preview_lead_h = 0.25"}], ids=["sample_period", "preview_lead"])
def test_a_caller_built_for_another_period_or_lead_is_refused(built, tmp_path, changes):
    """A caller compiled with the headers of an export at a 6-min sample period (its task every GT_DT_H =
    0.1 h) passed the check against the library of the 3-min export of the same scene (GT_ABI_OK): each
    estimate was taken as two periods and returned OK, each step OK with a 3-min move. A caller filling its
    preview to another GT_PREVIEW_LEAD_H passed the same way. Now GT_ABI_HASH covers both: the library
    refuses such a caller (GT_ABI_LAYOUT_DIFFERS, 2), NULL."""
    out, config = built
    cc = c_tools()
    text = REFERENCE.read_text()
    for old, new in changes.items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    scene = tmp_path / "variant.toml"
    scene.write_text(text)
    other = tmp_path / "other"
    assert main(["export-controller", str(scene), "--out", str(other)]) == 0
    other_cfg = dict(re.findall(r"#define (GT_\w+) (\S+)\n", (other / "gt_controller_config.h").read_text()))
    sizes = ("GT_NX", "GT_NU", "GT_NY", "GT_NB", "GT_N", "GT_NZ")
    assert [other_cfg[k] for k in sizes] == [config[k] for k in sizes]  # the lengths pass: only the hash can tell
    assert any(other_cfg[k] != config[k] for k in ("GT_DT_H", "GT_PREVIEW_LEAD_H"))
    exe = _compile(cc, ABI_DRIVER, other, other, [out / "libgtcontroller.a"])
    check, new_status, is_null, _ = subprocess.run([str(exe)], capture_output=True, text=True,
                                                   check=True).stdout.split()
    assert (check, new_status, is_null) == ("2", "2", "1")


def test_a_caller_of_the_previous_api_is_refused(built, tmp_path):
    """API 4 gave gt_controller_estimate the sample's time t_h before y: a caller built with the headers of
    an export of API 3 would pass y where t_h is. Its GT_ABI_HASH, the same layout at API 3, is refused
    (GT_ABI_LAYOUT_DIFFERS, 2), as is API 2's."""
    from mpc.export import API_VERSION, abi_hash

    out, config = built
    cc = c_tools()
    layout = json.loads((out / "grindtwin_export.json").read_text())["abi"]["layout"]
    assert f"0x{abi_hash(layout):08x}UL" == config["GT_ABI_HASH"] and layout["api_version"] == API_VERSION
    for version in (2, 3):  # the versions before t_h
        hdr = tmp_path / f"api{version}"
        hdr.mkdir()
        for h in HEADERS:
            shutil.copyfile(out / h, hdr / h)
        cfg = hdr / "gt_controller_config.h"
        old = abi_hash({**layout, "api_version": version})
        cfg.write_text(cfg.read_text().replace(config["GT_ABI_HASH"], f"0x{old:08x}UL"))
        exe = _compile(cc, ABI_DRIVER, hdr, hdr, [out / "libgtcontroller.a"])
        check, new_status, is_null, _ = subprocess.run([str(exe)], capture_output=True, text=True,
                                                       check=True).stdout.split()
        assert (check, new_status, is_null) == ("2", "2", "1"), version


def test_a_library_built_with_an_edited_config_header_is_refused(built, tmp_path):
    """gt_controller.h called the config header 'the tuning'; an edited target, speed bound or feed rate
    limit compiled, ran and returned OK while the QP's data (gt_rti_data.c) kept the exported values:
    a 150 um target moved the feed as the 210 um one did. Now the library compares its header with
    gt_exported.c: GT_ABI_CONFIG_EDITED (3) from the check and GT_CONTROLLER_NEW, NULL from
    gt_controller_new, and the replay harness says so; the export's own build passes (0)."""
    out, config = built
    cc = c_tools()
    for macro, value in (("GT_TARGET_P80_UM", "150.0"), ("gt_du_max", None)):
        lib = tmp_path / macro
        shutil.copytree(out, lib)
        cfg = lib / "gt_controller_config.h"
        if value is None:  # the feed's largest move per sample, 1.0 t/h as exported, made 0.2
            text, n = re.subn(r"(gt_du_max\[2\] = \{)[^,]+,", r"\g<1>0.2,", cfg.read_text())
        else:
            text, n = re.subn(rf"#define {macro} \S+\n", f"#define {macro} {value}\n", cfg.read_text())
        assert n == 1, macro
        cfg.write_text(text)
        build = subprocess.run(["make", "-C", str(lib), "CFLAGS=-O1", f"CC={cc}"], capture_output=True, text=True)
        assert build.returncode == 0, build.stderr[-2000:]
        exe = _compile(cc, CONFIG_DRIVER, lib, lib, [lib / "libgtcontroller.a"])
        check, new_status, is_null = subprocess.run([str(exe)], capture_output=True, text=True,
                                                    check=True).stdout.split()
        assert (check, new_status, is_null) == ("3", "3", "1"), macro
        assert subprocess.run([str(exe), "unchecked"], capture_output=True, text=True).stdout.strip() == "null"
        replay = subprocess.run([str(lib / "gt_replay")], input="", capture_output=True, text=True)
        assert replay.returncode != 0 and "abi status 3" in replay.stderr
    assert "GT_ABI_CONFIG_EDITED = 3" in (out / "gt_controller.h").read_text()


def test_every_constant_of_the_config_header_is_checked(built):
    """The library refuses an edited gt_controller_config.h by comparing GT_CONFIG_SCALARS and the arrays
    with gt_exported.c: a constant left out of them (as GT_DT_TOL, the estimate's time tolerance, might have
    been) could be edited and obeyed by the C while the exported data and the manifest said otherwise. Every
    number the header defines is in the check, but the derived GT_PREVIEW_LEN and the header's guard."""
    from mpc.export import CHECKED_ARRAYS

    out, _ = built
    text = (out / "gt_controller_config.h").read_text()
    scalars = set(re.search(r"#define GT_CONFIG_SCALARS \{(.*)\}", text).group(1).split(", "))
    defined = set(re.findall(r"#define (GT_\w+) ", text)) - {"GT_CONFIG_SCALARS", "GT_PREVIEW_LEN"}
    assert {"GT_DT_TOL", "GT_MAX_PREDICT_PERIODS", "GT_DT_H"} <= defined == scalars
    assert set(re.findall(r"static const double (gt_\w+)\[", text)) == set(CHECKED_ARRAYS)


#: the check and GT_CONTROLLER_NEW; with an argument gt_controller_new, unchecked
CONFIG_DRIVER = r"""
#include <stdio.h>
#include "gt_controller.h"

int main(int argc, char **argv) {
    int st = -1;
    gt_controller *c;
    (void)argv;
    if (argc > 1) {
        c = gt_controller_new();
        puts(c ? "made" : "null");
        gt_controller_free(c);
        return 0;
    }
    c = GT_CONTROLLER_NEW(&st);
    printf("%d %d %d\n", GT_CONTROLLER_CHECK_ABI(), st, c == NULL);
    gt_controller_free(c);
    return 0;
}
"""


def test_the_abi_hash_covers_the_order_of_the_components():
    """Two exports of the same sizes whose blends list the components in another order pass the
    length checks: the hash tells them apart (and the API version's)."""
    from mpc.export import abi_hash

    layout = {"api_version": 2, "n": 10, "nb": 2, "components": ["B", "D"], "disturbance_model": "hardness"}
    assert abi_hash(layout) == abi_hash(dict(reversed(list(layout.items()))))  # keys sorted
    assert abi_hash(layout) != abi_hash({**layout, "components": ["D", "B"]})
    assert abi_hash(layout) != abi_hash({**layout, "api_version": 3})


def test_the_preview_lead_is_exported(built, tmp_path):
    """The Python loop fills stage k of the preview with the blend at t + min(k dt, lead); the
    export did not say the lead, so a DCS engineer could not fill it the same way. Now the header
    has GT_PREVIEW_LEAD_H and GT_DT_H (the rule in gt_controller.h) and the manifest
    preview_lead_h: the reference scene's 0.5 h, and a scene's other lead."""
    out, config = built
    assert float(config["GT_PREVIEW_LEAD_H"]) == 0.5 and float(config["GT_DT_H"]) == 0.05
    assert json.loads((out / "grindtwin_export.json").read_text())["preview_lead_h"] == 0.5
    text = REFERENCE.read_text()
    assert text.count("preview_lead_h = 0.5\n") == 1
    scene = tmp_path / "lead.toml"
    scene.write_text(text.replace("preview_lead_h = 0.5\n", "preview_lead_h = 0.2\n"))
    other = tmp_path / "lead"
    assert main(["export-controller", str(scene), "--out", str(other)]) == 0
    assert "#define GT_PREVIEW_LEAD_H 0.2\n" in (other / "gt_controller_config.h").read_text()
    manifest = json.loads((other / "grindtwin_export.json").read_text())
    assert manifest["preview_lead_h"] == 0.2 and manifest["preview"] is True
    assert "t + min(k GT_DT_H, GT_PREVIEW_LEAD_H)" in (out / "gt_controller.h").read_text()


U_DRIVER = r"""
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "gt_controller.h"

int main(void) {
    int st, i, abi;
    gt_controller *c = GT_CONTROLLER_NEW(&abi);
    double good[GT_PREVIEW_LEN], bad[GT_PREVIEW_LEN], u_ok[2] = {27.0, 0.7}, u_nan[2] = {NAN, 0.7};
    double u_out[2] = {1000.0, 5.0}, u[2], plan[GT_N * 2], z[GT_NZ], y[3] = {NAN, NAN, NAN};
    for (i = 0; i < GT_N; ++i) {
        good[i * GT_NB] = 1.0; good[i * GT_NB + 1] = 0.0;
        bad[i * GT_NB] = 5.0; bad[i * GT_NB + 1] = -4.0;
    }
    gt_controller_estimate(c, 0.0, y, u_ok, good); /* a step needs an estimate first */
    st = gt_controller_step(c, good, u_out, u);
    printf("first %d %.17g %.17g\n", st, u[0], u[1]);
    memcpy(plan, gt_controller_plan(c), sizeof plan);
    memcpy(z, gt_controller_estimate_state(c), sizeof z);
    {
        const double *previews[3] = {bad, good, NULL};
        const double *applied[3] = {u_ok, u_nan, u_ok};
        for (i = 0; i < 3; ++i) {
            u[0] = 123.25; u[1] = -7.5;
            st = gt_controller_step(c, previews[i], applied[i], u);
            printf("bad %d %d %d %d\n", st, u[0] == 123.25 && u[1] == -7.5,
                   memcmp(plan, gt_controller_plan(c), sizeof plan) == 0,
                   memcmp(z, gt_controller_estimate_state(c), sizeof z) == 0);
        }
    }
    printf("bounds %.17g %.17g %.17g %.17g\n", gt_u_lo[0], gt_u_lo[1], gt_u_hi[0], gt_u_hi[1]);
    gt_controller_free(c);
    return 0;
}
"""


def _status_text(header: str, name: str) -> str:
    """The comment of ``GT_STEP_<name>`` in enum gt_step_status, as one line."""
    m = re.search(rf"GT_STEP_{name} = \d+,?\s*/\*(.*?)\*/", header, re.S)
    assert m, name
    return " ".join(m.group(1).split())


def test_what_u_holds_after_a_refused_or_held_step_is_what_the_header_says(built, tmp_path):
    """The header said GT_STEP_BAD_INPUT leaves u "as it was" and GT_STEP_HOLD_INPUT gives
    u = u_applied, though the step holds u_applied projected onto the bounds. Now every status
    says what u holds, and the C does it: after a bad input u keeps the caller's values bit for bit
    (a preview of [5, -4], a NaN u_applied, a NULL preview), with the plan and the estimate
    unchanged; a hold (the library rebuilt with no real-time iteration, so every step falls back
    with no plan) is u_applied = (1000, 5) projected onto the bounds."""
    out, config = built
    cc = c_tools()
    header = (out / "gt_controller.h").read_text()
    assert "nothing written into u: both elements keep the caller's values" in _status_text(header, "BAD_INPUT")
    for name in ("HOLD_INPUT", "BAD_BIAS"):
        assert "u = u_applied projected onto the bounds" in _status_text(header, name), name
    for name in ("OK", "SHIFTED_PLAN", "TARGET_UNREACHABLE", "INPUT_PROJECTED"):
        assert " u " in f" {_status_text(header, name)} ", name
    from mpc.export import STEP_STATUS
    assert "nothing written into u" in STEP_STATUS[4] and "projected onto the input bounds" in STEP_STATUS[2]

    exe = _compile(cc, U_DRIVER, tmp_path, out, [out / "libgtcontroller.a"])
    rows = [ln.split() for ln in subprocess.run([str(exe)], capture_output=True, text=True,
                                                check=True).stdout.splitlines()]
    lo_f, lo_s, hi_f, hi_s = map(float, rows[-1][1:])
    assert rows[0][1] == "6" and float(rows[0][2]) <= hi_f  # solved, from the projection: GT_STEP_INPUT_PROJECTED
    assert [r for r in rows if r[0] == "bad"] == [["bad", "4", "1", "1", "1"]] * 3

    # the hold: gt_controller.c built against a config with no real-time iteration (a QP never
    # solved), linked with the export's other objects
    hold = tmp_path / "hold"
    hold.mkdir()
    for name in (*HEADERS, "gt_controller.c"):
        shutil.copyfile(out / name, hold / name)
    cfg = hold / "gt_controller_config.h"
    text, n = re.subn(r"#define GT_RTI_ITERATIONS \d+\n", "#define GT_RTI_ITERATIONS 0\n", cfg.read_text())
    assert n == 1
    cfg.write_text(text)
    # the library refuses an edited header: this test's own gt_exported.c lists the edited value
    exported = (out / "gt_exported.c").read_text()
    listed = re.search(r"\{(.*)\}", exported).group(1).split(", ")
    scalars = re.search(r"#define GT_CONFIG_SCALARS \{(.*)\}", (out / "gt_controller_config.h").read_text()).group(1)
    listed[scalars.split(", ").index("GT_RTI_ITERATIONS")] = "0"
    (hold / "gt_exported.c").write_text(exported.replace(re.search(r"\{(.*)\}", exported).group(1), ", ".join(listed)))
    objs = []
    for name in ("gt_controller", "gt_exported"):
        objs.append(hold / f"{name}.o")
        run = subprocess.run([cc, "-O1", "-c", f"-I{hold}", f"-I{out}", str(hold / f"{name}.c"), "-o", str(objs[-1])],
                             capture_output=True, text=True)
        assert run.returncode == 0, run.stderr[-2000:]
    others = [out / f"{name}.o" for name in ("gt_rti_data", "gt_ekf_data", "gt_qp", "gt_cond", "gt_rti")]
    exe = _compile(cc, U_DRIVER, hold, hold, [*objs, *others])
    first = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.splitlines()[0].split()
    assert first[1] == "2" and [float(first[2]), float(first[3])] == [hi_f, hi_s] == [45.0, 0.85]


HOLDER = r"""
import sys
from mpc.export import export_lock
with export_lock(sys.argv[1]):
    print("held", flush=True)
    sys.stdin.read()
"""


def _hold(out: Path) -> subprocess.Popen:
    """Another process holding the export lock of ``out`` until its stdin closes."""
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(out)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline() == "held\n"
    return proc


def test_a_second_export_to_one_folder_is_refused_at_once(tmp_path, monkeypatch, capsys):
    """Two exports to one --out at once had no lock: both wrote, and the second's replace could
    move the first's export aside mid-way. Now an export holds .DIR.export.lock beside DIR (flock):
    another to the same folder is refused (exit 2) before it builds anything, naming the folder;
    the lock file is gone when the holder ends, and a lock left by a killed export is taken over
    by the next one and removed. A file of that name that is not a lock is refused, left as it
    was."""
    import scenarios.run.models as models

    out = tmp_path / "sub" / "ctl"  # its parent is created for the lock, and removed again
    lock = tmp_path / "sub" / ".ctl.export.lock"
    holder = _hold(out)
    try:
        assert lock.is_file()
        built = []
        real = models.build_models
        monkeypatch.setattr(models, "build_models", lambda *a, **k: built.append(1) or real(*a, **k))
        assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert f"--out {out}: another export-controller to this folder is running" in err
        assert f"pid {holder.pid}" in err and not built and not out.exists()
    finally:
        holder.stdin.close()
        holder.stdout.close()
        assert holder.wait(30) == 0
    assert not (tmp_path / "sub").exists()  # the holder removed its lock and the parent it made

    holder = _hold(out)
    holder.send_signal(signal.SIGKILL)
    holder.wait(30)
    holder.stdin.close()
    holder.stdout.close()
    assert lock.is_file()  # left by the killed holder, no longer locked
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 0
    assert built and sorted(p.name for p in out.parent.iterdir()) == ["ctl"]  # taken over and removed

    lock.write_text("a user's notes\n")
    assert main(["export-controller", str(REFERENCE), "--out", str(out)]) == 2
    assert "is in the way (not the lock file of a grindtwin export" in capsys.readouterr().err
    assert lock.read_text() == "a user's notes\n"
