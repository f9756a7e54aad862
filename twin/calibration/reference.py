"""The data calibrations are fitted to: MISSION.md's laboratory table (P80, specific energy and
throughput at constant load for the reference ores A-D), shipped as ``data/reference_table.csv``."""

from __future__ import annotations

import csv
from pathlib import Path

#: The table's KPIs, in the order of every residual vector.
KPIS = ("p80_um", "specific_energy_kwh_t", "throughput_kg_h")
REFERENCE_TABLE_PATH = Path(__file__).resolve().parent / "data" / "reference_table.csv"


def reference_table() -> dict:
    """{ore: {kpi: value}} of MISSION.md's reference table."""
    text = REFERENCE_TABLE_PATH.read_text(encoding="utf-8")
    rows = csv.DictReader([ln for ln in text.splitlines() if ln and not ln.startswith("#")])
    return {r["ore"]: {k: float(r[k]) for k in KPIS} for r in rows}
