"""The data calibrations are fitted to: MISSION.md's laboratory table (P80, specific energy and
throughput at constant load for the reference ores A-D), shipped as ``data/reference_table.csv``,
or a user's own table of the same form (:func:`read_table`, ``grindtwin calibrate --table FILE``)."""

from __future__ import annotations

import csv
import hashlib
import json
import math
from dataclasses import asdict
from pathlib import Path

from ..errors import TwinInputError

#: The table's KPIs, in the order of every residual vector.
KPIS = ("p80_um", "specific_energy_kwh_t", "throughput_kg_h")
REFERENCE_TABLE_PATH = Path(__file__).resolve().parent / "data" / "reference_table.csv"
#: What a table's values may be (its test: MISSION.md's laboratory mill at 70 % of critical, feed P80 3.2 mm,
#: throughput at constant load): a P80 finer than the 3,200-um feed and coarser than 1 um (a P80 in mm lands
#: below); the 0.5-100 kWh/t ball mills draw; a tenth to ten times the mill's nominal 31 kg/h (t/h lands below).
TABLE_RANGES = {"p80_um": (1.0, 3200.0), "specific_energy_kwh_t": (0.5, 100.0), "throughput_kg_h": (3.1, 310.0)}


def reference_table() -> dict:
    """{ore: {kpi: value}} of MISSION.md's reference table."""
    text = REFERENCE_TABLE_PATH.read_text(encoding="utf-8")
    rows = csv.DictReader([ln for ln in text.splitlines() if ln and not ln.startswith("#")])
    return {r["ore"]: {k: float(r[k]) for k in KPIS} for r in rows}


def read_table(path) -> tuple[dict, dict]:
    """A user's laboratory table in the shipped table's form: columns ``ore`` and :data:`KPIS`, lines
    starting with ``#`` comments, measured in the shipped table's test (:data:`TABLE_RANGES`). ``ore`` is a
    reference type (A-D) or an ore TOML file ([mineralogy], [texture]) relative to the table's folder.
    Returns ({ore name: {kpi: value}}, {ore name: twin Mineralogy}); TwinInputError naming the file, row
    and column, before any work."""
    from ..ore import load_ore, reference_ores

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise TwinInputError(f"--table {path}: file not found (a CSV with columns ore, {', '.join(KPIS)})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TwinInputError(f"--table {path}: cannot be read as UTF-8 text: {exc}") from None
    reader = csv.DictReader([ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")])
    columns = [c.strip() for c in reader.fieldnames or []]
    if sorted(columns) != sorted(("ore", *KPIS)):
        raise TwinInputError(f"--table {path}: columns must be ore, {', '.join(KPIS)} (the shipped table's: "
                             f"{REFERENCE_TABLE_PATH.name}); got {', '.join(columns) or 'none'}")
    rows, ores = {}, {}
    for i, raw in enumerate(reader, start=1):
        where = f"--table {path}: data row {i}"
        if None in raw:  # csv's key of the cells beyond the header's (a traceback on .strip)
            raise TwinInputError(f"{where}: {len(columns) + len(raw[None])} cells; one per column "
                                 f"({', '.join(columns)}): extra {raw[None]!r}")
        row = {k.strip(): (v or "").strip() for k, v in raw.items()}
        spec = row["ore"]
        local = path.parent / spec
        try:
            ore = load_ore(str(local) if spec.endswith(".toml") and not Path(spec).is_absolute() else spec)
        except TwinInputError as exc:
            raise TwinInputError(f"{where}: ore {spec!r}: {exc}") from None
        if spec.endswith(".toml") and ore.name in reference_ores():  # its rows would read as that type's
            raise TwinInputError(f"{where}: ore file {spec!r} is named as the reference type {ore.name!r}; rename "
                                 "the file (an ore's name is its file's)")
        if ore.name in rows:
            raise TwinInputError(f"{where}: ore {ore.name!r} is given twice (one row per ore)")
        rows[ore.name], ores[ore.name] = {k: _value(row[k], k, where) for k in KPIS}, ore
    if not rows:
        raise TwinInputError(f"--table {path}: no data rows")
    return rows, ores


def _value(text: str, kpi: str, where: str) -> float:
    lo, hi = TABLE_RANGES[kpi]
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not lo <= value <= hi:
        raise TwinInputError(f"{where}: {kpi} must be a number in [{lo:g}, {hi:g}] (the shipped table's test: the "
                             f"laboratory mill at 70 % of critical, feed P80 3.2 mm, constant load); got {text!r}")
    return value


def given_reference(rows: dict, path=None, ores: dict | None = None) -> dict:
    """What a fit to values given in place of the shipped table records: the values and their SHA-256 (checked
    where a file of it is read, :func:`twin.calibration.record_checks.check_data`), the table file they came
    from (``path``) and each ore's mineralogy and texture (``ores``: name -> Mineralogy)."""
    text = json.dumps(rows, sort_keys=True)
    out = {"path": None if path is None else str(Path(path).resolve()),
           "what": "a laboratory table given to the fit, not the shipped reference table", "values": rows,
           "sha256": hashlib.sha256(text.encode()).hexdigest()}
    if ores:
        out["ores"] = {n: {"wt_pct": dict(o.wt_pct), "texture": asdict(o.texture)} for n, o in ores.items()}
    return out


def fitted_ores(fit: dict) -> tuple:
    """The ores of a fit record's table step (``fit.predicted``'s keys) as predict_table takes them: a
    reference type by its name, a user's ore rebuilt from its recorded mineralogy and texture."""
    from ..ore import Mineralogy, Texture

    own = (fit.get("fitted_to") or {}).get("ores") or {}
    return tuple(Mineralogy(own[n]["wt_pct"], Texture(**own[n]["texture"]), name=n) if n in own else n
                 for n in fit["predicted"])


def given_values_sha256(fitted_to: dict) -> str:
    """The SHA-256 of the values a fit to given data records (:func:`given_reference`)."""
    return hashlib.sha256(json.dumps(fitted_to.get("values"), sort_keys=True).encode()).hexdigest()


def reference_identity() -> dict:
    """The table a fit used: its file (relative to the repository) and SHA-256."""
    return {"path": "twin/calibration/data/reference_table.csv", "what": "MISSION.md reference table",
            "sha256": hashlib.sha256(REFERENCE_TABLE_PATH.read_bytes()).hexdigest()}
