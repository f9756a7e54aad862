"""The audit log of a served controller: one row per cycle (every move, or why there was none),
as Parquet files in a folder of the service's own.

Rows are kept in memory and written every ``flush_every`` cycles and at shutdown as one
complete file ``audit-<start>-<part>.parquet`` (written under a ``.partial`` name, then renamed),
so a crash loses at most the unflushed rows and never leaves a torn file; a restart adds files
beside the old ones. :func:`read_audit` reads them back in order. The folder may hold only such
files: the service never writes into a folder it did not make for this purpose. It is checked at
once and made at the first write, so a start that fails leaves no empty folder behind.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd

from scenarios.errors import SceneError

PART = re.compile(r"^audit-\d{8}T\d{6}\d*Z-\d{5}\.parquet$")
#: A part a crash interrupted (ours, so the folder stays usable; never read back).
PARTIAL = re.compile(r"^audit-\d{8}T\d{6}\d*Z-\d{5}\.parquet\.partial$")


def check_audit_dir(path: Path) -> Path:
    """The folder (not made here: :meth:`AuditLog.flush` makes it); SceneError if it is a file or
    holds anything but audit files."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise SceneError(f"--audit {path}: is a file; give a folder for the audit log")
    if path.is_dir():
        foreign = sorted(p.name for p in path.iterdir() if not (PART.match(p.name) or PARTIAL.match(p.name)))
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

    def record(self, row: dict) -> None:
        self._rows.append(row)
        if len(self._rows) >= self.flush_every:
            self.flush()

    def flush(self) -> Path | None:
        """Write the pending rows as one part; returns its path (None if nothing was pending)."""
        if not self._rows:
            return None
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / f"{self._stem}-{self._part:05d}.parquet"
        tmp = path.with_name(path.name + ".partial")
        pd.DataFrame(self._rows).to_parquet(tmp, index=False)
        tmp.replace(path)
        self._rows, self._part = [], self._part + 1
        return path


def read_audit(folder: Path) -> pd.DataFrame:
    """Every audit part of a folder, in the order written."""
    if not Path(folder).is_dir():  # iterdir's bare error named no reason
        raise FileNotFoundError(f"{folder}: no audit folder there (serve --audit makes it at its first write: a "
                                "service that wrote no cycle leaves none)")
    parts = sorted(p for p in Path(folder).iterdir() if PART.match(p.name))
    if not parts:
        return pd.DataFrame()
    return pd.concat([pd.read_parquet(p) for p in parts], ignore_index=True)
