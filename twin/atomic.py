"""Writing where a user points: the content goes to a temporary file (or folder) of a name nobody
else holds, created exclusively beside the target (:mod:`tempfile`), and is renamed over the
target when complete. A reader never sees half a file, and no other file is touched: a fixed
name such as ``X.tmp`` or ``DIR.partial`` could be the user's own, and would be overwritten or
removed. A written file is known again by its sha256 (:func:`file_sha256`); a checkout of the
repository (where grindtwin may write its own shipped files) by its pyproject.toml
(:func:`is_grindtwin_checkout`)."""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path


def _default_mode(base: int) -> int:
    """``base`` under the process's umask (what ``open`` or ``mkdir`` would have given)."""
    umask = os.umask(0)
    os.umask(umask)
    return base & ~umask


def write_text_atomically(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` via a fresh temporary file beside it; on any error the
    temporary file is removed and ``path`` is as it was."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".partial")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(tmp, _default_mode(0o666))  # mkstemp makes it private (0600)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def new_folder_beside(path) -> Path:
    """A new, empty folder beside ``path`` (same file system, so it can be renamed to ``path``),
    under a name no one else holds; the caller fills it and renames it, or removes it."""
    path = Path(path)
    folder = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".partial"))
    os.chmod(folder, _default_mode(0o777))  # mkdtemp makes it private (0700)
    return folder


def file_sha256(path) -> str:
    """The sha256 of a file's bytes (hex), read in blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def is_grindtwin_checkout(folder) -> bool:
    """Whether ``folder`` holds a checkout of the grindtwin repository: its pyproject.toml names the
    project (an installed package, or another project's folder, has none that does)."""
    import tomllib

    try:
        with open(Path(folder) / "pyproject.toml", "rb") as fh:
            return tomllib.load(fh).get("project", {}).get("name") == "grindtwin"
    except (OSError, tomllib.TOMLDecodeError):
        return False
