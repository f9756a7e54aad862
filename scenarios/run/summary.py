"""The JSON-able summary of a run: the scene, KPIs, models, notes and the versions behind it."""

from __future__ import annotations

import platform
import subprocess
from importlib import metadata
from pathlib import Path

from scenarios.run.models import Models, is_batch
from scenarios.scene import Scene


def versions() -> dict:
    """Versions of Python and the libraries that shape a result."""
    out = {"python": platform.python_version()}
    for pkg in ("grindtwin", "numpy", "pandas", "scipy", "casadi", "pydantic"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parent, timeout=5)
        out["git"] = rev.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        out["git"] = None
    return out


def make_summary(scene: Scene, models: Models, kpis: dict, notes: list[str], wall_s: float) -> dict:
    """The JSON-able summary of a run."""
    plant_desc = None if models.plant is models.control else models.plant.model.describe()
    return {
        "scene": scene.scene.name,
        "description": scene.scene.description,
        "source": str(scene.source_path) if scene.source_path else None,
        "seed": scene.scene.seed,
        "controller": scene.controller.kind,
        "target_p80_um": scene.controller.target_p80_um,
        "load_band_frac": list(scene.controller.load_band_frac),
        "mode": "batch" if is_batch(scene) else ("open_loop" if scene.controller.kind == "none"
                                                  else "closed_loop"),
        "effects": list(scene.effects),
        "calibration": models.calibration.identity() if models.calibration is not None else None,
        "components": models.components,
        "kpis": kpis,
        "model": models.control.model.describe(),
        "plant_model": plant_desc,
        "notes": notes,
        "wall_time_s": wall_s,
        "versions": versions(),
    }
