"""Merge the rows dem_drum.py printed (one dict a line) into benchmarks/results/dem_drum.csv/.md.

Used when dem_drum.py is stopped before its end (shared machine): the rows are the same
numbers, parsed from its log; rows of the same case and speed already in the table are
replaced, the power-model columns recomputed (dem_drum.add_models).
Run: ``python benchmarks/dem_drum_table_from_log.py LOG``.
"""

import argparse
import ast
import json
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

import pandas as pd

from dem_common import OUT, write_table
from dem_drum import TITLE, add_models, merge, notes


def _parse_row(line: str):
    """A row as dem_drum.py prints it (JSON), or as it printed it before (a dict's repr, readable
    unless it holds a bare nan); None if neither."""
    try:
        return json.loads(line)
    except ValueError:
        pass
    try:
        return ast.literal_eval(line)
    except (ValueError, SyntaxError):
        return None


def read_rows(ap, log: str) -> list[dict]:
    """The dict lines of ``log``; anything unreadable is refused through ``ap.error`` before a file is written."""
    try:
        with open(log) as fh:
            lines = [(k, line) for k, line in enumerate(fh, 1) if line.startswith("{")]
    except (OSError, UnicodeDecodeError) as e:
        ap.error(f"LOG {log!r}: cannot be read ({e}). Nothing written.")
    rows = []
    for k, line in lines:
        rows.append(_parse_row(line))
        if not isinstance(rows[-1], dict):
            ap.error(f"LOG {log!r}, line {k}: not a row dict as dem_drum.py prints them. Nothing written.")
    if not rows:
        ap.error(f"LOG {log!r}: no row (a line starting with '{{') to merge. Nothing written.")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", metavar="LOG", help="the output of an interrupted dem_drum.py run")
    rows = read_rows(ap, ap.parse_args(argv).log)
    path = os.path.join(OUT, "dem_drum.csv")
    old = pd.read_csv(path) if os.path.exists(path) else None
    df = merge(old, pd.DataFrame(rows))
    write_table(add_models(df), "dem_drum", TITLE, notes(df))


if __name__ == "__main__":
    main()
