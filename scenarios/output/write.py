"""Write a run's results: time series, summary, plots; never a half-written result.

Layout of a run directory::

    DIR/timeseries.parquet   one row per sample, unit-suffixed columns
    DIR/timeseries.csv       the same, on request (``csv=True``)
    DIR/product_psd.csv      cumulative % passing at a few times (rows) per size (columns, um);
                             mill_psd.csv the same of the mill content, streams.csv every
                             stream size by size at the end (scenarios.output.workbook)
    DIR/run.xlsx             the workbook, on request (``xlsx=True``)
    DIR/summary.json         scene, KPIs (unit-suffixed keys; NaN written as null), model
                             description, effects, versions, seed, notes
    DIR/*.png                plots (see :data:`scenarios.output.plots.PLOTS`)
    DIR/report.html          written later by ``grindtwin report DIR``

Atomicity: everything is written into ``DIR.partial`` (with an ``_INCOMPLETE`` marker as
its first file); only when every file is written is the marker removed and the folder renamed
to ``DIR``. An existing ``DIR`` is replaced only then. If writing fails the partial folder is
removed; if the process is killed, what remains is ``DIR.partial`` with its marker, never a
``DIR`` that looks complete.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np

from scenarios.output.plots import write_plots
from scenarios.output.workbook import RUN_WORKBOOK, write_size_csvs, write_workbook

INCOMPLETE_MARKER = "_INCOMPLETE"
def json_safe(obj):
    """NaN and infinities -> None; numpy scalars -> Python; recursively."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_run(result, out_dir, csv: bool = False, plots: bool = True, xlsx: bool = False) -> Path:
    """Write ``result`` (a :class:`scenarios.run.runner.RunResult`) to ``out_dir`` atomically."""
    final = Path(out_dir)
    partial = final.with_name(final.name + ".partial")
    if partial.exists():
        shutil.rmtree(partial)
    partial.mkdir(parents=True)
    try:
        (partial / INCOMPLETE_MARKER).write_text("this run was interrupted while its results were "
                                                 "written; do not use these files\n")
        frame = result.frame
        frame.to_parquet(partial / "timeseries.parquet", index=False)
        if csv:
            frame.to_csv(partial / "timeseries.csv", index=False)
        write_size_csvs(result, partial)
        if xlsx:
            write_workbook(result, partial / RUN_WORKBOOK)
        if plots:
            write_plots(result, partial)
        summary = dict(result.summary)
        summary["files"] = sorted(p.name for p in partial.iterdir() if p.name != INCOMPLETE_MARKER) \
            + ["summary.json"]
        (partial / "summary.json").write_text(json.dumps(json_safe(summary), indent=2) + "\n")
        (partial / INCOMPLETE_MARKER).unlink()
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    old = None
    if final.exists():
        old = final.with_name(final.name + ".old")
        if old.exists():
            shutil.rmtree(old)
        final.rename(old)
    partial.rename(final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return final
