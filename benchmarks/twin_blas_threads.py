"""The steady state's Newton solves on one BLAS thread against the BLAS library's own count, interleaved.

A steady state's Newton steps solve dense systems of at most 600 unknowns (twin.solve.steady's dense limit):
small for a second BLAS thread, which must also wait for its core. Each repeat times the same steady state
once with ``twin.solve.numeric.NEWTON_BLAS_THREADS = 1`` (the default) and once with ``None`` (OpenBLAS's own
thread count), alternating which goes first; the ratio is taken within each pair (medians and ranges over the
repeats). Two conditions: the machine as it is, and beside a busy process (one Python loop spinning on a core
for the duration, as another job on a shared 2-core machine).

Writes benchmarks/results/twin_blas_threads.md and .csv. Run: PYTHONPATH=. python benchmarks/twin_blas_threads.py
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_info

import twin.solve.numeric as numeric
from dem_common import write_table
from twin import Twin

#: Steady states per side in one timing (a steady state takes a few ms: a timing of several is less noisy).
CALLS = 5


def cases() -> dict:
    """Name -> (number of unknowns, a function computing the steady state)."""
    lab = Twin("B")
    ind = Twin(["B", "D"], mill="industrial")
    four = Twin(["A", "B", "C", "D"], mill="industrial")
    return {"lab mill, Type B": (lab.model.n_x, lambda: lab.steady()),
            "industrial mill, B and D": (ind.model.n_x, lambda: ind.steady(feed_tph=30.0, blend=[1.0, 0.0])),
            "industrial mill, four ores": (four.model.n_x, lambda: four.steady(feed_tph=30.0))}


def timed(fn, threads) -> float:
    numeric.NEWTON_BLAS_THREADS = threads
    t0 = time.perf_counter()
    for _ in range(CALLS):
        fn()
    return (time.perf_counter() - t0) / CALLS


def pairs(fn, repeats: int) -> tuple[list, list]:
    one, own = [], []
    for k in range(repeats):
        order = (1, None) if k % 2 == 0 else (None, 1)
        t = {threads: timed(fn, threads) for threads in order}
        one.append(t[1])
        own.append(t[None])
    numeric.NEWTON_BLAS_THREADS = 1
    return one, own


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=15, help="pairs per case and condition (default 15)")
    o = ap.parse_args(argv)
    rows = []
    for condition in ("as it is", "beside a busy process"):
        busy = (subprocess.Popen([sys.executable, "-c", "while True: pass"]) if condition != "as it is" else None)
        try:
            for name, (n_x, fn) in cases().items():
                fn()  # built and compiled first
                one, own = pairs(fn, o.repeats)
                ratio = np.array(own) / np.array(one)
                rows.append({"condition": condition, "case": name, "unknowns": n_x, "repeats": o.repeats,
                             "one_thread_ms": 1e3 * float(np.median(one)), "own_threads_ms": 1e3 * float(np.median(own)),
                             "own_over_one": float(np.median(ratio)),
                             "range": f"{ratio.min():.2f}-{ratio.max():.2f}"})
                print(rows[-1], flush=True)
        finally:
            if busy is not None:
                busy.kill()
                busy.wait()
    blas = [f"{i['internal_api']} {i['version']} ({i['num_threads']} threads)" for i in threadpool_info()
            if i["user_api"] == "blas"]
    write_table(pd.DataFrame(rows), "twin_blas_threads",
                "Steady states: one BLAS thread for the Newton solves against the library's own count",
                f"BLAS: {', '.join(blas)}. Each row: the median time of a steady state ({CALLS} in a timing) with one "
                "BLAS thread and with the library's own count, timed in pairs of alternating order; own_over_one = "
                "median of the pairs' ratios (above 1: one thread is faster), range over the pairs. 'Beside a busy "
                "process': a Python loop spins on one core for the condition's duration.")


if __name__ == "__main__":
    main()
