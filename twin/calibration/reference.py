"""The data calibrations are fitted to: MISSION.md's laboratory table (P80, specific energy and
throughput at constant load for the reference ores A-D), shipped as ``data/reference_table.csv``."""

from __future__ import annotations

import csv
import hashlib
import json
from pathlib import Path

#: The table's KPIs, in the order of every residual vector.
KPIS = ("p80_um", "specific_energy_kwh_t", "throughput_kg_h")
REFERENCE_TABLE_PATH = Path(__file__).resolve().parent / "data" / "reference_table.csv"


def reference_table() -> dict:
    """{ore: {kpi: value}} of MISSION.md's reference table."""
    text = REFERENCE_TABLE_PATH.read_text(encoding="utf-8")
    rows = csv.DictReader([ln for ln in text.splitlines() if ln and not ln.startswith("#")])
    return {r["ore"]: {k: float(r[k]) for k in KPIS} for r in rows}


def given_reference(rows: dict) -> dict:
    """What a fit to values given in place of the table records: the values and their SHA-256 (a fit
    recorded its data as the shipped table's, whatever it was given; a file of it is refused as
    fitted to another table)."""
    text = json.dumps(rows, sort_keys=True)
    return {"path": None, "what": "values given to the fit, not the shipped reference table", "values": rows,
            "sha256": hashlib.sha256(text.encode()).hexdigest()}


def reference_identity() -> dict:
    """The table a fit used: its file (relative to the repository) and SHA-256."""
    return {"path": "twin/calibration/data/reference_table.csv", "what": "MISSION.md reference table",
            "sha256": hashlib.sha256(REFERENCE_TABLE_PATH.read_bytes()).hexdigest()}
