"""The shipped surrogate and its training table: paths, save and load (joblib) with the metadata
that says what they were made from, and the refusal of a stale or foreign file; the compiled
form beside it (``surrogate.npz``, :mod:`twin.surrogate.compiled`), which the command line reads
without scikit-learn."""

from __future__ import annotations

import hashlib
import platform
from functools import cache
from pathlib import Path

import numpy as np

from ..calibration.files import TABLE_CALIBRATION_PATH
from ..errors import TwinError
from .compiled import TARGETS, CompiledSurrogate, file_sha256

DATA_DIR = Path(__file__).resolve().parent / "data"
TABLE_PATH = DATA_DIR / "surrogate_training.parquet"
MODEL_PATH = DATA_DIR / "surrogate.joblib"
COMPILED_PATH = DATA_DIR / "surrogate.npz"
FORMAT_VERSION = 1
GENERATE_COMMAND = "python -m twin.surrogate --generate"
TRAIN_COMMAND = "python -m twin.surrogate --train"
COMPILE_COMMAND = "python -m twin.surrogate --compile"


def calibration_sha256() -> str:
    """Hash of the calibration file the twin runs used (a surrogate is stale once it changes)."""
    return hashlib.sha256(TABLE_CALIBRATION_PATH.read_bytes()).hexdigest()


def save(surrogate, path: str | Path, metadata: dict | None = None) -> Path:
    """Save a fitted Surrogate (joblib) and its compiled form beside it (same name, ``.npz``)."""
    import joblib  # only when saving or loading
    import sklearn

    surrogate._check_fitted()
    meta = {"format_version": FORMAT_VERSION, "sklearn": sklearn.__version__, "numpy": np.__version__,
            "python": platform.python_version(), "params": surrogate.get_params(), "targets": list(TARGETS)}
    meta |= dict(metadata or {})
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    joblib.dump({"metadata": meta, "surrogate": surrogate}, path, compress=3)
    save_compiled(surrogate, path, meta)
    return path


def save_compiled(surrogate, joblib_path: str | Path, metadata: dict) -> Path:
    """The compiled form of ``surrogate`` (saved as ``joblib_path``) beside it, ``.npz``, with the
    metadata and the joblib file's hash (so a test can tell they belong together)."""
    joblib_path = Path(joblib_path)
    meta = dict(metadata, joblib_sha256=file_sha256(joblib_path), compiled_by=COMPILE_COMMAND)
    return surrogate.compiled(meta).save(joblib_path.with_suffix(".npz"))


def _minor(v: str) -> str:
    return ".".join(v.split(".")[:2])


def load(path: str | Path | None = None):
    """A saved Surrogate; refuses another format version or scikit-learn minor version."""
    import joblib  # only when saving or loading
    import sklearn

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
def shipped_surrogate():
    """The shipped surrogate ``twin/surrogate/data/surrogate.joblib`` (loaded once)."""
    return load()


@cache
def shipped_compiled() -> CompiledSurrogate:
    """The shipped surrogate's compiled form ``twin/surrogate/data/surrogate.npz`` (loaded once,
    numpy alone); TwinError if it was made from another calibration than the shipped one."""
    compiled = CompiledSurrogate.load(COMPILED_PATH)
    made_from = compiled.metadata.get("calibration_sha256")
    if made_from != calibration_sha256():
        raise TwinError(f"{COMPILED_PATH} was trained on another calibration than "
                        f"{TABLE_CALIBRATION_PATH.name} (hash {str(made_from)[:12]}...); retrain it: "
                        f"`{TRAIN_COMMAND}`.")
    return compiled
