"""Recorded feed histories (CSV or Parquet) turned into a regular time series.

File format. Comma-separated with decimal points, UTF-8 (with or without a byte-order mark), or Parquet (its
time column may be its index); a header split by semicolons (Excel's CSV where the comma is the decimal
separator) or tabs is refused.
One row per record, a header row; lines starting with ``#`` are comments (a ``#``
inside a line is text: Excel's ``#VALUE!`` or ``#N/A`` is refused by rule 5, not read as a comment
that ends the row, nor a line starting with one as a comment: :func:`twin.atomic.csv_text`, which reads a
feed's ``psd_csv`` too).
- time: ``timestamp`` (ISO 8601) or ``time_h`` (hours, any origin); time 0 is the first record;
- composition, one family: mineral wt% columns ``<mineral>_wt_pct`` (e.g. ``quartz_wt_pct``)
  or ore fractions ``ore_<name>_frac`` (``<name>`` an ore of the scene);
- optional: ``feed_tph``, ``speed_frac_critical``, ``p80_um`` (what the plant did) and the
  texture ``mean_grain_um``, ``uniformity``, ``association_entropy`` (all three or none).
Any other column is refused.

Rules, applied in this order; each action is written to ``History.report``:
1. Out-of-order rows are sorted by time (stable); the report counts them (the fewest rows that,
   moved, leave the others in order) and names the first. A row that repeats an earlier row's
   time is counted under rule 2, not here.
2. Duplicated timestamps: the last row in file order is kept, the others dropped; the report
   counts the repeated rows, names the first and the time it repeats, and the rows dropped. Local
   timestamps without a UTC offset that step back about an hour in file order to a time recorded
   already (the clock put back at the end of daylight-saving time: that hour recorded twice) are
   refused: keeping the last copy would drop an hour of records. So are repeated times over at least
   :data:`CONFLICTING_REPEATS_SPAN_H` whose rows disagree with the earlier ones, or, in naive local times,
   any (the same hour sorted by local time).
3. NaN: a missing value (a blank cell, or one of :data:`MISSING_TEXT`) is replaced by the previous
   valid value of its column (a row with any
   missing composition value has its whole composition replaced). A recorded column that is
   empty throughout is dropped.
4. Gaps: a value may be held for at most ``max_gap_h`` (default 10 min), whether the rows are
   missing or present with NaN. A longer stretch, or missing values in the first row, is
   refused, naming the data rows (1 = first row after the header). Rows missing (a step over
   :data:`MISSING_RECORDS_INTERVALS` record intervals) are said, as held values are; in naive local
   times a step of an hour and an interval over a whole clock hour at a clock change's hour and
   month (:data:`DST_CHANGE_HOURS`, :data:`DST_CHANGE_MONTHS`; the clock put forward for
   daylight-saving time) is refused.
5. Cells that are not numbers (text), infinite values and negative values are refused, naming
   the rows; so are values outside their physical range, with the usual unit mistake named:
   ``speed_frac_critical`` in (0, 1) (a fraction of critical, not percent), ``p80_um`` at least
   :data:`scenarios.scene.ranges.P80_MIN_UM` (a P80 in mm lands below) and (when the scene's feed
   P80 is known) finer than the feed, the texture within the scene schema's ranges, and (when the
   scene's mill is known)
   ``feed_tph`` at most :data:`scenarios.scene.ranges.FEED_MAX_NOMINAL_MULTIPLE` times the
   mill's nominal feed rate (a feed in kg/h is 1000x), and with its median over the rows above 0
   at least :data:`scenarios.scene.ranges.FEED_MIN_NOMINAL_FRAC` of it (kg/s or kt/d land below).
   A ``feed_tph`` column with no value above 0 is refused: a mill never fed makes no product, so
   nothing of it can be replayed.
6. Composition rows must sum to 100 wt% (or 1) within ``sum_tol_frac`` (relative, default 2 %);
   they are rescaled to sum exactly; rows further off are refused, naming them.
7. Resampling to the scene's sample period: an input's value at grid time t_k = k*dt (the
   composition, texture, feed rate and speed, held by the run over [t_k, t_k + dt)) is the
   time-weighted mean over [t_k, t_k + dt) of the held (previous-value) signal; finer records
   are averaged, coarser ones repeated. A measured output's (``p80_um``, an analyser's reading,
   :data:`HELD_COLUMNS`) is the reading shown at t_k, the last record at or before it: a mean over
   the sample ahead set it half a sample early. Grid: 0 .. the last record, the last value held.
"""

from __future__ import annotations

import bisect
import codecs
import functools
import io
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd

from pydantic import ValidationError

from scenarios.errors import SceneError
from scenarios.scene.keypaths import did_you_mean
from scenarios.scene.ranges import feed_level_problem, feed_problem, product_p80_problem, speed_problem
from scenarios.scene.schema import Texture
from twin import csv_text, read_once
from twin.ore import mineral_names

DEFAULT_MAX_GAP_H = 10 / 60
#: Records whose intervals differ by less than this fraction of their median are regular: one-minute
#: records with ``time_h`` written to 6 decimals (3.6 ms) were reported "irregular (1 to 1 min)"
RECORD_INTERVAL_TOL_REL = 1e-3
RECORDED_COLUMNS = ("feed_tph", "speed_frac_critical", "p80_um")
#: Recorded columns that are measurements read at a time, not inputs held over a sample (rule 7).
HELD_COLUMNS = ("p80_um",)
TEXTURE_COLUMNS = ("mean_grain_um", "uniformity", "association_entropy")
_MINERAL = re.compile(r"^(.+)_wt_pct$")
_ORE = re.compile(r"^ore_(.+)_frac$")
_MAX_NAMED = 10
#: Cell texts read as a missing value (rule 3); any other text is refused (rule 5).
MISSING_TEXT = ("", "nan", "NaN", "NA", "N/A", "n/a", "null", "NULL", "None")
#: A step back in file order of naive timestamps to a time recorded already, of an hour less one record
#: interval within this [h], is a daylight-saving change (rule 2): clocks go back one hour (Lord Howe
#: Island's half hour is not caught).
DST_STEP_TOL_H = 0.1
#: Local hours at which clocks are put forward (00:00 in Chile, Brazil, Lebanon; 02:00 in Europe, North
#: America, Australia; 03:00 in some zones' rules) and the months they are (March-April in the north,
#: September-November in the south): a skipped clock hour elsewhere is an outage, said, not refused.
DST_CHANGE_HOURS = (0, 1, 2, 3)
DST_CHANGE_MONTHS = (3, 4, 9, 10, 11)
#: Repeated times whose rows disagree, over at least this span [h], are refused (rule 2): keeping the last
#: copy drops that long a stretch of other records (an hour recorded twice over the end of daylight-saving
#: time, sorted by local time; two exports of the same times), where a few repeats are a record logged twice.
CONFLICTING_REPEATS_SPAN_H = 0.5
#: A step between records longer than this multiple of their median interval is records missing (rule 4):
#: said, with the span the values were held over.
MISSING_RECORDS_INTERVALS = 1.5


@dataclass
class History:
    """A recorded history on a regular grid: ``frame`` indexed by ``time_h``."""

    frame: pd.DataFrame
    kind: Literal["mineralogy", "blend"]
    report: list[str]
    source: Path
    start: pd.Timestamp | None = None
    span_h: float = 0.0
    composition_columns: list[str] = field(default_factory=list)
    #: the report's lines that changed the records (rows sorted or dropped, values held, columns
    #: dropped): a run shows them as warnings, the rest as notes
    changes: list[str] = field(default_factory=list)
    #: SHA-256 of the file's bytes as read: what a run was fed, whatever the file holds later
    sha256: str | None = None

    @property
    def ores(self) -> list[str]:
        """Ore names of a ``blend`` history."""
        return [_ORE.match(c).group(1) for c in self.composition_columns] if self.kind == "blend" else []

    @property
    def minerals(self) -> list[str]:
        """Mineral names of a ``mineralogy`` history."""
        return [_MINERAL.match(c).group(1) for c in self.composition_columns] \
            if self.kind == "mineralogy" else []


def read_history_once(path: str | Path, sample_period_h: float, *, max_gap_h: float = DEFAULT_MAX_GAP_H,
                      feed_nominal_tph: float | None = None, feed_p80_um: float | None = None) -> History:
    """:func:`read_history`, read again only when the file has changed (its modification time or size) or is
    read with other settings: a replay read its history five times (the scene's check twice, the replay's
    span twice, the run), each a full parse. The History returned is shared: not to be changed."""
    path = Path(path)
    stat = path.stat()
    return _read_cached(str(path), stat.st_mtime_ns, stat.st_size, float(sample_period_h), float(max_gap_h),
                        feed_nominal_tph, feed_p80_um)


@functools.lru_cache(maxsize=8)
def _read_cached(path: str, _mtime_ns: int, _size: int, dt: float, max_gap_h: float, feed_nominal_tph: float | None,
                 feed_p80_um: float | None) -> History:
    return read_history(Path(path), sample_period_h=dt, max_gap_h=max_gap_h, feed_nominal_tph=feed_nominal_tph,
                        feed_p80_um=feed_p80_um)


def read_history(path: str | Path, sample_period_h: float, *, max_gap_h: float = DEFAULT_MAX_GAP_H,
                 sum_tol_frac: float = 0.02, feed_nominal_tph: float | None = None,
                 feed_p80_um: float | None = None) -> History:
    """Read, clean and resample a recorded history by the rules of this module's docstring
    (``feed_nominal_tph``: the scene's mill's nominal feed rate, for the feed's range;
    ``feed_p80_um``: the scene's feed P80, above which no recorded product P80 lies)."""
    path = Path(path)
    raw, sha256 = _read_table(path)
    where = str(path)
    report: list[str] = []
    raw = raw.assign(_row=np.arange(1, len(raw) + 1))
    time_h, start = _time_column(raw, where)
    raw = raw.assign(_t=time_h)
    comp_cols, kind, other_cols = _classify_columns(raw, where)

    changes = _order_report(raw)
    order = np.argsort(raw["_t"].to_numpy(), kind="stable")
    # each copy of the table alive at once is the file's size again, or more (its strings): rows in time order
    # already are not copied, others once (reset_index copied them again)
    df = raw if np.array_equal(order, np.arange(len(order))) else _renumbered(raw.iloc[order])
    del raw, order
    naive = start is not None and start.tzinfo is None  # local times without a UTC offset
    _refuse_conflicting_repeats(df, where, naive)
    dup = df["_t"].duplicated(keep="last").to_numpy()
    if dup.any():
        df = _renumbered(df[~dup])
    if len(df) < 1:
        raise SceneError(f"{where}: no data rows")

    t = df["_t"].to_numpy() - df["_t"].iloc[0]
    if start is not None:
        start = start + pd.Timedelta(hours=float(df["_t"].iloc[0]))
    changes += _missing_records(t, df["_row"], where, start if naive else None)
    values = _numeric(df, comp_cols + other_cols, where)
    rows, n_records = df["_row"].copy(), len(df)
    del df  # its cells as read, now in values
    neg = [f"column {c}: negative values in data rows {_names(rows[values[c].to_numpy() < 0])}; "
           "allowed: >= 0" for c in values.columns if (values[c] < 0).any()]
    if neg:
        raise SceneError(f"{where}: " + f"\n{where}: ".join(neg))
    _check_ranges(values, rows, where, feed_nominal_tph, feed_p80_um)
    _check_some_feed(values, where, feed_nominal_tph)

    comp = values[comp_cols]
    comp_missing = comp.isna().any(axis=1).to_numpy()
    comp = comp.mask(comp_missing[:, None].repeat(len(comp_cols), axis=1))
    errors: list[str] = []
    _check_holds(t, comp_missing, rows, "composition", max_gap_h, errors)
    kept_other = []
    for col in other_cols:
        missing = values[col].isna().to_numpy()
        if missing.all():
            changes.append(f"column {col} is empty; dropped")
            continue
        _check_holds(t, missing, rows, col, max_gap_h, errors)
        kept_other.append(col)
    if errors:
        raise SceneError(f"{where}: " + f"\n{where}: ".join(errors))
    n_filled = int(comp_missing.sum() + sum(values[c].isna().sum() for c in kept_other))
    if n_filled:
        changes.append(f"{n_filled} missing values held from the previous row (max gap "
                       f"{max_gap_h * 60:g} min)")
    filled = pd.concat([comp, values[kept_other]], axis=1).ffill()
    del comp, values
    report += changes

    target = 100.0 if kind == "mineralogy" else 1.0
    sums = filled[comp_cols].sum(axis=1).to_numpy()
    off = np.abs(sums / target - 1) > sum_tol_frac
    if off.any():
        raise SceneError(f"{where}: composition does not sum to {target:g} within "
                         f"{sum_tol_frac:.0%} in data rows {_names(rows[off])} (sums "
                         f"{', '.join(f'{s:.4g}' for s in sums[off][:_MAX_NAMED])})")
    rel = np.abs(sums / target - 1)
    rescaled = int(np.sum(rel > 1e-9))
    if rescaled:
        report.append(f"{rescaled} rows rescaled so that the composition sums to {target:g} "
                      f"(largest correction {rel.max() * 100:.2g} %)")
    filled[comp_cols] = filled[comp_cols].to_numpy() * (target / sums)[:, None]

    grid = np.arange(int(np.floor(t[-1] / sample_period_h + 1e-9)) + 1) * sample_period_h
    data = _time_average(t, filled.to_numpy(), grid, sample_period_h)
    frame = pd.DataFrame(data, columns=list(filled.columns), index=pd.Index(grid, name="time_h"))
    # a record within the times' rounding of a sample time is that sample's (time_h to 6 decimals: 3.6 ms)
    tol = RECORD_INTERVAL_TOL_REL * min(sample_period_h, float(np.median(np.diff(t))) if len(t) > 1 else sample_period_h)
    shown = np.clip(np.searchsorted(t, grid + tol, side="right") - 1, 0, len(t) - 1)
    for col in (c for c in HELD_COLUMNS if c in frame):  # the reading at t_k, not the mean of the sample ahead
        frame[col] = filled[col].to_numpy()[shown]
    steps = np.diff(t)
    if len(steps) and (steps.max() - steps.min()) > RECORD_INTERVAL_TOL_REL * np.median(steps):
        report.append(f"irregular records (intervals {steps.min() * 60:.3g} to {steps.max() * 60:.3g}"
                      f" min) resampled to {len(grid)} samples every {sample_period_h * 60:g} min")
    else:
        report.append(f"{n_records} records resampled to {len(grid)} samples every "
                      f"{sample_period_h * 60:g} min")
    return History(frame=frame, kind=kind, report=report, source=path, start=start,
                   span_h=float(t[-1]), composition_columns=comp_cols, changes=changes, sha256=sha256)


def _renumbered(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` (a copy of other rows) numbered 0, 1, ... as ``reset_index(drop=True)`` numbers it, not copied again."""
    df.index = pd.RangeIndex(len(df))
    return df


def _order_report(raw: pd.DataFrame) -> list[str]:
    """What rules 1 and 2 find, each counted and named apart: rows that repeat the time of an
    earlier row (a record logged twice), and rows out of time order among the rest (the fewest
    rows that, moved, leave the others in order; of equally few, the later ones)."""
    t, rows = raw["_t"].to_numpy(), raw["_row"].to_numpy()
    out = []
    repeats = raw["_t"].duplicated(keep="first").to_numpy()
    late = np.zeros(len(t), bool)
    late[~repeats] = _out_of_order(t[~repeats])
    if late.any():
        n, first = int(late.sum()), int(rows[late][0])
        more = "" if n == 1 else f"; all: data rows {_names(rows[late])}"
        out.append(f"{n} row{'s' if n > 1 else ''} out of time order (first: data row {first}{more}); "
                   "sorted by time")
    if repeats.any():
        time_col = "timestamp" if "timestamp" in raw.columns else "time_h"
        i = int(np.argmax(repeats))
        original = int(rows[np.flatnonzero(t == t[i])[0]])
        dropped = raw["_t"].duplicated(keep="last").to_numpy()
        n = int(repeats.sum())
        # the cells as texts of the rows whose time repeats only (all rows' were many times the file's size)
        shared = raw["_t"].duplicated(keep=False).to_numpy()
        cells = raw.loc[shared].drop(columns=["_row", "_t", time_col]).astype(str)
        unlike = dropped.copy()
        unlike[shared] &= (cells != cells.groupby(t[shared]).transform("last")).any(axis=1).to_numpy()
        differ = (f"; the values of dropped data row{'s' if unlike.sum() > 1 else ''} {_names(rows[unlike])} differ "
                  "from those kept") if unlike.any() else ""
        out.append(f"{n} row{'s' if n > 1 else ''} repeat{'' if n > 1 else 's'} the time of an earlier row "
                   f"(duplicated timestamps; first: data row {int(rows[i])}, {time_col} {raw[time_col].iloc[i]} "
                   f"as data row {original}): dropped data rows {_names(rows[dropped])}, keeping the last row of "
                   f"each time{differ}")
    return out


def _refuse_conflicting_repeats(df: pd.DataFrame, where: str, naive: bool) -> None:
    """Rule 2: rows (sorted by time) that repeat earlier rows' times over at least
    :data:`CONFLICTING_REPEATS_SPAN_H` are refused when they disagree with them, or, in naive local times,
    at all (an hour recorded twice, the clock put back, in a file sorted by local time: keeping the last copy
    of each time drops an hour and places every later record an hour early)."""
    repeated = df["_t"].duplicated(keep=False).to_numpy()
    if not repeated.any():
        return
    cells = df.loc[repeated].drop(columns=["_row", "_t"]).astype(str)
    differ = cells.groupby(df.loc[repeated, "_t"].to_numpy()).nunique().gt(1).any(axis=1)
    times = (differ.index if naive else differ.index[differ.to_numpy()]).to_numpy(dtype=float)
    if times.size < 2 or times.max() - times.min() < CONFLICTING_REPEATS_SPAN_H:
        return
    rows = df.loc[repeated & df["_t"].isin(times).to_numpy(), "_row"]
    why = ("Local times without a UTC offset over the end of daylight-saving time (the clock put back, that hour "
           "recorded twice and sorted together), or two exports of the same times? Give the timestamps with their "
           "offset (e.g. 2026-10-25T02:30:00+02:00, then +01:00) or in UTC, or remove one copy" if naive else
           "Two records of the same times (overlapping exports?): remove one copy")
    raise SceneError(f"{where}: data rows {_names(rows)} repeat {times.size} times over "
                     f"{(times.max() - times.min()) * 60:.0f} min{'' if naive else ' with other values'}; keeping the "
                     f"last copy of each would drop that stretch of records. {why}.")


def _missing_records(t: np.ndarray, rows: pd.Series, where: str, naive_start: pd.Timestamp | None) -> list[str]:
    """Rule 4's missing rows, said: steps between records longer than :data:`MISSING_RECORDS_INTERVALS`
    median intervals, over which the values before were held (NaN cells held were said; rows missing were
    not). In naive local times (``naive_start``), a step of an hour and an interval that skips a whole clock
    hour is the clock put forward for daylight-saving time: refused, as rule 2 refuses it put back."""
    steps = np.diff(t)
    if not steps.size:
        return []
    interval = float(np.median(steps))
    long = np.flatnonzero(steps > MISSING_RECORDS_INTERVALS * interval)
    if not long.size:
        return []
    if naive_start is not None:
        for i in long[np.abs(steps[long] - (1.0 + interval)) <= DST_STEP_TOL_H]:
            before, after = (naive_start + pd.Timedelta(hours=float(t[k])) for k in (i, i + 1))
            hour = before.ceil("h")
            if (hour + pd.Timedelta(hours=1) <= after and hour.hour in DST_CHANGE_HOURS
                    and hour.month in DST_CHANGE_MONTHS):  # a whole clock hour never recorded, where clocks change
                raise SceneError(f"{where}: timestamp: data row {int(rows.iloc[i + 1])} ({after}) follows {before} "
                                 f"an hour and a record interval later, skipping the clock hour from "
                                 f"{hour}: local times without a UTC offset, the clock put forward for "
                                 "daylight-saving time, so an hour that never happened would be held as recorded "
                                 "and every later record placed an hour late. Give the timestamps with their offset "
                                 "(e.g. 2026-03-29T01:59:00+01:00, then 03:00:00+02:00) or in UTC.")
    worst = long[np.argmax(steps[long])]
    return [f"records missing {'once' if long.size == 1 else f'{long.size} times'} (steps over "
            f"{MISSING_RECORDS_INTERVALS:g} record intervals of {interval * 60:.3g} min; the longest "
            f"{steps[worst] * 60:.3g} min after data row {int(rows.iloc[worst])}): the values before each held "
            "over it"]


def _out_of_order(t: np.ndarray) -> np.ndarray:
    """Mask of the rows out of time order in distinct times ``t``: all but a longest increasing
    run of rows (a longest increasing subsequence, built from the end so that of equally long
    ones it keeps the earlier rows: 0, 1, 3, 2.5, 4 has 2.5 out of order, not 3)."""
    if np.all(np.diff(t) > 0):
        return np.zeros(len(t), bool)
    tails: list[float] = []  # smallest -t ending an increasing run of each length (scanning backwards)
    ends: list[int] = []
    prev = np.full(len(t), -1)
    for i in range(len(t) - 1, -1, -1):
        k = bisect.bisect_left(tails, -t[i])
        if k == len(tails):
            tails.append(-t[i])
            ends.append(i)
        else:
            tails[k], ends[k] = -t[i], i
        prev[i] = ends[k - 1] if k else -1
    keep = np.zeros(len(t), bool)
    i = ends[-1]
    while i != -1:
        keep[i], i = True, prev[i]
    return ~keep


def _read_table(path: Path) -> tuple[pd.DataFrame, str]:
    """The file's table and the SHA-256 of the bytes it was parsed from (read once: a file rewritten meanwhile
    is not recorded with the other version's hash)."""
    if not path.is_file():
        raise SceneError(f"{path}: history file not found")
    suffix = path.suffix.lower()
    try:
        data, sha256 = read_once(path)
        return _parse_table(path, suffix, data), sha256
    except SceneError:
        raise
    except (ValueError, OSError, pd.errors.ParserError) as exc:
        raise SceneError(f"{path}: cannot read the history: {exc}") from None


def _parse_table(path: Path, suffix: str, data: bytes) -> pd.DataFrame:
    if suffix == ".csv":
        # comment lines blank (csv_text, as a feed's psd_csv); a trailing delimiter on every row
        # (index_col=False) made pandas shift the columns by one
        body, header = _csv_bytes(data)
        _refuse_other_delimiter(path, header)
        try:
            table = pd.read_csv(io.BufferedReader(_Pieces(body)), encoding="utf-8", skipinitialspace=True, index_col=False,
                                keep_default_na=False, na_values=list(MISSING_TEXT))
        except pd.errors.ParserError as exc:
            raise SceneError(_row_length_problem(path, str(exc), csv_text(data))) from None
        # a delimiter closing the header row too makes an unnamed empty column: nothing was recorded in it
        return table.drop(columns=[c for c in table.columns
                                   if str(c).startswith("Unnamed: ") and table[c].isna().all()])
    if suffix in (".parquet", ".pq"):
        table = pd.read_parquet(io.BytesIO(data))
        if table.index.name in ("timestamp", "time_h") and table.index.name not in table.columns:
            table = table.reset_index()  # a frame indexed by time (df.set_index('timestamp')) keeps it there
        return table
    raise SceneError(f"{path}: history must be .csv or .parquet (got {suffix or 'no suffix'!r})")


#: Bytes of a CSV history blanked a piece at a time (each cut after a line feed): the whole file split into lines
#: (a Python string each) and joined again took several times the file's size at once.
CSV_PIECE_BYTES = 1 << 20


def _csv_bytes(data: bytes) -> tuple[list[memoryview], str]:
    """:func:`twin.atomic.csv_text` of ``data`` encoded as UTF-8 in pieces (one with no ``#`` is the file's bytes,
    unchanged, once checked as UTF-8: not copied), and its first non-blank line (the header)."""
    whole = data
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8):]  # the one mark utf-8-sig drops (a second is text)
    view, parts, header, start = memoryview(data), [], "", 0
    while start < len(data):
        end = data.find(b"\n", start + CSV_PIECE_BYTES) + 1 or len(data)
        piece, hashes = view[start:end], data.find(b"#", start, end) >= 0
        try:
            # a line feed ahead, so that a piece's leading U+FEFF stays text as it does mid-file
            text = csv_text(b"\n" + piece)[1:] if hashes else str(piece, "utf-8")
        except UnicodeDecodeError:
            whole.decode("utf-8-sig")  # the whole file's error, at its position in the file
            raise
        if hashes:
            piece = memoryview(text.encode("utf-8"))
        header = header or text.lstrip().partition("\n")[0]
        parts.append(piece)
        start = end
    return parts, header


class _Pieces(io.RawIOBase):
    """The pieces of :func:`_csv_bytes` read as one file, each let go once read."""

    def __init__(self, pieces: list[memoryview]):
        self._pieces = pieces[::-1]

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        while self._pieces and not len(self._pieces[-1]):
            self._pieces.pop()
        if not self._pieces:
            return 0
        head = self._pieces[-1]
        n = min(len(buffer), len(head))
        buffer[:n] = head[:n]
        self._pieces[-1] = head[n:]
        return n


def _row_length_problem(path: Path, said: str, text: str) -> str:
    """pandas' refusal of a row with more cells than the header (``said``; its line counted in ``text``, the file
    with its comment lines blank) as the row, what likely split it and what is allowed."""
    found = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", said)
    if found is None:
        return f"{path}: cannot read the history: {said}"
    header, line, cells = map(int, found.groups())
    row = text.splitlines()[line - 1] if line <= len(text.splitlines()) else ""
    return (f"{path}: line {line} has {cells} cells, the header {header} ({row[:200]!r}): a decimal comma (30,4) or "
            "a comma inside a text splits a cell; allowed: numbers with a decimal point (30.4), texts with commas "
            "in double quotes")


#: Delimiters of CSV files that are not comma-separated, named in the refusal: Excel writes ";" (and decimal commas)
#: where the comma is the decimal separator, and "Text (tab-delimited)" files use tabs.
OTHER_DELIMITERS = {";": "semicolon", "\t": "tab"}


def _refuse_other_delimiter(path: Path, header: str) -> None:
    """A header row split by another delimiter than the comma: pandas read it as one column, warned that data
    would be lost where decimal commas split the rows, and the time column was reported missing."""
    found = [name for sep, name in OTHER_DELIMITERS.items() if sep in header]
    if "," in header or not found:
        return
    raise SceneError(f"{path}: the header row is {found[0]}-separated ({header.strip()[:60]!r}...); allowed: a "
                     "comma-separated file with decimal points (Excel: 'CSV UTF-8 (comma delimited)' with '.' as the "
                     "decimal separator), or Parquet")


def _time_column(raw: pd.DataFrame, where: str) -> tuple[np.ndarray, pd.Timestamp | None]:
    has_ts, has_h = "timestamp" in raw.columns, "time_h" in raw.columns
    if has_ts == has_h:
        raise SceneError(f"{where}: needs exactly one time column, `timestamp` (ISO 8601) or "
                         f"`time_h` (got columns {list(raw.columns)})")
    if has_h:
        return _finite_times(pd.to_numeric(raw["time_h"], errors="coerce").to_numpy(dtype=float), raw, where,
                             "time_h"), None
    stamps = raw["timestamp"]
    if pd.api.types.is_numeric_dtype(stamps):  # epoch seconds: unreadable as ISO 8601, named as such
        stamps = stamps.astype(str)
    try:
        ts = pd.to_datetime(stamps, errors="coerce", format="ISO8601")
    except ValueError as exc:  # e.g. rows with and without a UTC offset: pandas refuses to mix them
        text = raw["timestamp"].astype(str)
        has_offset = text.str.contains(r"(?:Z|[+-]\d\d:?\d\d)$", regex=True)
        if has_offset.all():  # offsets that change (a daylight-saving change): one clock, UTC
            ts = pd.to_datetime(raw["timestamp"], errors="coerce", format="ISO8601", utc=True)
            return _hours_since_start(ts, raw, where)
        first = _names(raw["_row"][has_offset != has_offset.iloc[0]][:1]) if has_offset.nunique() > 1 else "?"
        raise SceneError(f"{where}: timestamp: rows with and without a UTC offset cannot be put on one clock "
                         f"(first data row that differs from the first: {first}); give every timestamp an offset "
                         f"(e.g. +00:00) or none. pandas said: {exc}") from None
    if ts.dt.tz is None:
        _refuse_clock_put_back(ts, raw, where)
    return _hours_since_start(ts, raw, where)


def _refuse_clock_put_back(ts: pd.Series, raw: pd.DataFrame, where: str) -> None:
    """Rule 2's daylight-saving change: naive timestamps stepping back about an hour in file order to a
    time recorded already (one row typed an hour late steps back to a time not yet recorded)."""
    step_h = (ts.diff() / pd.Timedelta(hours=1)).to_numpy(dtype=float)
    forward = step_h[step_h > 0]
    interval = float(np.median(forward)) if forward.size else 0.0
    # after the hour's last record (one interval before the clock goes back) comes its first again
    hour_back = (step_h >= -1.0 - DST_STEP_TOL_H) & (step_h <= -(1.0 - interval) + DST_STEP_TOL_H)
    back = np.flatnonzero(hour_back & ts.duplicated(keep="first").to_numpy())
    if back.size:
        i = int(back[0])
        row, now, before = int(raw["_row"].iloc[i]), raw["timestamp"].iloc[i], raw["timestamp"].iloc[i - 1]
        raise SceneError(f"{where}: timestamp: data row {row} ({now}) steps back about an hour from the row "
                         f"before ({before}): local times without a UTC offset, the clock put back at the end of "
                         "daylight-saving time, so that hour is recorded twice and one copy would be dropped as "
                         "duplicates. Give the timestamps with their offset (e.g. 2026-10-25T02:30:00+02:00, then "
                         "+01:00) or in UTC.")


def _hours_since_start(ts: pd.Series, raw: pd.DataFrame, where: str) -> tuple[np.ndarray, pd.Timestamp | None]:
    """Hours of the parsed timestamps since the earliest, and that start."""
    if not ts.notna().any():
        return _finite_times(np.full(len(raw), np.nan), raw, where, "timestamp"), None
    start = ts.min()
    return _finite_times(((ts - start) / pd.Timedelta(hours=1)).to_numpy(dtype=float), raw, where,
                         "timestamp"), start


#: What each time column takes, for the message naming an unreadable one.
TIME_FORMATS = {"timestamp": "ISO 8601, e.g. 2026-03-01T06:00:00 or 2026-03-01 06:00:00+01:00 (not day-first "
                             "dates, time-zone names or epoch seconds: convert those, or give hours in a "
                             "time_h column)",
                "time_h": "a number of hours, any origin"}


def _finite_times(t: np.ndarray, raw: pd.DataFrame, where: str, column: str) -> np.ndarray:
    bad = ~np.isfinite(t)
    if bad.any():
        first = raw[column][bad].iloc[0]
        raise SceneError(f"{where}: {column}: unreadable or missing time in data rows {_names(raw['_row'][bad])} "
                         f"(e.g. '{first}'); allowed: {TIME_FORMATS[column]}")
    return t


def _classify_columns(raw: pd.DataFrame, where: str) -> tuple[list[str], str, list[str]]:
    minerals = mineral_names()
    cols = [c for c in raw.columns if c not in ("timestamp", "time_h", "_row", "_t")]
    mineral_cols = [c for c in cols if _MINERAL.match(c)]
    ore_cols = [c for c in cols if _ORE.match(c)]
    other = [c for c in cols if c not in mineral_cols and c not in ore_cols]
    problems = []
    allowed_other = RECORDED_COLUMNS + TEXTURE_COLUMNS
    for c in other:
        if c not in allowed_other:
            hint = did_you_mean(c, list(allowed_other) + [f"{m}_wt_pct" for m in minerals])
            problems.append(f"unknown column {c!r}{hint}; allowed: <mineral>_wt_pct, "
                            f"ore_<name>_frac, {', '.join(allowed_other)}")
    for c in mineral_cols:
        m = _MINERAL.match(c).group(1)
        if m not in minerals:
            problems.append(f"column {c!r}: unknown mineral{did_you_mean(m, minerals)}")
    texture = [c for c in TEXTURE_COLUMNS if c in other]
    if texture and len(texture) < len(TEXTURE_COLUMNS):  # feed.history_texture would replace the recorded ones
        problems.append(f"texture column{'s' if len(texture) > 1 else ''} {', '.join(texture)} without "
                        f"{', '.join(c for c in TEXTURE_COLUMNS if c not in texture)}; allowed: all three texture "
                        "columns, or none (and the scene's feed.history_texture)")
    if bool(mineral_cols) == bool(ore_cols):
        problems.append("needs one composition family: <mineral>_wt_pct columns or "
                        "ore_<name>_frac columns (not both, not neither)")
    if problems:
        raise SceneError(f"{where}: " + f"\n{where}: ".join(problems))
    kind = "mineralogy" if mineral_cols else "blend"
    return (mineral_cols or ore_cols), kind, other


def _numeric(df: pd.DataFrame, cols: list[str], where: str) -> pd.DataFrame:
    """The columns as floats (empty cells NaN); SceneError naming text cells and infinite values."""
    out, errors = {}, []
    for col in cols:
        raw = df[col]
        num = pd.to_numeric(raw, errors="coerce").astype(float)
        text = raw.notna().to_numpy() & num.isna().to_numpy()
        if text.any():
            first = raw[text].iloc[0]
            errors.append(f"column {col}: not a number in data rows {_names(df['_row'][text])} "
                          f"(e.g. {first!r}); allowed: a number, or for a missing value (held from the row before, "
                          "up to the history's max gap) an empty cell or one of " + ", ".join(MISSING_TEXT[1:]))
        inf = np.isinf(num.to_numpy())
        if inf.any():
            errors.append(f"column {col}: infinite value in data rows {_names(df['_row'][inf])}")
        out[col] = num
    if errors:
        raise SceneError(f"{where}: " + f"\n{where}: ".join(errors))
    return pd.DataFrame(out, index=df.index)


def _check_ranges(values: pd.DataFrame, rows: pd.Series, where: str, feed_nominal_tph, feed_p80_um) -> None:
    """Refuse recorded values outside their physical ranges, naming rows and the likely mistake."""
    checks = {"speed_frac_critical": speed_problem,
              "feed_tph": lambda v: feed_problem(v, feed_nominal_tph),
              "p80_um": lambda v: product_p80_problem(v, feed_p80_um)}
    checks |= {key: functools.partial(_texture_problem, key) for key in TEXTURE_COLUMNS}
    errors = []
    for col, problem in checks.items():
        if col not in values:
            continue
        v = values[col].to_numpy()
        # each distinct value once (a historian holds a reading over many rows): a call per cell was most of
        # the time reading a day of one-second records took
        distinct, which = np.unique(v, return_inverse=True)
        which = which.ravel()
        msgs = [None if np.isnan(x) else problem(float(x)) for x in distinct]
        bad = np.flatnonzero(np.array([m is not None for m in msgs], bool)[which])
        if len(bad):
            errors.append(f"column {col}: {msgs[which[bad[0]]]} in data rows {_names(rows.iloc[bad])}")
    if errors:
        raise SceneError(f"{where}: " + f"\n{where}: ".join(errors))


def _check_some_feed(values: pd.DataFrame, where: str, feed_nominal_tph: float | None) -> None:
    """Refuse a recorded feed rate that is 0 in every row that has one, or whose level is no feed of
    the mill (a feed in kg/s or kt/d; rule 5)."""
    if "feed_tph" not in values:
        return
    feed = values["feed_tph"].dropna().to_numpy()
    if len(feed) and not np.any(feed > 0):
        raise SceneError(f"{where}: column feed_tph: 0 t/h in all {len(feed)} data rows that give it; allowed: "
                         "rates >= 0 t/h with at least one above 0 (a mill never fed makes no product to replay); "
                         "if the feed rate was not recorded, leave the column empty or remove it")
    problem = feed_level_problem(float(np.median(feed[feed > 0])), feed_nominal_tph) if len(feed) else None
    if problem:
        raise SceneError(f"{where}: column feed_tph: {problem}")


#: A texture inside every key's range (the reference ores' own scale), the other keys of one checked cell.
_TEXTURE_INSIDE = {"mean_grain_um": 100.0, "uniformity": 0.5, "association_entropy": 0.5}


@functools.lru_cache(maxsize=4096)
def _texture_problem(key: str, value: float) -> str | None:
    """The scene schema's range of a texture key (``[ores.NAME.texture]``), applied to a cell."""
    try:
        Texture.model_validate({**_TEXTURE_INSIDE, key: value})
    except ValidationError as exc:
        return f"{value:g} {exc.errors()[0]['msg'].lower()}"
    return None


def _check_holds(t: np.ndarray, missing: np.ndarray, rows: pd.Series, what: str,
                 max_gap_h: float, errors: list[str]) -> None:
    """Refuse a value held longer than ``max_gap_h`` or missing in the first row."""
    valid = np.flatnonzero(~missing)
    if len(valid) == 0 or valid[0] != 0:
        errors.append(f"{what}: missing in the first data row {int(rows.iloc[0])}; no earlier "
                      "value to hold")
        return
    ends = np.append(t[valid[1:]], t[-1])
    held = ends - t[valid]
    too_long = np.flatnonzero(held > max_gap_h + 1e-12)
    for i in too_long[:_MAX_NAMED]:
        a = valid[i]
        b = valid[i + 1] if i + 1 < len(valid) else len(t) - 1
        errors.append(f"{what}: no valid value for {held[i] * 60:.4g} min between data rows "
                      f"{int(rows.iloc[a])} and {int(rows.iloc[b])} (limit {max_gap_h * 60:g} min: the scene's "
                      "feed.history_max_gap_h)")
    if len(too_long) > _MAX_NAMED:
        errors.append(f"{what}: and {len(too_long) - _MAX_NAMED} more gaps longer than "
                      f"{max_gap_h * 60:g} min")


def _time_average(t: np.ndarray, values: np.ndarray, grid: np.ndarray, dt: float) -> np.ndarray:
    """Mean of the zero-order-hold signal (values held from t_i; values[0] before t_0) over each cell
    [g, g + dt) of the contiguous grid, each cell summed from its own pieces, and exact where one value
    is held over the cell: the difference of two running integrals left round-off where the signal was
    0 (a feed of 1e-13 t/h, so 4.5e6 kWh/t)."""
    bounds = np.append(grid, grid[-1] + dt)
    inside = t[(t > bounds[0]) & (t < bounds[-1])]
    edges = np.unique(np.concatenate([bounds, inside]))
    start, length = edges[:-1], np.diff(edges)
    held = np.clip(np.searchsorted(t, start, side="right") - 1, 0, len(t) - 1)
    cell = np.clip(np.searchsorted(bounds, start, side="right") - 1, 0, len(grid) - 1)
    first = np.searchsorted(cell, np.arange(len(grid)))
    out = np.empty((len(grid), values.shape[1]))
    for c in range(values.shape[1]):  # a column at a time: all columns' pieces at once were another copy of them
        piece_values = values[held, c]
        mean = np.bincount(cell, weights=piece_values * length, minlength=len(grid)) / dt
        # a value held over a whole cell is its mean exactly (an entropy of 1 stays in [0, 1])
        lo, hi = np.minimum.reduceat(piece_values, first), np.maximum.reduceat(piece_values, first)
        out[:, c] = np.where(lo == hi, lo, mean)
    return out


def _names(rows: pd.Series) -> str:
    rows = [int(r) for r in rows]
    text = ", ".join(str(r) for r in rows[:_MAX_NAMED])
    return text + (f" and {len(rows) - _MAX_NAMED} more" if len(rows) > _MAX_NAMED else "")
