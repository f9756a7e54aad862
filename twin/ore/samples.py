"""Sample tables: modal mineralogy and texture of ore samples (QEMSCAN/XRD), read and validated.

A sample table has one row per sample and the columns

- ``sample_id``: non-empty, unique;
- ``<mineral>_wt_pct``: modal mineralogy in wt%, one column per mineral of
  ``twin/ore/data/minerals.csv`` (e.g. ``quartz_wt_pct``); a missing mineral column means 0 wt%;
- texture: ``mean_grain_um`` (> 0), ``uniformity`` in (0, 1], ``association_entropy`` in [0, 1]
  (see :class:`twin.ore.mineralogy.Texture`);
- optional free columns (``ore_type``, ``hole_id``, ``depth_m``, ...) kept as they are.

Validation is row by row and complete: every bad cell is reported with its line, sample id,
column, value and what is allowed, all in one :class:`SampleTableError`; nothing is silently
dropped or repaired. Row sums must be 100 wt% within
:data:`twin.ore.mineralogy.SUM_TOLERANCE_WT_PCT`, as for :class:`twin.ore.mineralogy.Mineralogy`.

CSV files may start with ``#`` comment lines (provenance); Parquet files are read with pyarrow.
"""

from __future__ import annotations

import io
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import TwinInputError, close_matches
from .minerals import mineral_table
from .mineralogy import (MEAN_GRAIN_RANGE_UM, SUM_TOLERANCE_WT_PCT, TEXTURE_COLUMNS, WT_SUFFIX, Mineralogy, Texture,
                         fractions_hint)

ID_COLUMN = "sample_id"

#: allowed interval of each texture column: (lo, hi, lo_open, hi_open); the grain size's is Texture's own
#: (a row outside it passed here and failed later in to_mineralogy, without its row)
_TEXTURE_RANGES = {
    "mean_grain_um": (*MEAN_GRAIN_RANGE_UM, False, False),
    "uniformity": (0.0, 1.0, True, False),
    "association_entropy": (0.0, 1.0, False, False),
}


@dataclass(frozen=True)
class RowProblem:
    """One bad cell (or row) of a sample table. ``line`` is the 1-based data row number
    (header excluded, comment lines excluded)."""

    line: int
    sample_id: str
    column: str
    value: object
    allowed: str

    def __str__(self) -> str:
        return (f"row {self.line} (sample_id={self.sample_id!r}): column '{self.column}' "
                f"must be {self.allowed}. Got {self.value!r}.")


class SampleTableError(TwinInputError):
    """A sample table has bad rows; ``problems`` lists every one of them."""

    def __init__(self, source: str, problems: list[RowProblem]):
        self.source = source
        self.problems = list(problems)
        head = "\n  ".join(str(p) for p in self.problems[:50])
        more = f"\n  ... and {len(self.problems) - 50} more" if len(self.problems) > 50 else ""
        super().__init__(f"{source}: {len(self.problems)} problem(s) in the sample table:\n  {head}{more}")


def mineral_columns(frame: pd.DataFrame) -> list[str]:
    """The ``<mineral>_wt_pct`` columns of ``frame``, in table order."""
    return [c for c in frame.columns if str(c).endswith(WT_SUFFIX)]


def mineral_of(column: str) -> str:
    return column[: -len(WT_SUFFIX)]


#: pandas' name for the second and later copies of a repeated CSV header: 'quartz_wt_pct.1'
_REPEAT = re.compile(r"^(.+)\.(\d+)$")


def _column_problems(frame: pd.DataFrame, known) -> list[RowProblem]:
    """A column given twice (its second copy was read by nothing: 'quartz_wt_pct.1'), and a column named
    after a mineral without the wt% suffix ('kaolinite_wt_frac', 'pyrite'), also read by nothing."""
    cols = [str(c) for c in frame.columns]
    problems = []
    for col in sorted({c for c in cols if cols.count(c) > 1}):
        problems.append(RowProblem(0, "", col, col, "given once (it appears more than once in the header)"))
    for col in cols:
        m = _REPEAT.match(col)
        if m and m.group(1) in cols and (m.group(1).endswith(WT_SUFFIX) or m.group(1) in TEXTURE_COLUMNS):
            problems.append(RowProblem(0, "", m.group(1), col, "given once (it appears more than once in the header)"))
        elif not col.endswith(WT_SUFFIX) and not m and col.split("_wt")[0].split("_pct")[0] in known:
            problems.append(RowProblem(0, "", col, col, f"named '<mineral>{WT_SUFFIX}' (modal mineralogy in wt%)"))
    return problems


def check_samples(frame: pd.DataFrame) -> list[RowProblem]:
    """Every problem of a sample table, row by row; an empty list when the table is valid."""
    known = mineral_table()
    problems: list[RowProblem] = _column_problems(frame, known)
    if ID_COLUMN not in frame.columns:
        problems.append(RowProblem(0, "", ID_COLUMN, None,
                                   f"a column of the table (columns found: {', '.join(map(str, frame.columns))})"))
        return problems
    wt_cols = mineral_columns(frame)
    for col in wt_cols:
        if mineral_of(col) not in known:
            problems.append(RowProblem(
                0, "", col, col,
                f"'<mineral>{WT_SUFFIX}' with a known mineral "
                f"({', '.join(known)}){close_matches(mineral_of(col), known)}"))
    if not wt_cols:
        problems.append(RowProblem(0, "", f"<mineral>{WT_SUFFIX}", None,
                                   "at least one mineral column such as 'quartz_wt_pct'"))
    for col in TEXTURE_COLUMNS:
        if col not in frame.columns:
            problems.append(RowProblem(0, "", col, None, "a column of the table (texture)"))
    if problems:
        return problems

    seen: dict[str, int] = {}
    for i, row in enumerate(frame.itertuples(index=False), start=1):
        rec = dict(zip(frame.columns, row))
        raw_id = rec[ID_COLUMN]
        sid = "" if _missing(raw_id) else str(raw_id).strip()
        if not sid:
            problems.append(RowProblem(i, sid, ID_COLUMN, raw_id, "a non-empty identifier"))
        elif sid in seen:
            problems.append(RowProblem(i, sid, ID_COLUMN, raw_id,
                                       f"unique (already used on row {seen[sid]})"))
        else:
            seen[sid] = i
        total, row_ok = 0.0, True
        for col in wt_cols:
            v = _number(rec[col])
            if v is None or not (0.0 <= v <= 100.0):
                problems.append(RowProblem(i, sid, col, rec[col], "a number in [0, 100] wt%"))
                row_ok = False
            else:
                total += v
        if row_ok and abs(total - 100.0) > SUM_TOLERANCE_WT_PCT:
            problems.append(RowProblem(i, sid, f"sum of {WT_SUFFIX} columns", round(total, 4),
                                       f"100 wt% within {SUM_TOLERANCE_WT_PCT} wt%{fractions_hint(total)}"))
        for col, (lo, hi, lo_open, hi_open) in _TEXTURE_RANGES.items():
            v = _number(rec[col])
            ok = v is not None and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
            if not ok:
                interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
                problems.append(RowProblem(i, sid, col, rec[col], f"a number in {interval}"))
    return problems


def validate_samples(frame: pd.DataFrame, source: str = "sample table") -> pd.DataFrame:
    """Return a clean copy of ``frame`` (ids as str, numbers as float, missing mineral columns
    of no consequence) or raise :class:`SampleTableError` listing every problem."""
    problems = check_samples(frame)
    if problems:
        raise SampleTableError(source, problems)
    out = frame.copy()
    out[ID_COLUMN] = out[ID_COLUMN].astype(str).str.strip()
    for col in mineral_columns(out) + list(TEXTURE_COLUMNS):
        out[col] = out[col].astype(float)
    return out.reset_index(drop=True)


def read_samples(path: str | Path) -> pd.DataFrame:
    """Read a sample table from CSV (``#`` comment lines allowed at the top) or Parquet and
    validate it (:func:`validate_samples`); errors name the file."""
    path = Path(path)
    if not path.is_file():
        raise TwinInputError(f"The sample table file must exist. Got {str(path)!r}.")
    suffix = path.suffix.lower()
    if suffix in (".parquet", ".pq"):
        frame = pd.read_parquet(path)
    elif suffix in (".csv", ".txt"):
        lines = path.read_text(encoding="utf-8").splitlines()
        body = "\n".join(ln for ln in lines if not ln.lstrip().startswith("#"))
        frame = pd.read_csv(io.StringIO(body), dtype={ID_COLUMN: str}, keep_default_na=True)
    else:
        raise TwinInputError(f"The sample table file must be .csv or .parquet. Got {str(path)!r}.")
    return validate_samples(frame, source=str(path))


def read_header_comments(path: str | Path) -> list[str]:
    """The leading ``#`` comment lines of a CSV file, without the ``#``."""
    out = []
    for ln in Path(path).read_text(encoding="utf-8").splitlines():
        if not ln.startswith("#"):
            break
        out.append(ln[1:].strip())
    return out


def to_mineralogy(row: pd.Series | dict) -> Mineralogy:
    """One validated row as a :class:`Mineralogy` (name = sample id)."""
    row = dict(row)
    wt = {mineral_of(c): float(v) for c, v in row.items() if str(c).endswith(WT_SUFFIX) and float(v) > 0}
    tex = Texture(*(float(row[c]) for c in TEXTURE_COLUMNS))
    return Mineralogy(wt, tex, name=str(row.get(ID_COLUMN, "")))


def to_mineralogies(frame: pd.DataFrame) -> list[Mineralogy]:
    return [to_mineralogy(r) for _, r in frame.iterrows()]


def from_mineralogies(ores, ids=None) -> pd.DataFrame:
    """Sample table from :class:`Mineralogy` objects (one row each; ids default to their names)."""
    ores = list(ores)
    ids = list(ids) if ids is not None else [o.name for o in ores]
    if len(ids) != len(ores):  # zip dropped the ores without an id
        raise TwinInputError(f"from_mineralogies needs one id per ore ({len(ores)} ores). Got {len(ids)} ids: {ids}.")
    minerals = [m for m in mineral_table() if any(m in o.wt_pct for o in ores)]
    rows = []
    for sid, ore in zip(ids, ores):
        rec = {ID_COLUMN: sid}
        rec.update({m + WT_SUFFIX: ore.wt_pct.get(m, 0.0) for m in minerals})
        rec.update({c: getattr(ore.texture, c) for c in TEXTURE_COLUMNS})
        rows.append(rec)
    return pd.DataFrame(rows)


def _missing(v) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v)) or v is pd.NA


def _number(v):
    if _missing(v) or isinstance(v, bool):
        return None
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if np.isfinite(x) else None
