"""Calibration files: where the shipped ones live, how they are read, and how a new one is
written with its provenance (the command, the versions, the seed), never half-written."""

from __future__ import annotations

import json
import platform
import time
from functools import cache
from pathlib import Path

from ..errors import TwinError

#: The folder of shipped calibration files, one per name.
CALIBRATION_DIR = Path(__file__).resolve().parent / "files"
TABLE_CALIBRATION_PATH = CALIBRATION_DIR / "table.json"
DEM_CALIBRATION_PATH = CALIBRATION_DIR / "dem.json"


def _read(path: Path, command: str) -> dict:
    if not path.is_file():
        raise TwinError(f"No calibration file {path}: run `{command}`.")
    return json.loads(path.read_text(encoding="utf-8"))


@cache
def shipped_calibration() -> dict:
    """The shipped mineralogy-map calibration (made by `grindtwin calibrate`)."""
    return _read(TABLE_CALIBRATION_PATH, "grindtwin calibrate")


@cache
def shipped_dem_calibration() -> dict:
    """The shipped DEM-derived calibration (made by `python -m twin.calibration --dem`)."""
    return _read(DEM_CALIBRATION_PATH, "python -m twin.calibration --dem")


def lab_mill_values(values: dict) -> dict:
    """The lab mill's fitted fields (twin.mill.Mill) from a fit's ``lab_*`` values."""
    return {k[len("lab_"):]: v for k, v in values.items() if k.startswith("lab_")}


def versions() -> dict:
    """Versions of what shapes a calibration, for its provenance record."""
    from importlib import metadata  # only when a calibration is written: slow to import

    return {"python": platform.python_version(),
            **{pkg: metadata.version(pkg) for pkg in ("numpy", "scipy", "numba", "casadi")}}


def provenance(command: str) -> dict:
    return {"command": command, **versions(), "seed": None,
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def write_json_atomically(path: Path, record: dict, indent: int = 2) -> None:
    """Write to a temporary file and rename it over ``path``: nothing is ever half-written."""
    path = Path(path)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(record, indent=indent) + "\n", encoding="utf-8")
    tmp.replace(path)
