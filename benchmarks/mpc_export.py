"""The exported C controller (``grindtwin export-controller``) against the Python controller on
the reference scene's whole 8-hour transition, in lock-step.

The scene's closed loop runs in Python (plant twin, sensors, EKF, NMPC with qpsol "condensed",
compiled); every estimator and controller call is also sent, as it happens, to the exported
controller's replay harness (gt_replay, built by the export's Makefile with -O2, run under the
LD_PRELOAD allocation counter gt_malloc_count.so) through a pipe, so the two sides' steps
alternate (Python, C, Python, C, ...). Recorded: the largest relative difference of the moves,
the steps each side found the target unreachable (the C step's GT_STEP_TARGET_UNREACHABLE, a
solved step, not a failed one), the C step's wall time (median, p95, worst; measured inside
gt_replay), the Python step's (make_step), allocations inside the C calls after
gt_controller_new, and the bytes it allocates.

Writes benchmarks/results/mpc_export.csv and .md (``--tag T``: mpc_exportT.csv, .md).

    PYTHONPATH=. python benchmarks/mpc_export.py [--tag T]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from mpc import codegen
from scenarios.cli import main as grindtwin
from scenarios.run import closed_loop, run_scene
from scenarios.scene import load_scene
from dem_common import TAG

#: gt_controller_step's statuses of a solved step (mpc/c/gt_controller.h): GT_STEP_OK,
#: GT_STEP_TARGET_UNREACHABLE (the plan misses the target at the horizon end, applied all the same) and
#: GT_STEP_INPUT_PROJECTED (planned from the applied input projected onto the bounds)
C_TARGET_UNREACHABLE = 5
C_SOLVED = (0, C_TARGET_UNREACHABLE, 6)

OUT = Path(__file__).parent / "results"
SCENE = Path(__file__).parents[1] / "scenarios" / "reference_transition.toml"


class Mirror:
    """Wraps the loop's EKF or NMPC; each call is mirrored to the C harness right after."""

    def __init__(self, inner, proc, kind, rows):
        self._inner, self._proc, self._kind, self._rows = inner, proc, kind, rows
        self.estimates = 0

    def __getattr__(self, name):
        return getattr(self._inner, name)

    def make_step(self, *args, **kwargs):
        t0, c0 = time.perf_counter(), time.thread_time()
        out = self._inner.make_step(*args, **kwargs)
        py_s, py_cpu = time.perf_counter() - t0, time.thread_time() - c0
        if self._kind == "E":
            y, u, d = args
            # the loop estimates once a sample from the warm-up on: the estimate's time, samples counted
            t_h, self.estimates = self.estimates * self._inner.dt_h, self.estimates + 1
            vals = [t_h, *y, *u, *np.asarray(d)[: self._inner.nd - 1]]
            self._proc.stdin.write("E " + " ".join(repr(float(v)) for v in vals) + "\n")
            self._proc.stdin.flush()
            return out
        _, preview, u_prev = args[:3]
        vals = [*u_prev, *np.asarray(preview)[:-1, :].ravel(order="F")]
        self._proc.stdin.write("C " + " ".join(repr(float(v)) for v in vals) + "\n")
        self._proc.stdin.flush()
        _, st, uf, us, it, c_s, c_cpu, _qp = self._proc.stdout.readline().split()
        self._rows.append({"python_feed": out.u_applied[0], "python_speed": out.u_applied[1],
                           "python_target_unreachable": out.status.startswith("target_unreachable"),
                           "c_feed": float(uf), "c_speed": float(us), "c_status": int(st),
                           "c_qp_iterations": int(it), "c_step_s": float(c_s), "c_step_cpu_s": float(c_cpu),
                           "python_step_s": py_s, "python_step_cpu_s": py_cpu,
                           "load_1min": os.getloadavg()[0]})
        return out


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tag", default="", type=TAG, help="suffix of the result files (mpc_export{TAG}.md, .csv)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "ctl"
        t0 = time.perf_counter()
        if grindtwin(["export-controller", str(SCENE), "--out", str(out)]) != 0:
            raise SystemExit("export-controller failed")
        export_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        subprocess.run(["make", "-j2", "-C", str(out), "CFLAGS=-O2", f"CC={codegen.find_compiler()}"],
                       check=True, capture_output=True)
        make_s = time.perf_counter() - t0
        env = dict(os.environ, LD_PRELOAD=str(out / "gt_malloc_count.so"))
        proc = subprocess.Popen([str(out / "gt_replay")], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                text=True, env=env)
        rows: list[dict] = []
        real = closed_loop.nmpc_parts

        def mirrored(*a, **k):
            est, ctrl = real(*a, **k)
            return Mirror(est, proc, "E", rows), Mirror(ctrl, proc, "C", rows)

        closed_loop.nmpc_parts = mirrored
        mode = os.environ.get(codegen.MODE_ENV)
        os.environ[codegen.MODE_ENV] = "on"
        try:
            run_scene(load_scene(SCENE), progress=False)
        finally:
            closed_loop.nmpc_parts = real
            if mode is None:
                os.environ.pop(codegen.MODE_ENV)
            else:
                os.environ[codegen.MODE_ENV] = mode
        tail, _ = proc.communicate()
        info = dict(line.split() for line in tail.strip().splitlines())
    fr = pd.DataFrame(rows)
    rel = np.max(np.abs(fr[["c_feed", "c_speed"]].to_numpy() / fr[["python_feed", "python_speed"]].to_numpy() - 1))
    table = pd.DataFrame([{
        "steps": len(fr), "move_rel_diff_max": rel, "c_failed_steps": int((~fr.c_status.isin(C_SOLVED)).sum()),
        "c_target_unreachable_steps": int((fr.c_status == C_TARGET_UNREACHABLE).sum()),
        "python_target_unreachable_steps": int(fr.python_target_unreachable.sum()),
        "c_step_median_s": fr.c_step_s.median(), "c_step_p95_s": fr.c_step_s.quantile(0.95),
        "c_step_max_s": fr.c_step_s.max(), "c_step_cpu_median_s": fr.c_step_cpu_s.median(),
        "c_step_cpu_max_s": fr.c_step_cpu_s.max(), "python_step_median_s": fr.python_step_s.median(),
        "python_step_cpu_median_s": fr.python_step_cpu_s.median(),
        "python_over_c_cpu_median": (fr.python_step_cpu_s / fr.c_step_cpu_s).median(),
        "c_qp_iterations_max": int(fr.c_qp_iterations.max()),
        "c_estimates_not_ok": int(info["R"]),
        "c_allocations_in_steps": int(info["M"]), "c_bytes_allocated_by_new": int(info["B"]),
        "export_s": export_s, "make_O2_s": make_s, "load_1min_median": fr.load_1min.median()}])
    print(table.T, flush=True)
    OUT.mkdir(exist_ok=True)
    table.to_csv(OUT / f"mpc_export{args.tag}.csv", index=False)
    load = os.getloadavg()
    md = ["# The exported C controller against the Python controller (reference scene, 8 h, lock-step)", "",
          "Python closed loop (plant twin, sensors, EKF, NMPC with qpsol \"condensed\", compiled) with every "
          "estimator and controller call mirrored to the export's gt_replay (gcc -O2) through a pipe as it "
          "happens (Python, C, Python, C, ...). `c_failed_steps`: C steps that solved no QP (a fallback or a "
          "refused input); `c_estimates_not_ok`: C estimates whose status was not GT_ESTIMATE_OK (a refused "
          "time, input or an implausible measurement); "
          "`*_target_unreachable_steps`: steps whose plan misses the target at the horizon "
          "end, C and Python by the same rule (solved, applied). `c_step`: wall time of gt_controller_step "
          "measured inside C (`_cpu`: the process's CPU time over it); `python_step`: make_step (`_cpu`: the "
          "thread's CPU time). "
          "The C harness sleeps on its pipe between steps (as a DCS task would) and is scheduled at once when "
          "woken, while the Python process also integrates the plant: under load the wall times differ by more "
          "than the work, the CPU times are the comparison. `c_allocations_in_steps`: malloc/calloc/realloc calls inside "
          "gt_controller_estimate and gt_controller_step after gt_controller_new (LD_PRELOAD counter); "
          "`c_bytes_allocated_by_new`: its two blocks (controller with the EKF's work; QP data and solver work). "
          f"Load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1/5/15 min) on 2 shared cores.",
          "", table.T.rename(columns={0: "value"}).to_markdown(floatfmt=".4g"), "",
          "Reproduce: `PYTHONPATH=. python benchmarks/mpc_export.py" + (f" --tag {args.tag}`." if args.tag else "`.")]
    (OUT / f"mpc_export{args.tag}.md").write_text("\n".join(md) + "\n")
    return table


if __name__ == "__main__":
    main()
