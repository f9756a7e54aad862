"""What surrogate accuracy costs: PLS components and training-set size -> R2 and fit/predict
time, beside the PBM twin's time for the same predictions.

Data: the shipped training table ``twin/surrogate/data/surrogate_training.parquet`` (design in
``twin/surrogate/``). A fixed 20 % of the mineralogies (grouped split, seed 0) is the test
set; training sets are nested subsets of the other mineralogies. For each (degree, n_pca,
n_components, training mineralogies): held-out R2 per KPI, fit time, predict time per row in
one batch call (all test rows) and for single-row calls (one ``predict`` per point, the way
``surrogate_steady`` is called). The PBM time of the same predictions: ``Twin.steady`` on an
already built twin (median per steady state) and build + first steady state (a new
mineralogy), on the first mineralogies of the test set. Times are medians of ``--repeats``
runs on a 2-core machine shared with other jobs (upper bounds of the quiet-machine times).

Writes ``benchmarks/results/twin_surrogate.csv`` and ``.md``.

Run: ``PYTHONPATH=. python benchmarks/twin_surrogate.py [--quick]``.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import platform
import time

import numpy as np
import pandas as pd
import sklearn
from sklearn.metrics import r2_score

from twin.surrogate import TARGETS, Surrogate, held_out_split, load, load_training_table, split_xy, surrogate_steady
from twin.errors import TwinInputError
from twin.ore.samples import to_mineralogy
from twin.twin import Twin
from dem_common import command_note

RESULTS = pathlib.Path(__file__).resolve().parent / "results"


def _median_time(fn, repeats: int) -> float:
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def pbm_times(test: pd.DataFrame, n_ores: int, repeats: int) -> dict:
    """Median seconds per prediction of the twin: steady state of a built twin, and build +
    first steady state."""
    steady, build = [], []
    for mid in test["mineralogy_id"].unique()[:n_ores]:
        rows = test[test["mineralogy_id"] == mid]
        ore = to_mineralogy(rows.iloc[0])
        for _ in range(repeats):
            t0 = time.perf_counter()
            tw = Twin(ore, mill="lab")
            tw.steady(feed_tph=rows["feed_tph"].iloc[0], speed_frac_critical=rows["speed_frac_critical"].iloc[0])
            build.append(time.perf_counter() - t0)
        for _ in range(repeats):
            for f, s in zip(rows["feed_tph"], rows["speed_frac_critical"]):
                t0 = time.perf_counter()
                tw.steady(feed_tph=f, speed_frac_critical=s)
                steady.append(time.perf_counter() - t0)
    return {"pbm_steady_s": float(np.median(steady)), "pbm_build_steady_s": float(np.median(build)),
            "pbm_n": len(steady)}


def run(table, test, train_ids, params, repeats: int) -> dict:
    tr = table[table["mineralogy_id"].isin(train_ids)]
    Xtr, Ytr, _ = split_xy(tr)
    Xte, Yte, _ = split_xy(test)
    fit_s = _median_time(lambda: Surrogate(**params).fit(Xtr, Ytr), repeats)
    sur = Surrogate(**params).fit(Xtr, Ytr)
    with np.errstate(over="ignore"):
        P = sur.predict(Xte, check_domain=False)
    Yv = Yte.to_numpy(float)
    # an over-fitted model can diverge (exp overflow) on unseen mineralogies: R2 = -inf
    r2 = {t: (float(r2_score(Yv[:, i], P[:, i])) if np.all(np.isfinite(P[:, i])) else -np.inf)
          for i, t in enumerate(TARGETS)}
    batch_s = _median_time(lambda: sur.predict(Xte, check_domain=False), repeats) / len(Xte)
    A = sur._as_array(Xte)
    rows = [A[i:i + 1] for i in range(min(50, len(A)))]
    single_s = _median_time(lambda: [sur._predict_array(r, check_domain=False) for r in rows], repeats) / len(rows)
    frames = [Xte.iloc[[i]] for i in range(min(50, len(Xte)))]
    single_df_s = _median_time(lambda: [sur.predict(r, check_domain=False) for r in frames], repeats) / len(frames)
    out = {"degree": params["degree"], "n_pca": params["n_pca"], "n_components": params["n_components"],
           "train_mineralogies": len(train_ids), "train_rows": len(tr), "test_rows": len(Xte)}
    out |= {f"r2_{t}": r2[t] for t in TARGETS}
    out |= {"r2_min": min(r2.values()), "fit_s": fit_s, "predict_batch_us_per_row": batch_s * 1e6,
            "predict_single_us": single_s * 1e6, "predict_single_dataframe_us": single_df_s * 1e6}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, 1 repeat")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    repeats = 1 if args.quick else args.repeats
    table = load_training_table()
    train, test = held_out_split(table)
    ids = train["mineralogy_id"].unique()
    rng = np.random.default_rng(0)
    ids = ids[rng.permutation(len(ids))]
    sizes = [32, 64, 128, len(ids)] if not args.quick else [64, len(ids)]
    configs = [(1, 10, nc) for nc in (1, 2, 4, 8, 12)] + [(2, 6, nc) for nc in (8, 16, 32, 64)] + [
        (2, 10, nc) for nc in (8, 16, 32, 64, 80, 135)]
    if args.quick:
        configs = [(1, 10, 8), (2, 6, 32), (2, 10, 80)]
    grid = [({"degree": d, "n_pca": p, "n_components": nc}, n) for n in sizes for d, p, nc in configs]
    pbm = pbm_times(test, n_ores=3 if args.quick else 6, repeats=repeats)  # first: fail before the grid
    rows = []
    for params, n in grid:
        try:
            r = run(table, test, ids[:n], params, repeats)
        except TwinInputError as exc:  # a grid point the data cannot support (too few rows)
            print(f"skip {params} n={n}: {exc}")
            continue
        rows.append(r)
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()}, flush=True)
    res = pd.DataFrame(rows)
    load_avg = os.getloadavg()
    shipped = load()
    steady_us = _median_time(lambda: [surrogate_steady("B", f, 0.70, surrogate=shipped) for f in
                                      np.linspace(0.02, 0.045, 50)], repeats) / 50 * 1e6
    res["pbm_steady_ms"] = pbm["pbm_steady_s"] * 1e3
    res["pbm_build_steady_ms"] = pbm["pbm_build_steady_s"] * 1e3
    res["ratio_steady_vs_batch"] = pbm["pbm_steady_s"] / (res["predict_batch_us_per_row"] * 1e-6)
    res["ratio_steady_vs_single"] = pbm["pbm_steady_s"] / (res["predict_single_us"] * 1e-6)
    res["ratio_build_vs_single"] = pbm["pbm_build_steady_s"] / (res["predict_single_us"] * 1e-6)
    res["surrogate_steady_us"] = steady_us
    RESULTS.mkdir(exist_ok=True)
    res.to_csv(RESULTS / "twin_surrogate.csv", index=False, float_format="%.6g")
    head = (f"# Surrogate accuracy against time\n\nmachine: {platform.machine()}, {os.cpu_count()} cores shared with other jobs, "
            f"load average {load_avg[0]:.1f} / {load_avg[1]:.1f} / {load_avg[2]:.1f} at the end of the grid "
            f"(times are upper bounds of quiet-machine times); scikit-learn {sklearn.__version__}; repeats {repeats} (medians); "
            f"table {len(table)} steady states of {table['mineralogy_id'].nunique()} mineralogies; test set "
            f"{len(test)} points of {test['mineralogy_id'].nunique()} unseen mineralogies. R2 in KPI units on the "
            f"test set. PBM per prediction: steady state of a built twin {pbm['pbm_steady_s'] * 1e3:.2f} ms, "
            f"build + first steady state {pbm['pbm_build_steady_s'] * 1e3:.0f} ms (median of {pbm['pbm_n']}). "
            f"`surrogate_steady` (the CLI's call, shipped model, domain checked): {steady_us:.0f} us per call, "
            f"ratio {pbm['pbm_steady_s'] / (steady_us * 1e-6):.0f}x against a built twin's steady state, "
            f"{pbm['pbm_build_steady_s'] / (steady_us * 1e-6):.0f}x against build + steady state.\n\n"
            "Columns: predict_batch_us_per_row = one predict() of all test rows (DataFrame in) / rows; "
            "predict_single_us = one-row array calls; predict_single_dataframe_us = one-row DataFrame calls "
            "(pandas overhead); ratio_* = PBM time / surrogate time per prediction.\n\n")
    cols = ["degree", "n_pca", "n_components", "train_mineralogies", "train_rows"] + [f"r2_{t}" for t in TARGETS] + [
        "fit_s", "predict_batch_us_per_row", "predict_single_us", "predict_single_dataframe_us",
        "ratio_steady_vs_batch", "ratio_steady_vs_single", "ratio_build_vs_single"]
    md = "| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n"
    for _, r in res[cols].iterrows():
        md += "| " + " | ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in r) + " |\n"
    head = head.replace("\n\n", f"\n\n{command_note()}\n\n", 1)  # after the title
    (RESULTS / "twin_surrogate.md").write_text(head + md, encoding="utf-8")
    print(head + md)


if __name__ == "__main__":
    main()
