"""Mineral property table shipped as data (``twin/ore/data/minerals.csv``), each value with its source.

Units: density t/m3, Vickers micro-hardness GPa, Young's modulus GPa, Bond work index kWh/t.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from functools import cache
from importlib import resources

CLAY_MINERALS = ("kaolinite", "illite")
MICA_MINERALS = ("biotite", "muscovite")
#: The soft, platy sheet silicates that cushion impacts in a charge (MISSION.md: clay and mica):
#: clays, micas and chlorite, a phyllosilicate as soft and platy as biotite (Deer, Howie &
#: Zussman 2013, sheet silicates; Vickers 0.9 GPa in minerals.csv).
CUSHIONING_MINERALS = CLAY_MINERALS + MICA_MINERALS + ("chlorite",)
SULFIDE_MINERALS = ("pyrite", "chalcopyrite", "bornite")


@dataclass(frozen=True)
class Mineral:
    """Properties of one mineral; ``sources`` maps a property name to a key of ``sources.csv``."""

    name: str
    group: str
    density_t_m3: float
    vickers_gpa: float
    youngs_gpa: float
    bond_wi_kwh_t: float  # NaN where no value is published
    sources: dict


def _read_data_csv(filename: str) -> list[dict]:
    text = resources.files("twin.ore").joinpath("data", filename).read_text(encoding="utf-8")
    lines = [ln for ln in text.splitlines() if ln and not ln.startswith("#")]
    return list(csv.DictReader(lines))


@cache
def mineral_table() -> dict[str, Mineral]:
    """All minerals by name, read once from the shipped CSV."""
    table = {}
    for row in _read_data_csv("minerals.csv"):
        wi = row["bond_wi_kwh_t"]
        table[row["name"]] = Mineral(
            name=row["name"],
            group=row["group"],
            density_t_m3=float(row["density_t_m3"]),
            vickers_gpa=float(row["vickers_gpa"]),
            youngs_gpa=float(row["youngs_gpa"]),
            bond_wi_kwh_t=float(wi) if wi else math.nan,
            sources={k[:-4]: row[k] for k in row if k.endswith("_src") and row[k]},
        )
    return table


@cache
def source_table() -> dict[str, str]:
    """Bibliographic references by key."""
    return {row["key"]: row["reference"] for row in _read_data_csv("sources.csv")}


def mineral_names() -> list[str]:
    return list(mineral_table())
