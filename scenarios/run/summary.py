"""The JSON-able summary of a run: the scene, KPIs, models, notes and the versions behind it."""

from __future__ import annotations

import hashlib
import json
import platform
import subprocess
from importlib import metadata
from pathlib import Path
from urllib.parse import urlparse
from urllib.request import url2pathname

from scenarios.run.feed import fed_file_changes
from scenarios.run.models import Models, is_batch
from scenarios.scene import Scene


#: The packages whose files decide whether an installed grindtwin is a given commit.
PACKAGES = ("dem", "twin", "mpc", "scenarios")


def versions() -> dict:
    """Versions of Python and the libraries that shape a result, and the git commit of the code
    (:func:`code_revision`)."""
    out = {"python": platform.python_version()}
    for pkg in ("grindtwin", "numpy", "pandas", "scipy", "casadi", "pydantic"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out | code_revision()


def _git(cwd: Path, *args: str) -> str | None:
    try:
        res = subprocess.run(["git", *args], capture_output=True, text=True, cwd=cwd, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return res.stdout.strip() if res.returncode == 0 else None


def code_revision() -> dict:
    """``git``: the commit of the running code, ``git_source``: how it is known.

    Run from a checkout (an editable install): its HEAD, "with uncommitted changes" when
    tracked files differ. Installed (``pip install .``): the checkout it was installed from
    (pip's ``direct_url.json``, PEP 610) if every installed source file is that checkout's HEAD
    version (git blob hashes); else ``None``, and the package version is what identifies it."""
    root = Path(__file__).resolve().parents[2]  # the folder that holds the packages
    top = _git(root, "rev-parse", "--show-toplevel")
    if top is not None and Path(top).resolve() == root:
        dirty = _git(root, "status", "--porcelain", "--untracked-files=no")
        return {"git": _git(root, "rev-parse", "--short=12", "HEAD"),
                "git_source": "checkout" + (" with uncommitted changes" if dirty else "")}
    src = _install_source()
    if src is not None and _installed_matches_head(src, root):
        return {"git": _git(src, "rev-parse", "--short=12", "HEAD"), "git_source": f"installed from {src}"}
    return {"git": None, "git_source": "installed package, not a git checkout (see the grindtwin version)"}


def _install_source() -> Path | None:
    """The local folder grindtwin was pip-installed from (PEP 610), or None."""
    try:
        text = metadata.distribution("grindtwin").read_text("direct_url.json")
    except metadata.PackageNotFoundError:
        return None
    url = json.loads(text).get("url", "") if text else ""
    return Path(url2pathname(urlparse(url).path)) if url.startswith("file://") else None


def _installed_matches_head(src: Path, root: Path) -> bool:
    """Every tracked .py file of the packages at ``src``'s HEAD has the same git blob hash as
    the installed file under ``root``."""
    listing = _git(src, "ls-tree", "-r", "HEAD", "--", *PACKAGES)
    if not listing:
        return False
    for line in listing.splitlines():
        meta, path = line.split("\t", 1)
        if not path.endswith(".py"):
            continue
        installed = root / path
        if not installed.is_file():
            return False
        data = installed.read_bytes()
        if hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest() != meta.split()[2]:
            return False
    return True


def make_summary(scene: Scene, models: Models, kpis: dict, notes: list[str], wall_s: float) -> dict:
    """The JSON-able summary of a run. ``plant_model`` describes the model that was integrated,
    ``controller_model`` the NMPC's or PI's (None open loop); ``schedule`` lists the feed's
    transitions (for the plots' markers)."""
    closed = scene.controller.kind != "none"
    return {
        "scene": scene.scene.name,
        "description": scene.scene.description,
        "source": str(scene.source_path) if scene.source_path else None,
        "seed": scene.scene.seed,
        "controller": scene.controller.kind,
        "target_p80_um": scene.controller.target_p80_um,
        "load_band_frac": list(scene.controller.load_band_frac),
        # only the NMPC reads the belt analyser's preview: a PI or open-loop run recorded the scene's lead,
        # and its plots marked the transitions as seen that far ahead
        "preview_lead_h": scene.controller.preview_lead_h if scene.controller.kind == "nmpc" else None,
        "mode": "batch" if is_batch(scene) else ("closed_loop" if closed else "open_loop"),
        "effects": list(scene.effects),
        "plant_effects": sorted(models.plant.model.effect_names,  # what the plant ran ([plant] may differ),
                                key=lambda e: (list(scene.effects) + [e]).index(e)),  # in the scene's order
        "calibration": models.calibration.identity() if models.calibration is not None else None,
        "mill_preset_file": preset_file_identity(scene),
        "scene_as_run": scene.model_dump(mode="json", exclude_none=True),  # every key as loaded, defaults filled
        "components": models.components,
        "schedule": [ev.model_dump() for ev in scene.feed.schedule],
        "kpis": kpis,
        "plant_model": models.plant.model.describe(),
        "controller_model": controller_model(scene, models),
        "notes": notes,
        "wall_time_s": wall_s,
        "versions": versions(),
    }


def preset_file_identity(scene: Scene) -> dict | None:
    """The mill preset file a scene names (its resolved path and SHA-256 as the scene was loaded,
    :meth:`scenarios.scene.Scene.preset_file_identity`), or None for a preset's name: a run folder said only
    ``my_mill.json``, which a later `size-mill --write-preset` rewrites."""
    return scene.preset_file_identity()


def preset_file_changes(scene: Scene) -> list[str]:
    """A warning when the mill preset file the scene names is not, at the end of its run, the file it was
    when the scene was loaded (rewritten or removed meanwhile: the run's mill may be either); else none."""
    identity = scene.preset_file_identity()
    if identity is None:
        return []
    return fed_file_changes("mill preset file", identity["path"], identity["sha256"],
                            read="the scene was loaded with the file of SHA-256",
                            consequence="the mill the run built may be either file's; ")


#: What the PI baseline knows of the mill (it has no model of its own).
PI_MODEL_TEXT = ("PI from the analyser's P80 to the feed rate (speed held), SIMC-tuned on a first-order-plus-"
                 "dead-time fit of the plant model linearised at its initial steady state; no model of its own.")


def controller_model(scene: Scene, models: Models) -> str | None:
    """The description of the controller's model: the NMPC's twin, the PI's tuning, or None."""
    kind = scene.controller.kind
    if kind == "nmpc":
        return models.control.model.describe()
    return PI_MODEL_TEXT if kind == "pi" else None
