"""HPIPM on the real-time iteration's QPs with and without the controller's primal regularisation
(mpc.nmpc.HPIPM_REG_PRIM), and in its other modes: failures, iterations, time, and how far each
solution is from qpOASES' (an active-set method, an independent reference).

The QPs are those the RTI solved in closed loops: the reference transition (the reference scene's
controller model, lock-step as benchmarks/mpc_compiled.py, the condensed controller driving the
plant) at each ``--horizons``, and the coarse industrial twin of the test suite (10 classes, B and
D, a power limit and move blocking at horizons 4, 6 and 10, as tests/mpc/test_codegen.py), plus
the QP kept in tests/mpc/data on which the robust mode once stalled. Every QP is solved by every
configuration in turn (A, B, C, ... per QP).

Writes benchmarks/results/mpc_hpipm_regularisation.csv and .md.

    PYTHONPATH=. python benchmarks/mpc_hpipm_regularisation.py [--horizons 4] [--duration-h 8]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import casadi as ca
import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from mpc_compiled import lockstep, reference_sensors, reference_setup, settings  # noqa: E402

from mpc import Controller, NmpcSettings  # noqa: E402
from mpc.nmpc import HPIPM_INF, HPIPM_REG_PRIM  # noqa: E402
from mpc.qpsol import conic  # noqa: E402
from twin import DEFAULT_EFFECTS, SizeGrid, Twin  # noqa: E402

OUT = Path(__file__).parent / "results"
STALLED_QP = Path(__file__).parent.parent / "tests" / "mpc" / "data" / "hpipm_semidefinite_qp.npz"
#: HPIPM's own primal regularisation (its ``reg_prim`` in every mode)
HPIPM_DEFAULT_REG = 1e-15
CONFIGS = {"robust, HPIPM's reg_prim": {"mode": "robust", "reg_prim": HPIPM_DEFAULT_REG},
           "robust, HPIPM_REG_PRIM": {"mode": "robust", "reg_prim": HPIPM_REG_PRIM},
           "balance, HPIPM's reg_prim": {"mode": "balance", "reg_prim": HPIPM_DEFAULT_REG},
           "speed, HPIPM's reg_prim": {"mode": "speed", "reg_prim": HPIPM_DEFAULT_REG}}
#: Largest QP solved by dense qpOASES for the reference solution (larger: no reference)
REFERENCE_MAX_N = 600


def recording(controller: Controller, case: str, qps: list) -> None:
    """Make ``controller`` append each sparse QP it solves (data, bounds, stage dimensions) to ``qps``."""
    step = controller._rti_qp_step

    def spy(w, p, lbx, ubx, lbg, ubg):
        H, grad, g, A = controller._qp_data(w, p)
        g = np.asarray(g, float).ravel()
        qps.append({"case": case, "H": ca.DM(H), "g": np.asarray(grad, float), "A": ca.DM(A), "lba": lbg - g,
                    "uba": ubg - g, "lbx": lbx - w, "ubx": ubx - w, "dims": controller._dims})
        return step(w, p, lbx, ubx, lbg, ubg)

    controller._rti_qp_step = spy


def reference_case_qps(horizons, duration_h: float, qps: list) -> None:
    plant, ss, ctw, css = reference_setup(reference_sensors())
    for n in horizons:
        lead = Controller(ctw.model, settings(n, "auto", "condensed"))
        sparse = Controller(ctw.model, settings(n, "off", "hpipm"))
        recording(sparse, f"reference h{n}", qps)
        lockstep(plant.model, ctw, css, ss, {"condensed": lead, "hpipm": sparse}, duration_h, 0.05, 1)


def test_twin_qps(qps: list, steps: int = 12) -> None:
    """The coarse industrial twin of tests/mpc (conftest.small_twin) from its steady state at 27 t/h
    towards a target 10 % finer, the blend changed to 0.6 / 0.4."""
    twin = Twin(["B", "D"], mill="industrial", effects=list(DEFAULT_EFFECTS) + ["sensor_delay"],
                effect_options={"sensor_delay": {"dead_time_h": 0.1}},
                grid=SizeGrid(top_um=6700.0, ratio=2.0, count=10), n_mixers=1)
    m = twin.model
    ss = twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    power = 1.02 * float(m.outputs["power_kw"](ss.x, ss.u, ss.d))
    for n in (4, 6, 10):
        kw = dict(horizon_steps=n, dt_h=0.05, solver="rti", move_block=2, target_p80_um=0.9 * ss.p80_um,
                  power_max_kw=power, codegen="off")
        lead, sparse = Controller(m, NmpcSettings(**kw, qpsol="condensed")), Controller(m, NmpcSettings(**kw))
        recording(sparse, f"test twin h{n}", qps)
        d, u = m.d_vector([0.6, 0.4]), ss.u
        for _ in range(steps):
            sparse.make_step(ss.x, d, u)
            u = lead.make_step(ss.x, d, u).u_applied


def stalled_qp(qps: list) -> None:
    z = np.load(STALLED_QP)
    H, A = (ca.DM(ca.Sparsity.triplet(*map(int, z[f"{k}_shape"]), z[f"{k}_row"], z[f"{k}_col"]), z[f"{k}_val"])
            for k in ("h", "a"))
    qps.append({"case": "kept stalled QP", "H": H, "g": z["g"], "A": A, "lba": z["lba"], "uba": z["uba"],
                "lbx": z["lbx"], "ubx": z["ubx"],
                "dims": {"N": int(z["dims_N"]), **{k: z[f"dims_{k}"].tolist() for k in ("nx", "nu", "ng")}}})


def solve_all(qps: list) -> pd.DataFrame:
    made, rows = {}, []

    def solver(plugin, q, opts):
        key = (plugin, q["H"].sparsity().hash(), q["A"].sparsity().hash(), repr(opts))
        if key not in made:
            made[key] = conic("b", plugin, {"h": q["H"].sparsity(), "a": q["A"].sparsity()}, opts)
        return made[key]

    for i, q in enumerate(qps):
        args = dict(h=q["H"], g=q["g"], a=q["A"], lba=q["lba"], uba=q["uba"], lbx=q["lbx"], ubx=q["ubx"])
        x_ref = f_ref = None
        if q["H"].shape[0] <= REFERENCE_MAX_N:
            ref = solver("qpoases", q, {"printLevel": "none", "error_on_fail": False})
            r = ref(**args)
            if ref.stats()["success"]:
                x_ref, f_ref = np.asarray(r["x"]).ravel(), float(r["cost"])
        for name, hp in CONFIGS.items():
            s = solver("hpipm", q, {**q["dims"], "error_on_fail": False, "inf": HPIPM_INF,
                                    "hpipm": {"iter_max": 100, **hp}})
            t0 = time.perf_counter()
            r = s(**args)
            dt = time.perf_counter() - t0
            st = s.stats()
            x = np.asarray(r["x"]).ravel()
            cost_rel = np.nan if f_ref is None else (float(r["cost"]) - f_ref) / max(1.0, abs(f_ref))
            rows.append({"case": q["case"], "config": name, "qp": i, "n": q["H"].shape[0], "success": st["success"],
                         "iterations": st["iter_count"], "seconds": dt,
                         "dx_max_vs_qpoases": np.nan if x_ref is None else float(np.max(np.abs(x - x_ref))),
                         "cost_rel_vs_qpoases": cost_rel})
    return pd.DataFrame(rows)


def summary(per_qp: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for (case, config), g in per_qp.groupby(["case", "config"], sort=False):
        ok = g[g.success]
        rows.append({"case": case, "config": config, "qps": len(g), "n": int(g.n.iloc[0]),
                     "failed": int((~g.success).sum()), "iterations_median": g.iterations.median(),
                     "iterations_max": int(g.iterations.max()), "solve_median_ms": 1e3 * g.seconds.median(),
                     "dx_max_vs_qpoases (solved)": ok.dx_max_vs_qpoases.max(),
                     "cost_rel_max_vs_qpoases (solved)": ok.cost_rel_vs_qpoases.abs().max()})
    return pd.DataFrame(rows)


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--horizons", default="4")
    ap.add_argument("--duration-h", type=float, default=8.0)
    args = ap.parse_args(argv)
    qps: list = []
    reference_case_qps([int(v) for v in args.horizons.split(",")], args.duration_h, qps)
    test_twin_qps(qps)
    stalled_qp(qps)
    per_qp = solve_all(qps)
    table = summary(per_qp)
    OUT.mkdir(exist_ok=True)
    per_qp.to_csv(OUT / "mpc_hpipm_regularisation.csv", index=False)
    md = ["# HPIPM on the RTI's QPs: the controller's primal regularisation, HPIPM's own, its modes", "",
          f"HPIPM_REG_PRIM = {HPIPM_REG_PRIM:g} (mpc/nmpc.py) against HPIPM's own reg_prim {HPIPM_DEFAULT_REG:g}; "
          "iter_max 100, as the controller. The QPs of closed loops (module docstring): the reference transition "
          f"({args.duration_h:g} h) at horizons {args.horizons}, the test suite's coarse industrial twin at horizons "
          "4, 6, 10 (12 steps each), and the QP kept in tests/mpc/data. Each QP solved by every configuration in "
          f"turn. `dx`/`cost` against dense qpOASES for QPs up to {REFERENCE_MAX_N} variables (over the solved ones). "
          "Per-QP rows: mpc_hpipm_regularisation.csv.", "",
          table.to_markdown(index=False, floatfmt=".3g"), "",
          f"Reproduce: `PYTHONPATH=. python benchmarks/mpc_hpipm_regularisation.py --horizons {args.horizons} "
          f"--duration-h {args.duration_h:g}`."]
    (OUT / "mpc_hpipm_regularisation.md").write_text("\n".join(md) + "\n")
    print(table.to_string())
    return table


if __name__ == "__main__":
    main()
