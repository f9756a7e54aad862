"""Writing where a user points: the content goes to a temporary file (or folder) of a name nobody
else holds, created exclusively beside the target (:mod:`tempfile`), and is renamed over the
target when complete. A reader never sees half a file, and no other file is touched: a fixed
name such as ``X.tmp`` or ``DIR.partial`` could be the user's own, and would be overwritten or
removed. A written file is known again by its sha256 (:func:`file_sha256`); a checkout of the
repository (where grindtwin may write its own shipped files) by its pyproject.toml
(:func:`is_grindtwin_checkout`).

A folder of results is replaced as a whole (:func:`replace_folder`) and written by one process at
a time: a lock file beside it (:func:`acquire_lock`, ``fcntl.flock``) that holds its tag from its
first instant, is refused when another process holds it or when it is not a lock (a user's file of
that name is never emptied or removed), and is taken over when left by a killed process (the
kernel drops a flock with its process)."""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import math
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path


def _default_mode(base: int) -> int:
    """``base`` under the process's umask (what ``open`` or ``mkdir`` would have given)."""
    umask = os.umask(0)
    os.umask(umask)
    return base & ~umask


def write_text_atomically(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` via a fresh temporary file beside it; on any error the
    temporary file is removed and ``path`` is as it was."""
    return write_atomically(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def write_atomically(path, write: Callable[[Path], object]) -> Path:
    """``write(tmp)`` writes the file's content at the path ``tmp``, a fresh temporary file beside
    ``path`` (``.NAME.<random>.partial``, :func:`temporaries_of`) renamed over ``path`` when done;
    on any error it is removed and ``path`` is as it was."""
    path = Path(path)
    tmp = write_beside(path, write)
    try:
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_beside(path, write: Callable[[Path], object]) -> Path:
    """The temporary file of :func:`write_atomically`, written by ``write(tmp)`` and left for the caller
    to rename over ``path`` (removed on any error): files that must change together are each written
    first, then renamed."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".partial")
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, _default_mode(0o666))  # mkstemp makes it private (0600)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return Path(tmp)


def temporaries_of(folder, names) -> list[str]:
    """The temporary files :func:`write_atomically` left in ``folder`` for any of ``names`` (a
    process killed while writing), by their names."""
    return sorted(p.name for p in Path(folder).iterdir()
                  if p.name.endswith(".partial") and any(p.name.startswith(f".{n}.") for n in names))


def new_folder_beside(path, suffix: str = ".partial") -> Path:
    """A new, empty folder beside ``path`` (same file system, so it can be renamed to ``path``),
    under a name no one else holds; the caller fills it and renames it, or removes it."""
    path = Path(path)
    folder = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix))
    os.chmod(folder, _default_mode(0o777))  # mkdtemp makes it private (0700)
    return folder


def file_sha256(path) -> str:
    """The sha256 of a file's bytes (hex), read in blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_once(path) -> tuple[bytes, str]:
    """A file's bytes and their sha256 (hex), read once: what a run parses and what it records of it are one
    version of the file, not two when it is rewritten meanwhile."""
    data = Path(path).read_bytes()
    return data, hashlib.sha256(data).hexdigest()


#: Excel's error values: a line whose first cell is one is a row of data (refused where a number is due), not a
#: comment; read as one, a sieve row "#N/A,60" was dropped without a word.
EXCEL_ERRORS = ("#N/A", "#VALUE!", "#REF!", "#DIV/0!", "#NUM!", "#NAME?", "#NULL!", "#SPILL!", "#CALC!")


def csv_text(data: bytes) -> str:
    """A CSV file's ``data`` as text (UTF-8, a byte-order mark dropped) with its comment lines (first
    non-blank character '#', the first cell no Excel error value) left blank: pandas skips blank lines, so its
    line numbers stay the file's, and a comment is a whole line (pandas' comment="#" also cut a row at a cell
    "#VALUE!")."""
    text = data.decode("utf-8-sig")
    return "".join("\n" if _is_comment(line) else line for line in text.splitlines(keepends=True))


def _is_comment(line: str) -> bool:
    head = line.lstrip()
    return head.startswith("#") and head.split(",", 1)[0].strip().upper() not in EXCEL_ERRORS


#: How a JSON file writes an infinity (a number, unlike NaN: null, undefined): the text the CSV files write
#: for it, which Python's ``float`` and pandas read back as the infinity (null made it undefined).
JSON_INF = {math.inf: "inf", -math.inf: "-inf"}


def json_safe(obj):
    """NaN -> None (undefined); an infinity -> :data:`JSON_INF`'s text; numpy scalars -> Python;
    tuples -> lists; keys -> str; recursively."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    np = sys.modules.get("numpy")  # a numpy scalar exists only once numpy is imported (the compiled
    # surrogate's reader runs without it)
    if isinstance(obj, float) or (np is not None and isinstance(obj, np.floating)):
        v = float(obj)
        return None if math.isnan(v) else JSON_INF.get(v, v)
    if np is not None and isinstance(obj, np.integer):
        return int(obj)
    if np is not None and isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def json_text(obj, **kwargs) -> str:
    """``obj`` as strict JSON (RFC 8259 has no NaN or infinity: Python's json wrote the tokens NaN and
    Infinity, which many readers refuse) through :func:`json_safe`; ``kwargs`` go to :func:`json.dumps`.
    ``allow_nan=False``: a value json_safe leaves non-finite raises instead of writing such a token."""
    return json.dumps(json_safe(obj), allow_nan=False, **kwargs)


def is_grindtwin_checkout(folder) -> bool:
    """Whether ``folder`` holds a checkout of the grindtwin repository: its pyproject.toml names the
    project (an installed package, or another project's folder, has none that does)."""
    import tomllib

    try:
        with open(Path(folder) / "pyproject.toml", "rb") as fh:
            return tomllib.load(fh).get("project", {}).get("name") == "grindtwin"
    except (OSError, tomllib.TOMLDecodeError):
        return False


def remove_by_name(folder, names=None) -> bool:
    """Unlink the files (or links) ``names`` in ``folder`` (None: every one in it), then rmdir it,
    which fails rather than delete anything else; False if anything is left (the folder stays)."""
    folder = Path(folder)
    for name in [p.name for p in folder.iterdir()] if names is None else names:
        p = folder / name
        if p.is_file() or p.is_symlink():
            p.unlink()
    try:
        folder.rmdir()
    except OSError:
        return False
    return True


def replace_folder(target, new, names) -> Path | None:
    """Rename the folder ``new`` to ``target``. A folder at ``target`` is first moved aside (into a
    fresh folder beside it, :func:`new_folder_beside`: no name of the user's is taken), put back if
    ``new`` cannot be put in place, and then removed by ``names`` only (:func:`remove_by_name`).
    Returns the moved-aside folder when something else kept it, else None."""
    target, new = Path(target), Path(new)
    if not target.exists():
        new.rename(target)
        return None
    old = new_folder_beside(target, suffix=".replaced")
    try:
        target.rename(old)  # onto the new empty folder
    except BaseException:
        old.rmdir()
        raise
    try:
        new.rename(target)
    except BaseException:
        old.rename(target)
        raise
    return None if remove_by_name(old, names) else old


class LockError(Exception):
    """The lock file ``path`` is held by another process (``busy``), or is not a lock (its ``text``
    lacks the tag): the caller refuses, in its own words."""

    def __init__(self, path: Path, text: str, busy: bool):
        super().__init__(f"{path}: {'held by another process' if busy else 'not a lock file'} ({text.strip()!r})")
        self.path, self.text, self.busy = path, text, busy


def acquire_lock(path, tag: str, accepts: Callable[[str], bool] | None = None) -> int:
    """Create or take over the lock file ``path`` and hold its flock (exclusive); returns its open
    descriptor, for :func:`release_lock`. ``tag``: its first words, with the pid after them;
    ``accepts(text)``: whether an existing file is a lock (default: it starts with ``tag``).
    LockError if another process holds it or it is not a lock (left as it was)."""
    path = Path(path)
    accepts = accepts or (lambda text: text.startswith(tag))
    stamp = f"{tag} pid {os.getpid()}\n".encode()
    while True:
        created = _create_tagged(path, stamp)
        try:
            fd = os.open(path, os.O_RDWR)
        except FileNotFoundError:  # removed by the process that held it just now: again
            continue
        text = os.read(fd, 200).decode(errors="replace")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise LockError(path, text, busy=True) from None
        if not created and not accepts(text):
            os.close(fd)
            raise LockError(path, text, busy=False)
        try:  # removed by the process that held it between our open and flock: lock the new one
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            os.ftruncate(fd, 0)
            os.pwrite(fd, stamp, 0)
            return fd
        os.close(fd)


def release_lock(path, fd: int) -> None:
    """Remove the lock file ``path`` (ours while we hold it: nobody else removes it), then close
    ``fd``, which releases the flock."""
    Path(path).unlink(missing_ok=True)
    os.close(fd)


def _create_tagged(path: Path, stamp: bytes) -> bool:
    """Create ``path`` holding ``stamp`` from its first instant (written to a new temporary file,
    then hard-linked into place, which fails if the name exists), so that no other process finds
    it empty and takes it for a user's file; False if it exists already. On a file system without
    hard links it is created exclusively and written just after."""
    fd, aside = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        os.write(fd, stamp)
        os.close(fd)
        os.link(aside, path)
        return True
    except FileExistsError:
        return False
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV):
            raise
    finally:
        os.unlink(aside)
    try:  # no hard links here
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        return False
    os.write(fd, stamp)
    os.close(fd)
    return True
