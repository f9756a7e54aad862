"""The audit log of a served controller: one row per cycle (every move, or why there was none),
as Parquet files in a folder of the service's own.

Rows are written every ``flush_every`` cycles and at shutdown as one complete file
``audit-<start>-<part>.parquet`` (written under a ``.partial`` name, then renamed), never a torn
file; meanwhile each row is appended to the part's journal ``audit-<start>-<part>.jsonl`` as it is
recorded (flushed to the disk), removed once the part is written, so a crash (a kill, a power cut)
loses no recorded row: up to ``flush_every`` cycles, an hour at 3-minute samples, were lost before.
A restart adds files beside the old ones. :func:`read_audit` reads them back in order, a crashed
run's journal too. The folder may hold only such files: the service never writes into a folder it
did not make for this purpose. It is checked at once and made at the first row, so a start that
fails before its first cycle leaves no empty folder behind.
"""

from __future__ import annotations

import json
import math
import os
import re
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd

from scenarios.errors import SceneError

PART = re.compile(r"^audit-\d{8}T\d{6}\d*Z-\d{5}\.parquet$")
#: A part a crash interrupted (ours, so the folder stays usable; never read back).
PARTIAL = re.compile(r"^audit-\d{8}T\d{6}\d*Z-\d{5}\.parquet\.partial$")
#: The rows of a part not yet written, one JSON object a line (read back only when its part is missing: a crash).
JOURNAL = re.compile(r"^audit-\d{8}T\d{6}\d*Z-\d{5}\.jsonl$")


def check_audit_dir(path: Path) -> Path:
    """The folder (not made here: :meth:`AuditLog.flush` makes it); SceneError if it is a file or
    holds anything but audit files."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise SceneError(f"--audit {path}: is a file; give a folder for the audit log")
    if path.is_dir():
        foreign = sorted(p.name for p in path.iterdir()
                         if not (PART.match(p.name) or PARTIAL.match(p.name) or JOURNAL.match(p.name)))
        if foreign:
            names = ", ".join(foreign[:3]) + (" ..." if len(foreign) > 3 else "")
            raise SceneError(f"--audit {path}: the folder holds files that are not audit parts ({names}); "
                             "give a new or an audit folder")
    return path


class AuditLog:
    """Rows of one service run, flushed to Parquet parts (see the module docstring)."""

    def __init__(self, folder: Path, flush_every: int = 20):
        if not isinstance(flush_every, int) or flush_every < 1:
            raise SceneError(f"The 'flush_every' of AuditLog must be an int >= 1. Got {flush_every!r}.")
        self.folder = check_audit_dir(folder)
        self.flush_every = flush_every
        self._stem = "audit-" + datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S%fZ")
        self._rows: list[dict] = []
        self._part = 0

    def _path(self, suffix: str) -> Path:
        return self.folder / f"{self._stem}-{self._part:05d}{suffix}"

    def record(self, row: dict) -> None:
        self._rows.append(row)
        self.folder.mkdir(parents=True, exist_ok=True)
        with open(self._path(".jsonl"), "a", encoding="utf-8") as f:
            f.write(json.dumps({k: _jsonable(v) for k, v in row.items()}, allow_nan=False) + "\n")
            f.flush()
            os.fsync(f.fileno())
        if len(self._rows) >= self.flush_every:
            self.flush()

    def flush(self) -> Path | None:
        """Write the pending rows as one part; returns its path (None if nothing was pending)."""
        if not self._rows:
            return None
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self._path(".parquet")
        tmp = path.with_name(path.name + ".partial")
        pd.DataFrame(self._rows).to_parquet(tmp, index=False)
        tmp.replace(path)
        self._path(".jsonl").unlink(missing_ok=True)
        self._rows, self._part = [], self._part + 1
        return path


def _jsonable(value):
    """A row's value for the journal: datetimes as ISO text (read back as UTC times), NaN and infinities as null."""
    if isinstance(value, datetime):
        return value.isoformat()
    if hasattr(value, "item") and not isinstance(value, (list, dict)):  # numpy scalars
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value if isinstance(value, (str, int, float, bool, type(None))) else str(value)


def _read_journal(path: Path) -> pd.DataFrame:
    """A crashed part's rows (a last line the crash cut is left out)."""
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            break
    frame = pd.DataFrame(rows)
    if "wall_time_utc" in frame:
        frame["wall_time_utc"] = pd.to_datetime(frame["wall_time_utc"], utc=True)
    return frame


def read_audit(folder: Path) -> pd.DataFrame:
    """Every audit part of a folder, in the order written."""
    if not Path(folder).is_dir():  # iterdir's bare error named no reason
        raise FileNotFoundError(f"{folder}: no audit folder there (serve --audit makes it at its first write: a "
                                "service that wrote no cycle leaves none)")
    files = sorted(p for p in Path(folder).iterdir() if PART.match(p.name)
                   or (JOURNAL.match(p.name) and not p.with_suffix(".parquet").exists()))
    frames = [pd.read_parquet(p) if p.suffix == ".parquet" else _read_journal(p) for p in files]
    frames = [f for f in frames if len(f)]
    if not frames:
        return pd.DataFrame()
    return pd.concat(frames, ignore_index=True)
