"""The shipped surrogate and its training table: paths, save and load (joblib) with the metadata
that says what they were made from, and the refusal of a stale or foreign file; the compiled
form beside it (``surrogate.json``, :mod:`twin.surrogate.compiled`), which the command line reads
without scikit-learn."""

from __future__ import annotations

import platform
from functools import cache
from pathlib import Path

from ..atomic import file_sha256
from ..calibration.files import Calibration, load_calibration
from ..errors import TwinError, TwinInputError
from .compiled import TARGETS, CompiledSurrogate

DATA_DIR = Path(__file__).resolve().parent / "data"
TABLE_PATH = DATA_DIR / "surrogate_training.parquet"
MODEL_PATH = DATA_DIR / "surrogate.joblib"
COMPILED_PATH = DATA_DIR / "surrogate.json"
FORMAT_VERSION = 1
GENERATE_COMMAND = "python -m twin.surrogate --generate"
TRAIN_COMMAND = "python -m twin.surrogate --train"
COMPILE_COMMAND = "python -m twin.surrogate --compile"


def calibration_sha256(calibration=None) -> str:
    """Hash of a calibration's file (the default calibration's unless named): a surrogate is
    trained on one calibration and stale once its file changes."""
    return load_calibration(calibration).sha256


def check_trained_on(surrogate, calibration: Calibration) -> None:
    """TwinInputError unless ``surrogate`` (fitted or compiled) was trained on runs of
    ``calibration`` (the same file hash)."""
    meta = getattr(surrogate, "metadata_", None) or getattr(surrogate, "metadata", None) or {}
    sha = meta.get("calibration_sha256")
    if sha != calibration.sha256:
        name = (meta.get("calibration") or {}).get("name", "?")
        raise TwinInputError(
            f"The surrogate was trained on another calibration than {calibration.label()}: on {name!r} (sha256 "
            f"{str(sha)[:12]}). Retrain it on this calibration: "
            f"`python -m twin.surrogate --generate --train --calibration {calibration.name}`.")


def save(surrogate, path: str | Path, metadata: dict | None = None) -> Path:
    """Save a fitted Surrogate (joblib) and its compiled form beside it (same name, ``.json``)."""
    import joblib  # only when saving or loading
    import numpy as np
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
    """The compiled form of ``surrogate`` (saved as ``joblib_path``) beside it, ``.json``, with the
    metadata and the joblib file's hash (so a test can tell they belong together)."""
    joblib_path = Path(joblib_path)
    meta = dict(metadata, joblib_sha256=file_sha256(joblib_path), compiled_by=COMPILE_COMMAND)
    return surrogate.compiled(meta).save(joblib_path.with_suffix(".json"))


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
    """The shipped surrogate's compiled form ``twin/surrogate/data/surrogate.json`` (loaded once,
    plain Python); TwinInputError if it was made from another calibration than the default one
    (:func:`check_trained_on`; ``surrogate_steady`` checks the calibration it is asked for)."""
    compiled = CompiledSurrogate.load(COMPILED_PATH)
    check_trained_on(compiled, load_calibration())
    return compiled
