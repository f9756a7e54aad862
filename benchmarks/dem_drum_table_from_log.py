"""Write benchmarks/results/dem_drum.csv/.md from the rows dem_drum.py printed (one dict a line).

Used when dem_drum.py is stopped before its end (shared machine): the rows are the same
numbers, parsed from its log. Run: ``python benchmarks/dem_drum_table_from_log.py LOG``.
"""

import ast
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

import pandas as pd

from dem_common import write_table

rows = [ast.literal_eval(line) for line in open(sys.argv[1]) if line.startswith("{")]
write_table(pd.DataFrame(rows), "dem_drum",
            "Drum DEM of the lab mill (0.5 m x 0.3 m, 25 mm balls, 8 lifters, J = 0.35)",
            "3D periodic slice 0.1 m long scaled to 0.3 m; power = -torque x omega; ball Young's "
            "modulus 1 GPa; impact energy = m* v_n^2/2 at first contact; settle 1 rev, measure 3 revs. "
            "Rows parsed from the log of benchmarks/dem_drum.py (stopped early on a shared machine: "
            "speeds above 0.7 and the stiffness check are not in this table).")
