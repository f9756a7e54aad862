"""The controller as C source for a DCS: the EKF step and the real-time iteration on the condensed
QP, with a small C API (mpc/c/gt_controller.h: new, estimate, step, plan).

What is written (``export_controller``): CasADi's generated C of the estimator's step
(:attr:`mpc.estimator.Ekf.step_function`, ``gt_ekf_data.c``) and of the condensed QP data
(:func:`mpc.condense.stage_functions`) with the plan's passing fraction (:func:`plan_passing_function`,
``gt_rti_data.c``), with their headers; the
hand-written C of mpc/c (the Goldfarb-Idnani QP solver, the condensing loop, the RTI step, the controller API, a
replay harness and an allocation counter); ``gt_controller_config.h`` (dimensions, scales, bounds,
passing weights, the initial estimate); a Makefile; and ``grindtwin_export.json`` listing every
file written with its sha256, what it was built from (``built_from``: the scene file's path and sha256, the
calibration, the controller model's effects and grid, the versions), the step's and the estimate's statuses
(:data:`STEP_STATUS`, :data:`ESTIMATE_STATUS`), the preview's lead (``preview_lead_h``), the layout the caller's buffers
follow and its hash (``abi``: :func:`abi_layout`, GT_ABI_HASH) and any notes. The Python controller with
``qpsol = "condensed"`` runs the same generated code and the same solver, so the moves agree to
rounding, and the step's status is the Python controller's: ok, a fallback, or target_unreachable
(the plan misses the target at the horizon end, by the rule of :meth:`mpc.Controller.make_step`).

The caller's headers: ``GT_CONTROLLER_NEW(&status)`` (gt_controller.h) passes the lengths and
GT_ABI_HASH of the headers the caller was compiled with to the library, which refuses another
export's (``GT_ABI_SIZES_DIFFER``, ``GT_ABI_LAYOUT_DIFFERS``: another layout, or another sample period
or preview lead, which time the caller's calls and fill its preview) rather than read past its buffers, and
refuses its own gt_controller_config.h once edited (``GT_ABI_CONFIG_EDITED``: the header's values
against ``gt_exported.c``'s, :func:`exported_source`; a bound or a target edited there compiled
and ran while the QP's data kept the exported ones).

Memory: ``gt_controller_new`` makes two allocations (the controller with the EKF's work, and the
RTI's block: QP data, solver work); estimate and step allocate nothing (counted by
``gt_malloc_count.so`` under ``LD_PRELOAD``).

The folder: created if absent; an existing folder is used only if it is empty or holds a previous
export and nothing else (its manifest names every file it wrote and every file its Makefile builds),
with none of its sources changed since (their sha256 in the manifest: an edited file is the
user's work), which is then replaced (its permissions kept); anything else (the current folder or a parent of it
too) is refused, nothing written. Files are written into a new hidden folder beside it
(``.DIR.<random>.partial``, :func:`twin.atomic.new_folder_beside`) and renamed when complete;
the previous export is moved aside first and removed by the names its manifest lists. One export
at a time: it holds ``.DIR.export.lock`` beside ``DIR`` (:func:`export_lock`, ``fcntl.flock``), so a
second export to the same folder is refused at once; the file is removed at the end, and one left
by a killed export (no longer locked) is taken over by the next export.

Checking an export (:func:`check_export`; ``grindtwin export-controller SCENE --check DIR``): whether the
export in a folder is what :func:`export_controller` would write now, writing nothing there. Every item of
its manifest (``built_from`` and each file's sha256 among them) is compared with the manifest of the files
regenerated in a temporary folder (CasADi's code generated, not compiled), each file of the folder with its
sha256, and gt_controller_config.h's constants by name (an input whose file hash is unchanged, a code
change, moves them). A manifest without ``built_from`` (made before it was recorded) cannot be checked.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import re
import shutil
import stat
import tempfile
import threading
import warnings
from pathlib import Path
from typing import NamedTuple

import casadi as ca
import numpy as np

from mpc.codegen import C_DIR
from mpc.condense import stage_functions
from mpc.errors import MpcInputError, OutsideModelsWarning
from mpc.estimator import MEASUREMENTS
from mpc.nmpc import PASSING_TARGET, speed_max_note
from twin import LockError, acquire_lock, file_sha256, json_text, new_folder_beside, release_lock, replace_folder
from twin.ore import blend_sum_tolerance

MANIFEST = "grindtwin_export.json"
#: The C API's version (gt_controller.h), in GT_ABI_HASH: 2 added gt_controller_check_abi; 3 the statuses
#: GT_STEP_INPUT_PROJECTED and GT_ESTIMATE_IMPLAUSIBLE (a caller of 2 would read them as unknown); 4 the
#: estimate's time argument t_h (a caller of 3 passes y where t_h is) and GT_ESTIMATE_BAD_TIME, GT_STEP_NO_ESTIMATE.
API_VERSION = 4
#: How far [fraction of the sample period] the time between two estimates may lie from a whole number of
#: periods (GT_DT_TOL): a DCS task's jitter, well under 5 % of a period of minutes, passes; a task at another
#: period (1 min for 3: a third) or a second estimate in one sample is refused (GT_ESTIMATE_BAD_TIME).
SAMPLE_TIME_TOL = 0.05
#: gt_controller_step's statuses (mpc/c/gt_controller.h's enum gt_step_status), in the manifest.
STEP_STATUS = {
    0: "ok: the QP solved; u is the plan's first move",
    1: "shifted_plan: the QP failed; u is the previous plan shifted by the periods estimated since the last step "
       "(one a sample, k after a gap of k; hold_input once that moves it past its last stage), clipped to the "
       "rate limits around u_applied",
    2: "hold_input: the QP failed and no plan is left; u = u_applied projected onto the input bounds",
    3: "bad_bias: the estimated P80 bias is not finite or not below the target; nothing solved, u = u_applied "
       "projected onto the input bounds",
    4: "bad_input: c, preview, u_applied or u is NULL, u_applied or the preview is not finite, or a stage's blend "
       "is not fractions in [0, 1] summing to 1 within GT_BLEND_SUM_TOL (the Python controller raises on each); "
       "nothing solved and nothing written into u (it keeps the caller's values; not a move to apply), the plan "
       "and the estimate unchanged",
    5: "target_unreachable: the QP solved and u is the plan's first move, applied as for ok, but the plan's "
       "passing fraction of the target at the horizon end (gt_controller_passing_end) misses 0.80 by more "
       "than unreachable_tol_frac: the target is out of reach within the horizon (the Python controller's "
       "status by the same rule)",
    6: "input_projected: the QP solved and u is the plan's first move, applied as for ok, but u_applied was "
       "outside the input bounds and the plan starts from its projection onto them (the Python controller's "
       "input_outside_bounds): after a manual period, or an input in other units; said before target_unreachable",
    7: "no_estimate: no estimate made since the last step (or since new/reset): the step would plan again from the "
       "estimate it planned from; inputs checked first (bad_input before this); nothing solved and nothing written "
       "into u, the plan and the estimate unchanged: estimate this sample, then step",
}
#: gt_controller_estimate's statuses (mpc/c/gt_controller.h's enum gt_estimate_status), in the manifest.
ESTIMATE_STATUS = {
    0: "ok: estimated",
    1: "bad_input: c, y, u_applied or blend is NULL, u_applied is not finite, a feed < 0 or above GT_FEED_MAX_TPH "
       "(its physical limit: a feed in kg/h or t/d), a speed outside (0, 1), or blend is not fractions in [0, 1] "
       "summing to 1 within GT_BLEND_SUM_TOL (the Python EKF raises); "
       "nothing estimated, the estimate left as it was",
    2: "reset: the update left a non-finite estimate or covariance; both back to the exported initial estimate "
       "(as the scene's closed loop resets its EKF), the plan kept",
    3: "implausible: a measurement lay outside its physical range (gt_y_lo, gt_y_hi): not used, as absent (as "
       "grindtwin serve takes a Bad reading), the others were",
    4: "bad_time: t_h is not finite, or, after the first estimate since new/reset (any finite t_h), it lies not "
       "within GT_DT_TOL x GT_DT_H of k GT_DT_H after the last estimate's for a whole k from 1 to "
       "GT_MAX_PREDICT_PERIODS (a second estimate in one sample, a task at another period, a gap longer than the "
       "horizon); inputs checked first (bad_input before this); nothing estimated, the estimate and the last t_h "
       "unchanged. k periods are k predicts, the k - 1 samples missed as ones with every measurement absent",
}
C_FILES = ("gt_qp.c", "gt_qp.h", "gt_cond.c", "gt_cond.h", "gt_rti.c", "gt_rti.h", "gt_controller.c", "gt_controller.h",
           "gt_replay.c", "gt_malloc_count.c")
#: What the Makefile builds in the folder (a re-export may replace these too).
BUILD_PRODUCTS = ("gt_rti_data.o", "gt_ekf_data.o", "gt_exported.o", "gt_qp.o", "gt_cond.o", "gt_rti.o",
                  "gt_controller.o", "gt_replay.o", "libgtcontroller.a", "gt_replay", "gt_malloc_count.so")
MAKEFILE = """\
# grindtwin's exported NMPC: `make` builds libgtcontroller.a, the replay harness gt_replay and
# the allocation counter gt_malloc_count.so (LD_PRELOAD=./gt_malloc_count.so ./gt_replay < log).
CC ?= cc
CFLAGS ?= -O2
# -ffast-math, -Ofast and -ffinite-math-only drop the NaN checks every refusal rests on (gt_qp.h refuses
# them too): refused here before anything is built, so no object of theirs is left for a later `make`
ifneq ($(filter -Ofast -ffast-math -ffinite-math-only,$(CFLAGS)),)
$(error CFLAGS $(CFLAGS): the controller checks for NaN and infinity; build without -ffast-math, -Ofast or \
-ffinite-math-only)
endif
OBJS = gt_rti_data.o gt_ekf_data.o gt_exported.o gt_qp.o gt_cond.o gt_rti.o gt_controller.o
# every object depends on every header: an edited gt_controller_config.h rebuilds everything (and the
# library then refuses it: GT_ABI_CONFIG_EDITED, the header's values not those exported)
HEADERS = gt_controller.h gt_controller_config.h gt_cond.h gt_qp.h gt_rti.h gt_rti_data.h gt_ekf_data.h

all: libgtcontroller.a gt_replay gt_malloc_count.so

libgtcontroller.a: $(OBJS)
\tar rcs $@ $(OBJS)

gt_replay: gt_replay.o libgtcontroller.a
\t$(CC) $(CFLAGS) -o $@ gt_replay.o libgtcontroller.a -lm

gt_malloc_count.so: gt_malloc_count.c
\t$(CC) -O2 -shared -fPIC -o $@ gt_malloc_count.c -ldl

%.o: %.c $(HEADERS)
\t$(CC) $(CFLAGS) -c $< -o $@

# what `make` built and nothing else (not *.o: an object of yours here stays)
clean:
\trm -f $(OBJS) gt_replay.o libgtcontroller.a gt_replay gt_malloc_count.so

.PHONY: all clean
"""


def _c_array(name: str, values) -> str:
    vals = ", ".join(_c_value(v) for v in np.asarray(values, float).ravel(order="F"))
    return f"static const double {name}[{max(len(np.ravel(values)), 1)}] = {{{vals}}};"


def _check(controller, estimator) -> None:
    s = controller.settings
    if s.solver != "rti" or s.qpsol != "condensed":
        raise MpcInputError(f"export-controller exports the real-time iteration on the condensed QP: the "
                            f"controller needs solver 'rti' and qpsol 'condensed' (the same QP as HPIPM's). "
                            f"Got solver {s.solver!r}, qpsol {s.qpsol!r}.")
    if estimator.model is not controller.model:
        raise MpcInputError("export-controller needs the estimator and the controller on one model.")
    if getattr(estimator, "change_detector", None) is not None:  # it was left out without a word
        raise MpcInputError("export-controller exports the EKF's step, not its change detector (the CUSUM's rewind "
                            "and rerun): the exported estimator would not be this one. Export an Ekf without "
                            "change_detector.")
    stride = controller._nxl + controller._nul
    for k, (ix, iu) in enumerate(zip(controller._ix, controller._iu)):
        if ix[0] != k * stride or iu[0] != k * stride + controller._nxl:
            raise MpcInputError("export-controller: the NLP's variable layout is not stage by stage.")


def plan_passing_function(controller) -> ca.Function:
    """``gt_plan_passing(x, u, d, wpass) -> passing``: the product's fraction passing the size of
    the passing weights ``wpass`` at a model state, input and disturbance, the controller's own
    (the first output of its ``_out_fn``), which :meth:`mpc.Controller.make_step` reads at the
    plan's end for its target_unreachable status and the exported step reads for the same."""
    c = controller
    x, u, d = ca.SX.sym("x", c.nx), ca.SX.sym("u", c.nu), ca.SX.sym("d", c.nd)
    wpass = ca.SX.sym("wpass", c._wpass.size)
    return ca.Function("gt_plan_passing", [x, u, d, wpass], [c._out_fn(x, u, d, wpass)[0]],
                       ["x", "u", "d", "wpass"], ["passing"])


def abi_layout(controller, estimator, preview_lead_h: float | None) -> dict:
    """What a caller's buffers and their meaning depend on (the lengths, the order of the blend's
    components, the measurements, the inputs, the estimate's states, the preview setting, the API's
    version, the sample period that times its calls and spaces the preview's stages, the lead to
    which it fills the preview): GT_ABI_HASH is a hash of it (:func:`abi_hash`), and the manifest
    lists it. A caller built for a 6-min export ran a 3-min library with every status OK (each
    estimate two periods, each move a 3-min one) before the period and the lead were in it."""
    c, s = controller, controller.settings
    return {"api_version": API_VERSION, "nx": c.nx, "nu": c.nu, "ny": len(MEASUREMENTS), "nb": c.nd - 1,
            "n": s.horizon_steps, "nz": int(estimator.z.size), "preview_len": (c.nd - 1) * s.horizon_steps,
            "preview": bool(s.preview), "components": [str(n) for n in c.model.spec.component_names],
            "model_shape": [int(v) for v in c.model.shape], "measurements": list(MEASUREMENTS),
            "inputs": ["feed_tph", "speed_frac_critical"], "disturbance_model": estimator.disturbance_model,
            "dt_h": float(s.dt_h), "preview_lead_h": None if preview_lead_h is None else float(preview_lead_h)}


def abi_hash(layout: dict) -> int:
    """GT_ABI_HASH: the first 32 bits of the sha256 of the layout's JSON (keys sorted)."""
    return int(hashlib.sha256(json.dumps(layout, sort_keys=True).encode()).hexdigest()[:8], 16)


#: The arrays of gt_controller_config.h the library checks, after the scalars, in this order.
CHECKED_ARRAYS = ("gt_x_scale", "gt_u_lo", "gt_u_hi", "gt_du_max", "gt_wpass", "gt_upper_um", "gt_z0", "gt_p0", "gt_u0",
                  "gt_y_lo", "gt_y_hi")


def _constants(controller, estimator, u0, preview_lead_h, measurement_range, feed_max_tph) -> tuple[dict, dict]:
    """The exported header's scalar macros (name -> value, C text; None: not exported) and arrays (name ->
    values). The scalars' order is GT_CONFIG_SCALARS's and gt_exported.c's, the dimensions up to
    GT_RTI_ITERATIONS first."""
    c, s, e = controller, controller.settings, estimator
    layout = abi_layout(controller, estimator, preview_lead_h)
    scalars = {"GT_NX": c.nx, "GT_NU": c.nu, "GT_ND": c.nd, "GT_NB": c.nd - 1, "GT_N": s.horizon_steps,
               "GT_NXL": c._nxl, "GT_NUL": c._nul, "GT_NW": c._nw,
               "GT_NP": c.nx + c.nd * s.horizon_steps + c.nu + c._wpass.size, "GT_NPASS": c._wpass.size,
               "GT_NZ": e.z.size, "GT_HAS_HARDNESS": int(e.has_hardness), "GT_HAS_P80_BIAS": int(e.has_p80_bias),
               "GT_PREVIEW": int(s.preview),
               "GT_WARM_START": int(s.warm_start), "GT_RTI_ITERATIONS": min(s.rti_iterations, s.max_iter),
               "GT_API_VERSION": API_VERSION, "GT_NY": layout["ny"], "GT_ABI_HASH": f"0x{abi_hash(layout):08x}UL",
               "GT_DT_H": repr(float(s.dt_h)),
               "GT_PREVIEW_LEAD_H": None if preview_lead_h is None else repr(float(preview_lead_h)),
               "GT_DT_TOL": repr(SAMPLE_TIME_TOL), "GT_MAX_PREDICT_PERIODS": s.horizon_steps,
               "GT_TOL": repr(s.tol), "GT_HARDNESS0": repr(e.hardness_est),
               "GT_TARGET_P80_UM": repr(float(s.target_p80_um)), "GT_P80_GAIN": repr(float(e.p80_gain)),
               "GT_P80_REFERENCE_UM": repr(float(e.p80_reference_um or 0.0)), "GT_PASSING_TARGET": repr(PASSING_TARGET),
               "GT_BLEND_SUM_TOL": repr(blend_sum_tolerance(c.nd - 1)),
               "GT_UNREACHABLE_TOL": repr(float(s.unreachable_tol_frac)),
               "GT_GRID_RATIO": repr(float(c.model.spec.grid.ratio)), "GT_FEED_MAX_TPH": _c_value(feed_max_tph)}
    du_max = np.array([s.feed_rate_max_tph_per_h, s.speed_rate_max_per_h]) * s.dt_h
    arrays = {"gt_x_scale": c.x_scale, "gt_u_lo": [s.feed_tph_min, s.speed_min],
              "gt_u_hi": [s.feed_tph_max, s.speed_max], "gt_du_max": du_max, "gt_wpass": c._wpass,
              "gt_upper_um": c.model.spec.grid.upper_um,
              "gt_z0": e.z, "gt_p0": e.P, "gt_u0": u0,
              "gt_y_lo": measurement_range[0], "gt_y_hi": measurement_range[1]}
    return scalars, arrays


def _c_value(v) -> str:
    v = float(v)
    return "INFINITY" if v == math.inf else ("-INFINITY" if v == -math.inf else repr(v))


def exported_source(controller, estimator, u0, preview_lead_h: float | None, measurement_range, feed_max_tph) -> str:
    """gt_exported.c: the header's constants as the QP's and the EKF's data were generated with them, for
    gt_controller_check_abi to compare the library's gt_controller_config.h with (GT_ABI_CONFIG_EDITED:
    an edited header compiled, ran and was ignored by the QP, whose bounds, scales and target weights
    are in gt_rti_data.c)."""
    scalars, arrays = _constants(controller, estimator, u0, preview_lead_h, measurement_range, feed_max_tph)
    values = [str(v).removesuffix("UL") for v in scalars.values() if v is not None]
    values += [_c_value(v) for name in CHECKED_ARRAYS for v in np.asarray(arrays[name], float).ravel(order="F")]
    return ("/* generated by grindtwin export-controller: gt_controller_config.h's constants as exported, in the\n"
            " * order of its GT_CONFIG_SCALARS and then its arrays; the library refuses a header that differs\n"
            " * (gt_controller_check_abi: GT_ABI_CONFIG_EDITED): change the scene and export again */\n"
            "#include <math.h>\n\n"
            f"const int gt_exported_constants_len = {len(values)};\n"
            f"const double gt_exported_constants[{len(values)}] = {{{', '.join(values)}}};\n")


def config_header(controller, estimator, u0, preview_lead_h: float | None, measurement_range, feed_max_tph) -> str:
    """gt_controller_config.h: dimensions, the ABI hash, the preview's lead, scales, bounds, the
    measurements' physical ranges and the initial estimate."""
    sc, ar = _constants(controller, estimator, u0, preview_lead_h, measurement_range, feed_max_tph)
    layout = abi_layout(controller, estimator, preview_lead_h)
    names = list(sc)
    dims = names[:names.index("GT_RTI_ITERATIONS") + 1]
    if sc["GT_PREVIEW_LEAD_H"] is None:
        lead = ["/* GT_PREVIEW_LEAD_H: not given to the export (mpc.export_controller's preview_lead_h) */"]
    else:
        lead = [f"#define GT_PREVIEW_LEAD_H {sc['GT_PREVIEW_LEAD_H']}"]
    abi = ["/* the layout the caller's buffers follow (gt_controller.h: GT_CONTROLLER_CHECK_ABI): y holds",
           f" * {', '.join(layout['measurements'])}; u {', '.join(layout['inputs'])}; blend and each preview stage",
           f" * the fractions of {', '.join(layout['components'])}, in this order; GT_ABI_HASH hashes it all with",
           " * GT_DT_H and GT_PREVIEW_LEAD_H (when to call, what each preview stage holds; mpc.export.abi_layout,",
           " * in the manifest) */",
           f"#define GT_API_VERSION {sc['GT_API_VERSION']}", f"#define GT_NY {sc['GT_NY']}",
           "#define GT_PREVIEW_LEN (GT_NB * GT_N)", f"#define GT_ABI_HASH {sc['GT_ABI_HASH']}",
           "/* the sample period [h]; the preview's lead [h]: the feed blend is known this far ahead",
           " * (scene controller.preview_lead_h), stage k of the preview is the blend at t + min(k GT_DT_H,",
           " * GT_PREVIEW_LEAD_H) (gt_controller.h, gt_controller_step) */",
           f"#define GT_DT_H {sc['GT_DT_H']}", *lead,
           "/* gt_controller_estimate's times: t_h - the last t_h within GT_DT_TOL x GT_DT_H of k GT_DT_H (a task's",
           " * jitter; mpc.export.SAMPLE_TIME_TOL), k from 1 to GT_MAX_PREDICT_PERIODS (the horizon's stages: a",
           " * longer gap left the loop without the controller longer than it plans ahead), else",
           " * GT_ESTIMATE_BAD_TIME */",
           f"#define GT_DT_TOL {sc['GT_DT_TOL']}", f"#define GT_MAX_PREDICT_PERIODS {sc['GT_MAX_PREDICT_PERIODS']}"]
    checked = [k for k, v in sc.items() if v is not None]
    lines = ["/* generated by grindtwin export-controller: the controller's dimensions and constants, exported with",
             " * the QP's and the EKF's data (gt_rti_data.c, gt_ekf_data.c). Not tuning: an edit would not reach",
             " * that data, and the library refuses an edited header (gt_controller.h: GT_ABI_CONFIG_EDITED); to",
             " * change a value, change the scene and export again */",
             "#ifndef GT_CONTROLLER_CONFIG_H", "#define GT_CONTROLLER_CONFIG_H", "#include <math.h>", ""]
    lines += [f"#define {k} {sc[k]}" for k in dims] + abi
    lines += [f"#define GT_TOL {sc['GT_TOL']}", f"#define GT_HARDNESS0 {sc['GT_HARDNESS0']}",
              "/* the P80 target [um]; the analyser reads ref + gain (P80_model - ref) + bias (mpc.estimator) */",
              f"#define GT_TARGET_P80_UM {sc['GT_TARGET_P80_UM']}", f"#define GT_P80_GAIN {sc['GT_P80_GAIN']}",
              f"#define GT_P80_REFERENCE_UM {sc['GT_P80_REFERENCE_UM']}",
              "/* GT_STEP_TARGET_UNREACHABLE: the plan's passing fraction at the horizon end differs from",
              " * GT_PASSING_TARGET by more than GT_UNREACHABLE_TOL (mpc.Controller.make_step's rule) */",
              f"#define GT_PASSING_TARGET {sc['GT_PASSING_TARGET']}",
              "/* a blend's fractions may sum this far from 1 (twin.ore.blend_sum_tolerance of GT_NB ores) */",
              f"#define GT_BLEND_SUM_TOL {sc['GT_BLEND_SUM_TOL']}",
              f"#define GT_UNREACHABLE_TOL {sc['GT_UNREACHABLE_TOL']}", "",
              "/* state scales, input bounds, largest move per sample, passing weights of the target */",
              *[_c_array(k, ar[k]) for k in ("gt_x_scale", "gt_u_lo", "gt_u_hi", "gt_du_max", "gt_wpass")],
              "/* the size grid's class upper sizes [um] and ratio, for the passing weights of a biased target */",
              _c_array("gt_upper_um", ar["gt_upper_um"]), f"#define GT_GRID_RATIO {sc['GT_GRID_RATIO']}",
              "/* the estimator's initial augmented state and covariance (column-major), the initial input */",
              *[_c_array(k, ar[k]) for k in ("gt_z0", "gt_p0", "gt_u0")],
              f"/* the physical range of each measurement of y ({', '.join(MEASUREMENTS)}; ends included, in its",
              " * units): a value outside is not used (GT_ESTIMATE_IMPLAUSIBLE) */",
              *[_c_array(k, ar[k]) for k in ("gt_y_lo", "gt_y_hi")],
              "/* the applied feed's physical limit [t/h]: above, the estimate refuses it (GT_ESTIMATE_BAD_INPUT) */",
              f"#define GT_FEED_MAX_TPH {sc['GT_FEED_MAX_TPH']}",
              "/* the scalars gt_exported.c lists first, in its order (then the arrays above, in the order of",
              " * mpc.export.CHECKED_ARRAYS) */",
              f"#define GT_CONFIG_SCALARS {{{', '.join(checked)}}}", "", "#endif", ""]
    return "\n".join(lines)


def _generate(fns, name: str, folder: Path) -> None:
    gen = ca.CodeGenerator(f"{name}.c", {"with_header": True})
    for fn in fns:
        gen.add(fn)
    gen.generate(str(folder) + "/")


def _previous_export(out: Path) -> dict:
    """The manifest of the previous export in ``out``; MpcInputError if ``out`` holds anything else."""
    man = out / MANIFEST
    if not man.is_file():
        raise MpcInputError(f"--out {out}: the folder is not empty and holds no {MANIFEST} (not an "
                            f"export of ours); choose an empty or new folder.")
    try:
        data = json.loads(man.read_text())
        listed = set(data.get("files", [])) | set(data.get("build_products", []))
        hashes = dict(data.get("sha256", {}))
    except (ValueError, AttributeError, TypeError):
        raise MpcInputError(f"--out {out}: its {MANIFEST} is not one this export wrote (not readable as an "
                            "export's file list); choose another folder.") from None
    # an export writes no folder: one of a listed name is the user's (it would be deleted whole)
    foreign = sorted(p.name for p in out.iterdir() if p.name not in listed or p.is_dir() or p.is_symlink())
    if foreign:
        raise MpcInputError(f"--out {out}: holds files this export did not write ({', '.join(foreign[:5])}); "
                            f"move them away or choose another folder.")
    # a source edited since is the user's work: not replaced
    edited = sorted(name for name, digest in hashes.items() if (out / name).is_file() and file_sha256(out / name) != digest)
    if edited:
        raise MpcInputError(f"--out {out}: {', '.join(edited[:5])} changed since the export wrote "
                            f"{'it' if len(edited) == 1 else 'them'}; keep your changes elsewhere or choose "
                            "another folder.")
    return data


def check_out_dir(out) -> None:
    """Refuse a folder that is not empty and not a previous export (nothing written): the current
    folder or one of its parents, a link, a file in the path, files the export did not write, or
    a source file changed since the export wrote it (its sha256 in the manifest)."""
    out = Path(out)
    if out.is_symlink():  # an export replaces the folder as a whole: the link would be in the way
        raise MpcInputError(f"--out {out}: is a symbolic link (to {os.readlink(out)}); give the folder itself.")
    if any(p.exists() and not p.is_dir() for p in (out, *out.parents)):
        raise MpcInputError(f"--out {out}: {next(p for p in (out, *out.parents) if p.exists() and not p.is_dir())} "
                            "exists and is not a folder.")
    here, target = Path.cwd().resolve(), out.resolve()
    if target == here or target in here.parents:  # "." was emptied and its rename failed (exit 1)
        raise MpcInputError(f"--out {out}: is the current folder or one of its parents, which the export would "
                            "have to replace; give a folder of its own.")
    if out.is_dir() and any(out.iterdir()):
        _previous_export(out)


def _replace(out: Path, partial: Path) -> None:
    """Put ``partial`` in place of ``out`` (:func:`twin.atomic.replace_folder`) with ``out``'s permissions:
    an empty folder or a previous export there is moved aside first and removed only by the names its
    manifest lists; one holding anything else is left, hidden beside DIR, rather than deleted."""
    names = []
    if out.exists():
        # an empty folder (the README's "DIR new, empty or a previous export") was refused here as "not empty"
        if any(out.iterdir()):
            data = _previous_export(out)  # again, just before: nothing of the user's arrived meanwhile
            names = set(data.get("files", [])) | set(data.get("build_products", []))
        os.chmod(partial, stat.S_IMODE(out.stat().st_mode))  # the folder's permissions stay the user's
    replace_folder(out, partial, names)


#: The first words of an export's lock file (``.DIR.export.lock`` beside ``DIR``): a file of that
#: name without them is not ours, refused and never written.
LOCK_TAG = "grindtwin export-controller lock"
_HELD: dict[str, list] = {}  # lock path -> [thread id, depth]: re-entered by the thread holding it
_HELD_GUARD = threading.Lock()


def lock_path(out) -> Path:
    """The lock file of an export to ``out``: ``.DIR.export.lock`` in its parent folder (not in
    ``out``, which an export replaces as a whole)."""
    out = Path(out)
    return out.parent / f".{out.name}.export.lock"


def _lock(path: Path, out: Path) -> int:
    """The open, flocked lock file ``path`` (:func:`twin.atomic.acquire_lock`); MpcInputError if
    another process holds it or it is not ours (left as it was)."""
    try:
        return acquire_lock(path, LOCK_TAG)
    except LockError as exc:
        if exc.busy:
            holder = exc.text[len(LOCK_TAG):].strip() or "?"
            raise MpcInputError(f"--out {out}: another export-controller to this folder is running ({holder}, "
                                f"lock {path}); wait for it to end or choose another folder.") from None
        raise MpcInputError(f"--out {out}: {path} is in the way (not the lock file of a grindtwin export, "
                            "which it would be); move it away or choose another folder.") from None


@contextlib.contextmanager
def export_lock(out):
    """Hold the lock of an export to ``out`` (:func:`lock_path`, ``fcntl.flock``, exclusive): a
    second export to the same folder, from another process or thread, is refused at once
    (MpcInputError naming the folder) rather than mixing its files with this one's. Re-entered by
    the thread holding it (the CLI locks before it builds the models, :func:`export_controller`
    again). The folder is checked first (:func:`check_out_dir`: a refused one gets no lock file);
    missing parents of ``out`` are created, and removed again at the end if still empty. The lock
    file is removed when the export ends, well or not; after a killed export it stays, unlocked
    (the kernel drops a flock with its process), and the next export takes it over and removes it.
    """
    out = Path(out)
    check_out_dir(out)
    path = lock_path(out)
    key = str(path.parent.resolve() / path.name)
    me = threading.get_ident()
    with _HELD_GUARD:
        held = _HELD.get(key)
        if held is not None and held[0] != me:
            raise MpcInputError(f"--out {out}: another export-controller to this folder is running in this "
                                f"process (lock {path}); wait for it to end or choose another folder.")
        if held is not None:
            held[1] += 1
    if held is not None:
        try:
            yield path
        finally:
            with _HELD_GUARD:
                held[1] -= 1
        return
    made = [p for p in out.parents if not p.exists()]  # removed again at the end if still empty
    fd = None
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fd = _lock(path, out)
        with _HELD_GUARD:
            _HELD[key] = [me, 0]
        yield path
    finally:
        if fd is not None:
            with _HELD_GUARD:
                _HELD.pop(key, None)
            release_lock(path, fd)
        for p in made:  # deepest first; only if empty (a failed export's, or nothing was written)
            try:
                p.rmdir()
            except OSError:
                break


def export_controller(controller, estimator, u0, out_dir, source: str = "",
                      preview_lead_h: float | None = None, *, measurement_range, feed_max_tph: float,
                      built_from: dict | None = None) -> list[str]:
    """Write the controller and its estimator as C into ``out_dir`` (module docstring); returns
    the names of the files written. ``u0``: the input applied before the first step.
    ``preview_lead_h``: how far ahead [h] the loop knows the feed blend (the scene's
    ``controller.preview_lead_h``; None: not stated),
    exported as GT_PREVIEW_LEAD_H and in the manifest, for the DCS to fill the preview the same way.
    ``measurement_range``: ``(low, high)``, each the 3 values of the measurements (p80_um, power_kw,
    load_frac) in their units, ends included: the physically possible ones (a scene's:
    :func:`scenarios.scene.physical.physical_limits`); the exported estimate does not use a measurement
    outside (GT_ESTIMATE_IMPLAUSIBLE: a P80 in mm was taken for one in um and drove the feed to its bound).
    ``(-inf, inf)`` each checks nothing. ``feed_max_tph``: the applied feed's physical limit [t/h] (> 0,
    inf: none; a scene's ``physical_limits("feed_tph", scene)``), above which the exported estimate
    refuses the input (a feed in kg/h or t/d emptied the estimated mill).
    A speed bound beyond what the twin's models describe (:func:`mpc.nmpc.speed_max_note`) is
    exported with a note: warned (:class:`mpc.errors.OutsideModelsWarning`) and in the manifest's
    ``notes``. ``built_from``: what the controller was built from (JSON-able; a scene's:
    :func:`scenarios.run.closed_loop.export_provenance`), in the manifest as is.
    The export holds :func:`export_lock` on ``out_dir`` throughout."""
    measurement_range, notes = _checked_inputs(controller, estimator, preview_lead_h, measurement_range, feed_max_tph)
    out = Path(out_dir)
    with export_lock(out):
        files = _export(controller, estimator, u0, out, source, preview_lead_h, measurement_range, feed_max_tph,
                        notes, built_from)
    for note in notes:
        warnings.warn(note, OutsideModelsWarning, stacklevel=2)
    return files


def _checked_inputs(controller, estimator, preview_lead_h, measurement_range, feed_max_tph) -> tuple[np.ndarray, list]:
    """export_controller's arguments checked (MpcInputError naming one): the measurement range as an array,
    and the notes the export carries."""
    _check(controller, estimator)
    if preview_lead_h is not None and not (isinstance(preview_lead_h, (int, float)) and math.isfinite(preview_lead_h)
                                           and preview_lead_h >= 0):
        raise MpcInputError(f"The 'preview_lead_h' parameter of export_controller must be a float >= 0 [h]. "
                            f"Got {preview_lead_h!r}.")
    measurement_range = _measurement_range(measurement_range)
    if not (isinstance(feed_max_tph, (int, float)) and feed_max_tph > 0):  # NaN fails too
        raise MpcInputError(f"The 'feed_max_tph' parameter of export_controller must be a number > 0 [t/h] (inf: no "
                            f"limit). Got {feed_max_tph!r}.")
    return measurement_range, [n for n in [speed_max_note(controller.settings)] if n]


def _measurement_range(value) -> np.ndarray:
    """export_controller's ``measurement_range`` as a 2 x 3 array; MpcInputError naming it unless each of
    ``low`` and ``high`` is 3 numbers, not NaN, with ``low <= high``."""
    try:
        r = np.asarray(value, float)
    except (TypeError, ValueError):
        r = None
    if r is None or r.shape != (2, len(MEASUREMENTS)) or np.isnan(r).any() or not np.all(r[0] <= r[1]):
        raise MpcInputError(f"The 'measurement_range' parameter of export_controller must be (low, high), each "
                            f"{len(MEASUREMENTS)} numbers ({', '.join(MEASUREMENTS)}) with low <= high "
                            f"(-inf, inf: no check). Got {value!r}.")
    return r


def _export(controller, estimator, u0, out: Path, source: str, preview_lead_h, measurement_range, feed_max_tph,
            notes, built_from) -> list[str]:
    check_out_dir(out)  # again, under the lock
    partial = new_folder_beside(out)
    try:
        constants = (controller, estimator, u0, preview_lead_h, measurement_range, feed_max_tph)
        _write_sources(partial, *constants)
        manifest = _manifest(partial, controller, estimator, preview_lead_h, measurement_range, feed_max_tph, source,
                             notes, built_from)
        files = manifest["files"]
        # no check (an infinite range or feed limit) is the text inf, as summary.json's: Infinity is no JSON
        (partial / MANIFEST).write_text(json_text(manifest, indent=2) + "\n")
        _replace(out, partial)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    return files


def _write_sources(folder: Path, controller, estimator, u0, preview_lead_h, measurement_range, feed_max_tph) -> None:
    """Every file of an export but its manifest, written into ``folder``."""
    _generate([*stage_functions(controller), plan_passing_function(controller)], "gt_rti_data", folder)
    _generate([estimator.step_function], "gt_ekf_data", folder)
    for name in C_FILES:
        shutil.copyfile(C_DIR / name, folder / name)
    constants = (controller, estimator, u0, preview_lead_h, measurement_range, feed_max_tph)
    (folder / "gt_controller_config.h").write_text(config_header(*constants))
    (folder / "gt_exported.c").write_text(exported_source(*constants))
    (folder / "Makefile").write_text(MAKEFILE)


def _manifest(folder: Path, controller, estimator, preview_lead_h, measurement_range, feed_max_tph, source, notes,
              built_from) -> dict:
    """The manifest of the sources written into ``folder`` (:func:`_write_sources`)."""
    files = sorted(p.name for p in folder.iterdir()) + [MANIFEST]
    s, layout = controller.settings, abi_layout(controller, estimator, preview_lead_h)
    return {"source": source, "built_from": built_from, "casadi": ca.__version__, "files": files,
            "build_products": list(BUILD_PRODUCTS),
            "horizon_steps": s.horizon_steps, "dt_h": s.dt_h, "dt_tol_frac": SAMPLE_TIME_TOL,
            "n_x": controller.nx,
            "preview": bool(s.preview), "preview_lead_h": preview_lead_h,
            "measurement_range": {name: [float(lo), float(hi)] for name, lo, hi
                                  in zip(MEASUREMENTS, *measurement_range)},
            "feed_max_tph": float(feed_max_tph),
            "abi": {"hash": f"0x{abi_hash(layout):08x}", "layout": layout},
            "estimator_state": int(estimator.z.size), "disturbance_model": estimator.disturbance_model,
            "api": "gt_controller.h", "build": "make",
            "step_status": {str(k): v for k, v in STEP_STATUS.items()},
            "estimate_status": {str(k): v for k, v in ESTIMATE_STATUS.items()},
            "unreachable_tol_frac": float(s.unreachable_tol_frac), "notes": notes,
            "sha256": {name: file_sha256(folder / name) for name in files if name != MANIFEST}}


class ExportDifference(NamedTuple):
    """What differs between an export and what would be exported now (:func:`check_export`): the item
    (a manifest key path such as ``built_from.calibration.sha256``, a constant of gt_controller_config.h,
    a file in the folder), its recorded value, its current one, and whether it makes the export stale
    (False: a note, such as where the scene file was)."""
    item: str
    recorded: object
    current: object
    stale: bool = True


_ABSENT = "(absent)"
_DEFINE = re.compile(r"^#define (GT_\w+) (.*)$", re.M)
_ARRAY = re.compile(r"^static const double (gt_\w+)\[\d+\] = \{(.*)\};$", re.M)


def recorded_export(out_dir, again: str = "export it again") -> dict:
    """The manifest of the export in ``out_dir``, with what it was built from (``built_from``);
    MpcInputError saying so, and how to export (``again``), for a folder that holds no export, a
    manifest that is not an export's, or one without ``built_from`` (an export made before the
    manifest recorded it, or by :func:`export_controller` without it: nothing to compare)."""
    out = Path(out_dir)
    if not out.is_dir():
        raise MpcInputError(f"--check {out}: {'is not a folder' if out.exists() else 'no such folder'}; give the "
                            f"folder an export was written to ({again}).")
    man = out / MANIFEST
    if not man.is_file():
        raise MpcInputError(f"--check {out}: holds no {MANIFEST}, so no export of grindtwin export-controller; "
                            f"export into it first ({again}).")
    try:
        data = json.loads(man.read_text())
        ok = isinstance(data, dict) and isinstance(data.get("sha256"), dict)
    except (OSError, ValueError) as exc:
        raise MpcInputError(f"--check {out}: its {MANIFEST} is not readable ({exc}); export again ({again}).") from None
    if not ok:
        raise MpcInputError(f"--check {out}: its {MANIFEST} is not an export's manifest (no sha256 of its files); "
                            f"export again ({again}).")
    if not isinstance(data.get("built_from"), dict):
        raise MpcInputError(f"--check {out}: its {MANIFEST} does not record what the export was built from (no "
                            "built_from: an export made before the manifest recorded it, or by "
                            "mpc.export_controller without built_from), so it cannot be compared; export again "
                            f"({again}) and check that export.")
    return data


def check_export(out_dir, controller, estimator, u0, preview_lead_h: float | None = None, *, measurement_range,
                 feed_max_tph: float, built_from: dict | None, source: str = "", note_items=("source", "casadi"),
                 again: str = "export it again") -> list[ExportDifference]:
    """What differs between the export in ``out_dir`` and what :func:`export_controller` would write
    there now with these arguments (empty: it is current); nothing is written to ``out_dir``.
    Compared: every item of the manifest (``built_from`` and each file's sha256 among them) with the
    manifest the export would write, its files regenerated in a temporary folder (CasADi's code
    generated, not compiled); each file in ``out_dir`` with its sha256 in the manifest (an edit since
    the export); and the constants of the folder's gt_controller_config.h with the regenerated ones,
    by name. Items in ``note_items`` (and under them) are reported as notes, not stale.
    MpcInputError for a folder without an export or a manifest without ``built_from``
    (:func:`recorded_export`)."""
    out = Path(out_dir)
    recorded = recorded_export(out, again)
    measurement_range, notes = _checked_inputs(controller, estimator, preview_lead_h, measurement_range, feed_max_tph)
    constants = (controller, estimator, u0, preview_lead_h, measurement_range, feed_max_tph)
    with tempfile.TemporaryDirectory(prefix="grindtwin-export-check-") as tmp:
        _write_sources(Path(tmp), *constants)
        current = _manifest(Path(tmp), controller, estimator, preview_lead_h, measurement_range, feed_max_tph,
                            source, notes, built_from)
        header = (Path(tmp) / "gt_controller_config.h").read_text()
    current = json.loads(json_text(current))  # as the manifest reads back (lists, not tuples; inf as text)
    found = _differences(recorded, current, "", tuple(note_items))
    for name, digest in recorded["sha256"].items():
        path = out / name
        now = file_sha256(path) if path.is_file() else _ABSENT
        if now != digest:
            found.append(ExportDifference(f"{name} in the folder (sha256; changed since the export)", digest, now))
    cfg = out / "gt_controller_config.h"
    if cfg.is_file():  # by name: the numbers behind a file's sha256 (an edited header's are the user's)
        edited = file_sha256(cfg) != recorded["sha256"].get(cfg.name)
        found += _header_differences(cfg.read_text(), header, " (as edited in the folder)" if edited else "")
    return found


def _same(a, b) -> bool:
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)  # NaN equals NaN, as in the file


def _differences(recorded, current, item: str, note_items: tuple) -> list[ExportDifference]:
    """The leaves that differ between two JSON values, dicts by key and lists of one length by index."""
    if isinstance(recorded, dict) and isinstance(current, dict):
        keys = [*recorded, *(k for k in current if k not in recorded)]
        return [d for k in keys for d in _differences(recorded.get(k, _ABSENT), current.get(k, _ABSENT),
                                                      f"{item}.{k}" if item else str(k), note_items)]
    if isinstance(recorded, list) and isinstance(current, list) and len(recorded) == len(current):
        return [d for i, (a, b) in enumerate(zip(recorded, current))
                for d in _differences(a, b, f"{item}[{i}]", note_items)]
    if _same(recorded, current):
        return []
    note = any(item == n or item.startswith((f"{n}.", f"{n}[")) for n in note_items)
    return [ExportDifference(item, recorded, current, stale=not note)]


def _header_constants(text: str) -> dict:
    """gt_controller_config.h's macros (name -> text) and arrays (name -> the values' texts)."""
    out = {name: value.strip() for name, value in _DEFINE.findall(text)}
    out.update({name: [v.strip() for v in values.split(",")] for name, values in _ARRAY.findall(text)})
    return out


def _header_differences(recorded_text: str, current_text: str, where: str = "") -> list[ExportDifference]:
    """The constants of two gt_controller_config.h texts that differ, by name (an array: its first differing
    value, with how many more differ); ``where`` follows the file's name in each item."""
    rec, cur = _header_constants(recorded_text), _header_constants(current_text)
    found = []
    for name in [*rec, *(k for k in cur if k not in rec)]:
        a, b = rec.get(name, _ABSENT), cur.get(name, _ABSENT)
        if a == b:
            continue
        item = f"gt_controller_config.h{where} {name}"
        if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
            idx = [i for i, (x, y) in enumerate(zip(a, b)) if x != y]
            more = f" (and {len(idx) - 1} more of {len(a)})" if len(idx) > 1 else ""
            found.append(ExportDifference(f"{item}[{idx[0]}]{more}", a[idx[0]], b[idx[0]]))
        elif isinstance(a, list) or isinstance(b, list):
            found.append(ExportDifference(item, *(f"{len(v)} values" if isinstance(v, list) else v for v in (a, b))))
        else:
            found.append(ExportDifference(item, a, b))
    return found
