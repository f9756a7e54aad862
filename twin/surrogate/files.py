"""The shipped surrogate and its training table: paths, save and load (joblib) with the metadata
that says what they were made from, and the refusal of a stale or foreign file."""

from __future__ import annotations

import platform
from functools import cache
from pathlib import Path

import numpy as np
import sklearn

from ..calibration import Calibration, load_calibration
from ..errors import TwinError, TwinInputError
from .model import TARGETS, Surrogate

DATA_DIR = Path(__file__).resolve().parent / "data"
TABLE_PATH = DATA_DIR / "surrogate_training.parquet"
MODEL_PATH = DATA_DIR / "surrogate.joblib"
FORMAT_VERSION = 1
GENERATE_COMMAND = "python -m twin.surrogate --generate"
TRAIN_COMMAND = "python -m twin.surrogate --train"


def calibration_sha256(calibration=None) -> str:
    """Hash of a calibration's file (the default calibration's unless named): a surrogate is
    trained on one calibration and stale once its file changes."""
    return load_calibration(calibration).sha256


def check_trained_on(surrogate: Surrogate, calibration: Calibration) -> None:
    """TwinInputError unless ``surrogate`` was trained on runs of ``calibration`` (same file hash)."""
    meta = getattr(surrogate, "metadata_", {})
    trained = meta.get("calibration") or {"name": "?", "sha256": meta.get("calibration_sha256")}
    if trained.get("sha256") != calibration.sha256:
        raise TwinInputError(
            f"The surrogate was trained on calibration {trained.get('name')!r} (sha256 "
            f"{str(trained.get('sha256'))[:12]}); this is calibration {calibration.label()}. Retrain it on this "
            f"calibration: `python -m twin.surrogate --generate --train --calibration {calibration.name}`.")


def save(surrogate: Surrogate, path: str | Path, metadata: dict | None = None) -> Path:
    import joblib  # only when saving or loading

    surrogate._check_fitted()
    meta = {"format_version": FORMAT_VERSION, "sklearn": sklearn.__version__, "numpy": np.__version__,
            "python": platform.python_version(), "params": surrogate.get_params(), "targets": list(TARGETS)}
    meta |= dict(metadata or {})
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    joblib.dump({"metadata": meta, "surrogate": surrogate}, path, compress=3)
    return path


def _minor(v: str) -> str:
    return ".".join(v.split(".")[:2])


def load(path: str | Path | None = None) -> Surrogate:
    """A saved surrogate; refuses another format version or scikit-learn minor version."""
    import joblib  # only when saving or loading

    path = Path(path) if path else MODEL_PATH
    if not path.is_file():
        raise TwinError(f"No surrogate file {path}: run `{TRAIN_COMMAND}`.")
    blob = joblib.load(path)
    meta = blob.get("metadata", {}) if isinstance(blob, dict) else {}
    if meta.get("format_version") != FORMAT_VERSION:
        raise TwinError(f"Surrogate file {path} has format version {meta.get('format_version')!r}; this code "
                        f"reads version {FORMAT_VERSION}. Regenerate it: `{TRAIN_COMMAND}`.")
    if _minor(meta.get("sklearn", "")) != _minor(sklearn.__version__):
        raise TwinError(f"Surrogate file {path} was saved with scikit-learn {meta.get('sklearn')}; this is "
                        f"{sklearn.__version__}. Regenerate it: `{TRAIN_COMMAND}`.")
    sur = blob["surrogate"]
    sur.metadata_ = meta
    return sur


@cache
def shipped_surrogate() -> Surrogate:
    """The shipped surrogate ``twin/surrogate/data/surrogate.joblib`` (loaded once)."""
    return load()
