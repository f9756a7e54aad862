"""The tables an engineer opens after a run: size distributions as labelled CSV files, and one
Excel workbook per run or per sweep (written with openpyxl through pandas).

Run workbook (``run.xlsx``): summary, KPIs (with their meaning and unit), a replay's run minus
recorded (summary.json's ``replay``, as the report shows it), the time series, the size-by-size
table of every stream at the start and the end of the run (as a simulator prints a circuit), the
product and mill-content size distributions over time, the models, the scene.
Sweep workbook (``sweep.xlsx``): the cases with their KPIs (headed by their meaning and unit, shares as
percentages, as the KPI sheet gives them), the P80 of every case against time,
the scene the cases vary. Units are in every column name or header.

A workbook's numbers have 16 significant digits (openpyxl writes every number as ``%.16g``; Excel
shows 15): a number that needs 17 to read back exactly is off by one unit in its last digit
(0.30000000000000004 reads back 0.3). The CSV and parquet files hold every digit.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from scenarios.output.labels import (KPI_LABELS, calibration_text, effects_rows, is_percent, percent_decimals,
                                      preset_file_text, replay_rows)
from twin import json_text, write_atomically

#: Size distributions a run writes as CSV: the stream (``attrs['what']``) -> file name.
PSD_FILES = {"product": "product_psd.csv", "mill content": "mill_psd.csv"}
#: The size-by-size table of every stream at the end of a run.
STREAMS_FILE = "streams.csv"
RUN_WORKBOOK = "run.xlsx"
#: Rows an Excel sheet holds (Excel's limit), its header row included.
EXCEL_MAX_ROWS = 1_048_576
#: The KPI sheet's note beside an empty value (the report's "n/a").
UNDEFINED_NOTE = "n/a: not defined for this run (no P80 target, no controller, a batch grind or nothing fed)"
SWEEP_WORKBOOK = "sweep.xlsx"
#: How every CSV of a run folder writes a number that is not defined (NaN: the P80 of an empty mill,
#: a KPI with no target): the text ``NaN``, which pandas, numpy, R and Python's ``float`` read back as
#: NaN; an empty cell (pandas' default) reads as a sample lost. Other numbers are written with every
#: digit (Python's repr), so they read back exactly.
CSV_NA = "NaN"
#: The same in a workbook's tables of numbers: Excel's own error value, which a chart skips and a sum
#: or mean carries (an empty cell reads as lost, text as zero in a chart); pandas reads it back as NaN.
XLSX_NA = "#N/A"


def write_csv(table: pd.DataFrame, path: Path, index: bool = True) -> Path:
    """``table`` as CSV at ``path``, an undefined number written :data:`CSV_NA`, a missing text empty
    (:func:`blank_missing_text`)."""
    blank_missing_text(table).to_csv(path, index=index, na_rep=CSV_NA)
    return Path(path)


def _text_or_missing(value) -> bool:
    return isinstance(value, str) or value is None or (isinstance(value, float) and math.isnan(value))


def blank_missing_text(table: pd.DataFrame) -> pd.DataFrame:
    """``table`` with the missing cells of its text columns (of strings, or objects holding only text or None: a
    sweep case's ``error`` and ``warnings``) as empty text: no error is no text, not an undefined number (``NaN``,
    ``#N/A`` read as one). Columns of numbers keep their NaN (:data:`CSV_NA`, :data:`XLSX_NA`)."""
    text = [c for c in table.columns if isinstance(table[c].dtype, pd.StringDtype)
            or (table[c].dtype == object and table[c].map(_text_or_missing).all())]
    if not text:
        return table
    out = table.copy()
    for c in text:
        out[c] = out[c].astype(object).where(out[c].notna(), "")
    return out


def workbook_problem(n_samples: int) -> str | None:
    """Why a run of ``n_samples`` samples cannot have a workbook (its time series is one row per
    sample below a header), or None; asked before the run, so the run is never lost at its end."""
    if n_samples + 1 <= EXCEL_MAX_ROWS:
        return None
    return (f"--xlsx: the run has {n_samples:,} samples, more than an Excel sheet holds ({EXCEL_MAX_ROWS - 1:,} "
            "rows below its header); allowed: at most that many samples (scene.duration_h / "
            "scene.sample_period_h + 1). Leave out --xlsx (timeseries.parquet holds every sample) or use a "
            "longer sample period")


def psd_table(psd: pd.DataFrame) -> pd.DataFrame:
    """A size distribution over time with its units in the header: ``time [h]``, then one
    column per sieve size, ``cumulative % passing <size> µm``, the size with every digit it has
    (:func:`size_text`: a reader maps a column to its size by the header)."""
    out = 100.0 * psd.astype(float)
    out.columns = [f"cumulative % passing {size_text(s)} µm" for s in psd.columns]
    out.index = pd.Index(psd.index.astype(float), name="time [h]")
    return out


def size_text(size_um) -> str:
    """A size as the shortest text that reads back as the same float (6700, 4737.6154); ``:g``'s six
    digits named a sieve of 4737.6154 µm "4737.62" and gave sieves of 6699.991 and 6699.994 µm one
    header."""
    return np.format_float_positional(float(size_um), unique=True, trim="-")


def write_size_csvs(result, folder: Path) -> list[Path]:
    """``product_psd.csv`` and ``mill_psd.csv`` (a batch grind has the second only) and
    ``streams.csv`` (every stream at the end of the run)."""
    written = []
    for psd in (result.psd, getattr(result, "mill_psd", None)):
        if psd is not None and len(psd):
            path = Path(folder) / PSD_FILES[psd.attrs.get("what", "product")]
            write_csv(psd_table(psd), path)
            written.append(path)
    end = (getattr(result, "streams", None) or {}).get("end")
    if end is not None:
        write_csv(end, Path(folder) / STREAMS_FILE)
        written.append(Path(folder) / STREAMS_FILE)
    return written


def kpi_rows(kpis: dict) -> pd.DataFrame:
    """KPI key, meaning with its unit, value (None where undefined, and the note says so: an empty
    cell alone reads as a value lost)."""
    rows = []
    for k, v in kpis.items():
        undefined = v is None or (isinstance(v, float) and math.isnan(v))  # an infinity is a value: "inf"
        rows.append({"kpi": k, "meaning [unit]": KPI_LABELS.get(k, (k, ""))[0], "value": None if undefined else v,
                     "note": UNDEFINED_NOTE if undefined else None})
    table = pd.DataFrame(rows, columns=["kpi", "meaning [unit]", "value", "note"])
    table.attrs["percent_cells"] = percent_cells((i, 2, k, v) for i, (k, v) in enumerate(kpis.items()))
    return table


def percent_cells(cells) -> list[tuple[int, int, str]]:
    """(row, column, Excel number format) of the cells, given as (row, column, KPI key, value), whose KPI is
    a fraction labelled [%]: shown as a percentage (the cell keeps the fraction), with the decimals the
    report gives it (a share just short of 1 never reads 100.0 %)."""
    return [(i, j, percent_format(v)) for i, j, k, v in cells if is_percent(k)]


def kpi_header(key: str) -> str:
    """A KPI's column header in a table of cases: its meaning with its unit (the KPI sheet's), then its key
    (sweep.csv's column); a column that is no KPI keeps its key."""
    return f"{KPI_LABELS[key][0]} ({key})" if key in KPI_LABELS else key


def cases_sheet(table: pd.DataFrame) -> pd.DataFrame:
    """A sweep's table of cases as its workbook shows it, as readable as the KPI sheet: the KPIs headed by
    :func:`kpi_header`, shares as percentages (:func:`percent_cells`), cells that are tables as JSON text
    (:func:`tables_as_json`), and its text columns' missing cells empty (:func:`blank_missing_text`: an error
    column whose case ran holds no #N/A error value)."""
    cases = blank_missing_text(tables_as_json(table))
    cases.attrs["percent_cells"] = percent_cells((i, j, k, v) for j, k in enumerate(cases.columns)
                                                 for i, v in enumerate(cases[k]))
    return cases.rename(columns=kpi_header)


def percent_format(value) -> str:
    """Excel's number format of a share: :func:`scenarios.output.labels.percent_decimals` decimals."""
    ok = isinstance(value, (int, float)) and math.isfinite(value)
    return "0." + "0" * (percent_decimals(float(value)) if ok else 1) + "%"


def flat_keys(data, prefix: str = "") -> list[tuple[str, object]]:
    """A nested table as (key path, value) rows: ``feed.schedule[0].blend.D``."""
    rows: list[tuple[str, object]] = []
    if isinstance(data, dict):
        for k, v in data.items():
            rows += flat_keys(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(data, list) and data and all(isinstance(v, (dict, list)) for v in data):
        for i, v in enumerate(data):
            rows += flat_keys(v, f"{prefix}[{i}]")
    else:
        rows.append((prefix, ", ".join(map(str, data)) if isinstance(data, list) else data))
    return rows


def scene_rows(scene) -> pd.DataFrame:
    """Every key of a validated scene (defaults filled in) with its value."""
    data = scene.model_dump(exclude_none=True) if scene is not None else {}
    return pd.DataFrame(flat_keys(data), columns=["key", "value"])


def summary_rows(summary: dict) -> pd.DataFrame:
    keys = ("scene", "description", "mode", "controller", "target_p80_um", "seed", "source", "wall_time_s")
    rows = [(k, summary.get(k)) for k in keys]
    rows += [*replay_rows(summary), *effects_rows(summary),
             ("components", ", ".join(summary.get("components", []))),
             ("calibration", calibration_text(summary.get("calibration"))),
             ("mill preset file", preset_file_text(summary.get("mill_preset_file"))),
             ("history file", preset_file_text(summary.get("history_file"))),
             ("feed screen analysis file", preset_file_text(summary.get("psd_file")))]
    # the warnings apart, as the report puts them (a run's notes hold its warnings too)
    warnings = [str(w) for w in summary.get("warnings") or []]
    rows += [(f"warning {i + 1}", w) for i, w in enumerate(warnings)]
    notes = [str(n) for n in summary.get("notes") or [] if str(n) not in warnings]
    rows += [(f"note {i + 1}", n) for i, n in enumerate(notes)]
    rows += [(f"version: {k}", v) for k, v in (summary.get("versions") or {}).items()]
    return pd.DataFrame(rows, columns=["item", "value"])


def model_rows(summary: dict) -> pd.DataFrame:
    """The plant's model and the controller's, line by line side by side."""
    plant = (summary.get("plant_model") or "").splitlines()
    ctl = (summary.get("controller_model") or "none (open loop)").splitlines()
    n = max(len(plant), len(ctl))
    return pd.DataFrame({"plant (simulated)": plant + [""] * (n - len(plant)),
                         "controller's model": ctl + [""] * (n - len(ctl))})


#: Sheets of text and settings, where an empty cell means "not set" (the KPI sheet's note says why a
#: value is empty); every other sheet is a table of numbers, an undefined one written :data:`XLSX_NA`.
TEXT_SHEETS = ("summary", "KPIs", "replay", "models", "scene", "varied keys")


def _write_sheets(path: Path, sheets: dict[str, tuple[pd.DataFrame, bool]]) -> Path:
    """Write ``name -> (table, keep its index)`` sheets to ``path`` via a temporary file of a name
    nobody else holds (:func:`twin.atomic.write_atomically`; ``path.partial`` could be the user's);
    header row frozen, columns sized to their header."""
    return write_atomically(path, lambda tmp: _fill_book(tmp, sheets))


def _fill_book(tmp: Path, sheets: dict[str, tuple[pd.DataFrame, bool]]) -> None:
    with pd.ExcelWriter(tmp, engine="openpyxl") as xl:
        for name, (table, index) in sheets.items():
            table = blank_missing_text(table)  # a missing text is empty on a sheet of numbers too, not #N/A
            table.to_excel(xl, sheet_name=name, index=index, na_rep="" if name in TEXT_SHEETS else XLSX_NA)
            ws = xl.sheets[name]
            ws.freeze_panes = "B2" if index else "A2"
            for row, col, fmt in table.attrs.get("percent_cells", []):  # (row, column, format) of the table
                ws.cell(row=row + 2, column=col + 1 + bool(index)).number_format = fmt
            for cells in ws.iter_cols(min_row=1, max_row=1):
                width = max(10, min(60, len(str(cells[0].value or "")) + 2))
                ws.column_dimensions[cells[0].column_letter].width = width


def write_workbook(result, path: Path) -> Path:
    """The run's workbook (module docstring)."""
    s = result.summary
    sheets = {"summary": (summary_rows(s), False), "KPIs": (kpi_rows(s.get("kpis", {})), False)}
    if s.get("replay"):  # the run beside its record, as summary.json and the report give it
        sheets["replay"] = (kpi_rows(s["replay"].get("run_minus_recorded", {})), False)
    sheets["time series"] = (result.frame, False)
    for when, table in (getattr(result, "streams", None) or {}).items():
        sheets[f"streams at {when}"] = (table, True)
    for attr, label in (("psd", "PSD " + (result.psd.attrs.get("what", "product") if result.psd is not None
                                          else "")), ("mill_psd", "PSD mill content")):
        psd = getattr(result, attr, None)
        if psd is not None and len(psd):
            sheets[label.strip()[:31]] = (psd_table(psd), True)
    sheets["models"] = (model_rows(s), False)
    sheets["scene"] = (scene_rows(getattr(result, "scene", None)), False)
    return _write_sheets(Path(path), sheets)


#: Decimals of an hour the traces' times are taken to (3.6 us): the sample grids' rounding is below them.
TRACE_TIME_DECIMALS = 9


def trace_table(traces: pd.DataFrame, column: str | None = None) -> pd.DataFrame:
    """Long traces (``case``, ``time_h``, ...) as one column per case, ``time [h]`` rows; by default
    of the product P80 (of the mill content's in a batch sweep)."""
    column = column or ("p80_um" if "p80_um" in traces else "content_p80_um")
    # one row per time: cases of other sample periods reach a time by other roundings (5 x 0.03 h is
    # 0.15000000000000002 h), and split it into two rows with gaps
    traces = traces.assign(time_h=traces["time_h"].round(TRACE_TIME_DECIMALS))
    wide = traces.pivot(index="time_h", columns="case", values=column)
    wide.columns = [f"case {c}: {column}" for c in wide.columns]
    wide.index.name = "time [h]"
    return wide


def tables_as_json(table: pd.DataFrame) -> pd.DataFrame:
    """``table`` with its cells that are tables (a case's blend, a list) as JSON text, for CSV, Parquet and a
    sheet: Python's text of them ({'B': 0.8}) was neither JSON nor TOML."""
    out = table.copy()
    for c in out.columns:
        if out[c].map(lambda v: isinstance(v, (dict, list))).any():
            out[c] = out[c].map(lambda v: json_text(v) if isinstance(v, (dict, list)) else v)
    return out


def write_sweep_workbook(table: pd.DataFrame, traces: pd.DataFrame | None, scene, path: Path) -> Path:
    """The sweep's workbook (module docstring); ``scene``: the validated base scene or None."""
    sheets = {"cases": (cases_sheet(table), False)}
    if traces is not None and len(traces):
        sheets["P80 traces"] = (trace_table(traces), True)
    varied = pd.DataFrame({"varied key": table.attrs.get("varied", [])})
    sheets["varied keys"] = (varied, False)
    sheets["scene"] = (scene_rows(scene), False)
    return _write_sheets(Path(path), sheets)
