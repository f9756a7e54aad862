"""Merge the rows dem_drum.py printed (one dict a line) into benchmarks/results/dem_drum.csv/.md.

Used when dem_drum.py is stopped before its end (shared machine): the rows are the same
numbers, parsed from its log; rows of the same case and speed already in the table are
replaced, the power-model columns recomputed (dem_drum.add_models).
Run: ``python benchmarks/dem_drum_table_from_log.py LOG``.
"""

import ast
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

import pandas as pd

from dem_common import OUT, write_table
from dem_drum import NOTES, TITLE, add_models, merge

rows = [ast.literal_eval(line) for line in open(sys.argv[1]) if line.startswith("{")]
path = os.path.join(OUT, "dem_drum.csv")
old = pd.read_csv(path) if os.path.exists(path) else None
write_table(add_models(merge(old, pd.DataFrame(rows))), "dem_drum", TITLE, NOTES)
