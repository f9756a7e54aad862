"""Write a run's results into a folder of its own; never a half-written result, never into or
over anything grindtwin did not write.

Layout of a run directory::

    DIR/timeseries.parquet   one row per sample, unit-suffixed columns
    DIR/timeseries.csv       the same, on request (``csv=True``)
    DIR/product_psd.csv      cumulative % passing at a few times (rows) per size (columns, um);
                             mill_psd.csv the same of the mill content, streams.csv every
                             stream size by size at the end (scenarios.output.workbook)
    DIR/run.xlsx             the workbook, on request (``xlsx=True``)
    DIR/summary.json         scene, KPIs (unit-suffixed keys; NaN written as null, an infinity
                             as the text "inf" or "-inf"), model description, effects, versions,
                             seed, notes
    DIR/*.png                plots (see :data:`scenarios.output.plots.PLOTS`)
    DIR/grindtwin-manifest.json  what grindtwin wrote here (written last), each file with its
                             sha256: how a later run knows the folder is a grindtwin result it
                             may replace, and the report that a file is missing or was changed;
                             ``later_sha256``: the sha256 of the report.html ``grindtwin report``
                             last wrote (the manifest is rewritten as a whole to record it)
    DIR/report.html          written later by ``grindtwin report DIR``; replaced by the next report
                             (or removed with the folder by the next run) only while its sha256 is
                             the recorded one: one edited by hand, or the user's, is refused and kept

In every CSV an undefined number (NaN: the P80 of an empty mill, a sample the model leaves
undefined) is the text ``NaN`` (:data:`scenarios.output.workbook.CSV_NA`), never an empty cell
(a missing text, a sweep case's ``error`` when it ran, is the empty one, in the workbook too),
and every other number has all its digits, so ``pd.read_csv`` reads back the run's numbers
exactly, NaN as NaN; Excel shows ``NaN`` as text. In the workbook's tables of numbers (time
series, size distributions, streams, P80 traces) it is Excel's ``#N/A``; summary.json writes it
as null, and the workbook's KPI sheet leaves its cell empty with a note saying why. An infinity
(a number, not undefined) is ``inf`` / ``-inf`` everywhere: in the CSVs, as text in the
workbook (Excel has no infinity) and as a string in summary.json (JSON has none; null would
read as undefined).

The folder is claimed before any work (:func:`claim_output`), so a bad ``DIR`` costs nothing:
- ``DIR`` missing or empty, or a previous grindtwin result (its manifest lists every file in
  it, each with the sha256 grindtwin wrote it with, apart from a ``report.html`` grindtwin wrote
  and nobody changed since): accepted; a previous result is replaced as a whole, only once the
  new one is complete; a file of it edited since is the user's, and refused;
- anything else (a folder with files grindtwin did not write, a file, the current folder or one
  of its parents, the scene file's own folder) is refused;
- ``DIR.lock`` is locked (:func:`lock_folder`, ``fcntl.flock``, exclusive): a second run to the
  same ``DIR``, or a ``grindtwin report DIR``, is refused at once, so two can never mix their
  files; the kernel drops the lock when a process dies, so a killed run leaves no stale lock;
- ``DIR.partial`` is created, with an ``_INCOMPLETE`` marker as its first file: this is the
  writability check. Everything is written there; only when every file is written is the
  marker removed and the folder renamed to ``DIR``. If the run fails or is interrupted the
  partial folder is removed; if the process is killed outright, what remains is
  ``DIR.partial`` with its marker, never a ``DIR`` that looks complete.
Removing: a partial folder this run made is emptied and removed; a stale one (with the
marker) and a previous result only by name (the names a run writes and their scratch files, or
the ones its manifest lists), then with ``os.rmdir``, which fails rather than delete anything
else. A previous result is moved aside into a fresh hidden folder first, and put back if the
new one cannot be put in place (:func:`twin.atomic.replace_folder`).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from contextlib import nullcontext
from importlib import metadata
from pathlib import Path

from scenarios.errors import RunError, SceneError, raise_if_interrupted
from twin import (LockError, acquire_lock, file_sha256, json_text, release_lock, remove_by_name, replace_folder,
                  temporaries_of, write_beside, write_text_atomically)
from scenarios.output.plots import PLOTS, SWEEP_PLOT, write_plots
from scenarios.output.workbook import (PSD_FILES, RUN_WORKBOOK, STREAMS_FILE, SWEEP_WORKBOOK, write_csv,
                                      write_size_csvs, write_workbook)

INCOMPLETE_MARKER = "_INCOMPLETE"
MANIFEST = "grindtwin-manifest.json"
#: first words of DIR.lock, by which a run knows the lock is grindtwin's (not a user's file)
LOCK_TAG = "grindtwin lock"
#: Files grindtwin may add to a finished run folder later (``grindtwin report``); each, and the
#: manifest that records them, is written via a temporary file of a name no one else holds
#: (:func:`later_names` counts those a killed process left).
LATER_FILES = ("report.html",)
#: The later files whose sha256 the manifest records (its :data:`LATER_SHA256`): one whose content is
#: not what grindtwin last wrote (edited by hand, or the user's own) is never replaced or removed.
RECORDED_LATER_FILES = ("report.html",)
#: The manifest's key of the later files' sha256 (name -> hex); apart from ``sha256``, which is the
#: run's own files, checked by the report.
LATER_SHA256 = "later_sha256"
#: Every name a run or a sweep writes, so that a stale partial folder is removed by name.
RUN_FILES = ("timeseries.parquet", "timeseries.csv", *PSD_FILES.values(), STREAMS_FILE, RUN_WORKBOOK,
             "summary.json", *PLOTS, "sweep.csv", "sweep.parquet", "sweep_traces.csv", SWEEP_PLOT, SWEEP_WORKBOOK,
             MANIFEST, INCOMPLETE_MARKER)


#: how an error names the output folder: the CLI's option and the Python functions' parameter
#: (run_scene said --out to a Python caller)
OUT_NAME = "(--out; out_dir in Python)"


def _refuse(final: Path, why: str) -> SceneError:
    return SceneError(f"The output folder {final} {OUT_NAME}: {why}; nothing was run. Choose a new folder "
                      "(e.g. runs/NAME), or move the folder away yourself.")


def installed_version() -> str | None:
    """The installed grindtwin's version (None when run from a checkout that is not installed)."""
    try:
        return metadata.version("grindtwin")
    except metadata.PackageNotFoundError:
        return None


def read_manifest(folder: Path) -> dict | None:
    """The grindtwin manifest of ``folder`` (a dict whose ``files`` is a list), or None."""
    try:
        data = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    ok = isinstance(data, dict) and data.get("written_by") == "grindtwin" and isinstance(data.get("files"), list)
    return data if ok else None


def manifest_files(folder: Path) -> list[str] | None:
    """The files a grindtwin manifest in ``folder`` lists, or ``None`` if it has none."""
    data = read_manifest(folder)
    return None if data is None else [str(f) for f in data["files"]]


def later_file_is_as_written(folder: Path, name: str, manifest: dict | None = None) -> bool:
    """Whether ``folder/name`` (one of :data:`RECORDED_LATER_FILES`) is a regular file whose sha256
    is the one the manifest recorded when grindtwin wrote it; False for a file edited since, one
    of the user's, a symbolic link, or one a grindtwin that recorded none wrote."""
    manifest = read_manifest(folder) if manifest is None else manifest
    recorded = (manifest or {}).get(LATER_SHA256)
    path = folder / name
    if not isinstance(recorded, dict) or path.is_symlink() or not path.is_file():
        return False
    return recorded.get(name) == file_sha256(path)


def record_later_file(folder: Path, name: str, sha256: str) -> None:
    """Record in ``folder``'s manifest that grindtwin wrote ``name`` with this ``sha256`` (the
    manifest is replaced via a temporary file, as a whole)."""
    manifest = read_manifest(folder)
    if manifest is None:
        raise RunError(f"{folder}: its {MANIFEST} is gone or unreadable; {name} was written but not recorded")
    later = manifest.get(LATER_SHA256)
    manifest[LATER_SHA256] = {**(later if isinstance(later, dict) else {}), name: sha256}
    write_text_atomically(folder / MANIFEST, json.dumps(manifest, indent=2) + "\n")


def later_names(folder: Path) -> list[str]:
    """The names grindtwin may have added to a finished run folder: :data:`LATER_FILES` and the
    temporary files a killed report left of them or of the manifest (twin.atomic.temporaries_of)."""
    return [*LATER_FILES, *temporaries_of(folder, (MANIFEST, *LATER_FILES))]


def strangers(folder: Path, also: tuple[str, ...] = ()) -> list[str] | None:
    """Names in an existing ``folder`` that grindtwin did not write (``[]``: all ours, or
    empty); ``None`` if ``folder`` is not a directory. A :data:`RECORDED_LATER_FILES` file that is
    not as grindtwin last wrote it (:func:`later_file_is_as_written`), or a listed one edited since,
    is the user's. ``also``: names of the writer's own temporaries, allowed too."""
    if not folder.is_dir():
        return None
    names = sorted(p.name for p in folder.iterdir())
    if not names:
        return []
    manifest = read_manifest(folder)
    if manifest is None:
        return names
    allowed = {str(f) for f in manifest["files"]} | {MANIFEST, *later_names(folder), *also}
    return [n for n in names if n not in allowed
            or (n in RECORDED_LATER_FILES and not later_file_is_as_written(folder, n, manifest))
            or not _as_written(folder, n, manifest)]


def _as_written(folder: Path, name: str, manifest: dict) -> bool:
    """False for a file the manifest lists with a sha256 it no longer has (edited since grindtwin wrote it:
    the next run replaced a time series a user had annotated); True for the rest."""
    recorded = manifest.get("sha256")
    want = recorded.get(name) if isinstance(recorded, dict) else None
    if want is None:
        return True
    path = folder / name
    # a list while files are being replaced (:func:`replace_recorded_files`): the old or the new content
    return path.is_file() and not path.is_symlink() and file_sha256(path) in _hashes(want)


def _hashes(recorded) -> list[str]:
    return [recorded] if isinstance(recorded, str) else [h for h in recorded if isinstance(h, str)] \
        if isinstance(recorded, list) else []


def _check_place(final: Path, protect: tuple[Path, ...]) -> None:
    if final.is_symlink():  # a result replaces DIR as a whole: the link would be renamed away
        raise _refuse(final, f"it is a symbolic link (to {os.readlink(final)}); give the folder itself")
    here = Path.cwd().resolve()
    target = final.resolve()
    if target == here or target in here.parents:
        raise _refuse(final, "this is the current folder or one of its parents, which grindtwin "
                      "would have to replace")
    for p in protect:
        if target == p.resolve() or target in p.resolve().parents:
            raise _refuse(final, f"this folder holds {p.name}, which grindtwin did not write")
    if final.exists() and not final.is_dir():
        raise _refuse(final, "a file of that name exists")
    others = strangers(final)
    if others:
        shown = ", ".join(others[:5]) + (f" and {len(others) - 5} more" if len(others) > 5 else "")
        listed = set(manifest_files(final) or [])
        edited = [n for n in others if n in RECORDED_LATER_FILES or n in listed]
        why = (f"; {', '.join(edited)} is not the one grindtwin last wrote (edited since, or yours), so "
               "it is kept" if edited else "")
        raise _refuse(final, f"the folder exists and holds files grindtwin did not write ({shown}){why}")


def lock_path(folder) -> Path:
    """``DIR.lock``: the lock file of the folder ``DIR``, beside it (not in it: a run replaces it)."""
    final = Path(os.path.abspath(folder))  # "." and ".." get a name of their own
    return final.with_name(final.name + ".lock")


def lock_folder(folder, refuse: Callable[[str], Exception]) -> int:
    """Hold ``DIR.lock`` (:func:`twin.atomic.acquire_lock`, tagged :data:`LOCK_TAG`; a bare pid is an
    older grindtwin's): one run or report writes a folder at a time. ``refuse(why)``: the error raised
    when another run or report holds it, or when it is not grindtwin's (``uv.lock`` beside ``--out
    uv``), which is left as it was. Returns the descriptor for :func:`twin.atomic.release_lock`."""
    path = lock_path(folder)
    try:
        return acquire_lock(path, LOCK_TAG, lambda text: text.startswith(LOCK_TAG) or text.strip().isdigit())
    except LockError as exc:
        if exc.busy:
            why = f"another grindtwin run or report ({exc.text.strip() or '?'}) is writing to this folder"
        else:
            why = f"{path.name} beside it is not grindtwin's (grindtwin locks DIR with the file DIR.lock)"
        raise refuse(f"{why} (lock {path.name})") from None


class OutputClaim:
    """An output folder claimed for one run: checked, locked, ``DIR.partial`` created.

    Use as a context manager; :meth:`commit` writes the files into the partial folder (via
    ``write_files(folder) -> None``) and puts it in place. Leaving the block without a commit
    (an error, Ctrl-C, SIGTERM) removes the partial folder and releases the lock.
    """

    def __init__(self, out_dir, protect=()):
        self.given = Path(out_dir)
        self.final = Path(os.path.abspath(out_dir))  # "." and ".." get a name of their own
        self.partial = self.final.with_name(self.final.name + ".partial")
        self.lock_path = lock_path(self.final)
        self._protect = tuple(Path(p) for p in protect if p is not None)
        self._lock_fd: int | None = None
        self._keep_partial = False
        self.notes: list[str] = []

    # ------------------------------------------------------------------ claim
    def __enter__(self) -> OutputClaim:
        _check_place(self.given, self._protect)
        parent = self.final.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
            self._lock()
            self._fresh_partial()
        except OSError as exc:
            self._unlock()
            raise _refuse(self.final, f"cannot write there ({exc.strerror or exc})") from None
        except BaseException:
            self._unlock()
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.partial.exists() and not self._keep_partial:
            remove_by_name(self.partial)  # this run made it: everything in it is this run's
        self._unlock()

    def _lock(self) -> None:
        self._lock_fd = lock_folder(self.final, lambda why: _refuse(self.final, why))

    def _unlock(self) -> None:
        if self._lock_fd is not None:
            release_lock(self.lock_path, self._lock_fd)
            self._lock_fd = None

    def _fresh_partial(self) -> None:
        if self.partial.exists() and not self.partial.is_dir():  # a user's file of that name
            raise _refuse(self.final, f"{self.partial.name} is a file, not grindtwin's; it is where this run "
                          "writes before it moves its results to the output folder")
        if self.partial.exists():  # left by a killed run: ours if marked, or as far as its manifest says
            marked = (self.partial / INCOMPLETE_MARKER).exists()
            names = ([*RUN_FILES, *temporaries_of(self.partial, RUN_FILES)] if marked
                     else [*(manifest_files(self.partial) or []), MANIFEST])
            if not remove_by_name(self.partial, names):
                raise _refuse(self.final, f"{self.partial.name} is left from an earlier run and holds "
                              "files grindtwin did not write")
        self.partial.mkdir()
        (self.partial / INCOMPLETE_MARKER).write_text("this run was interrupted while its results "
                                                      "were written; do not use these files\n")

    # ------------------------------------------------------------------ commit
    def commit(self, write_files: Callable[[Path], None], kind: str = "run", after_signal: bool = False) -> Path:
        """Write the files (``write_files(partial_folder)``), the manifest, and put the folder
        in place of ``DIR`` (a previous grindtwin result there is replaced as a whole), unless a
        signal came during the run (:func:`scenarios.errors.raise_if_interrupted`) and ``after_signal``
        does not say the files are whole nonetheless (an interrupted sweep's finished cases)."""
        check = (lambda: None) if after_signal else raise_if_interrupted
        check()
        write_files(self.partial)
        files = sorted(p.name for p in self.partial.iterdir() if p.name != INCOMPLETE_MARKER)
        (self.partial / MANIFEST).write_text(json.dumps(manifest_of(self.partial, files, kind), indent=2) + "\n",
                                             encoding="utf-8")
        check()
        (self.partial / INCOMPLETE_MARKER).unlink()
        self._replace_final()
        return self.final

    def _replace_final(self) -> None:
        listed = []
        if self.final.exists():
            if strangers(self.final):  # a file was added while this run was computing
                self._keep_partial = True
                raise RunError(f"The output folder {self.final} {OUT_NAME}: files grindtwin did not write "
                               f"appeared in the folder during the run; it was left alone and the results are in "
                               f"{self.partial}")
            listed = (manifest_files(self.final) or []) + [MANIFEST, *later_names(self.final)]
        kept = replace_folder(self.final, self.partial, listed)
        if kept is not None:
            self.notes.append(f"kept {kept}: the previous result there holds files grindtwin did not write")


def manifest_of(folder: Path, files: list[str], kind: str, sha256: dict | None = None) -> dict:
    """The manifest of ``files`` grindtwin wrote in ``folder``: each with its sha256 (what tells a later
    writer that the folder is grindtwin's, and which of its files were edited since), read from the
    files unless given."""
    sha256 = {name: file_sha256(folder / name) for name in files} if sha256 is None else sha256
    return {"written_by": "grindtwin", "kind": kind, "files": files, "sha256": sha256,
            "grindtwin_version": installed_version(), "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}


def replace_recorded_files(folder: Path, kind: str, writers: dict) -> None:
    """Write or rewrite the files ``{name: write(path)}`` in ``folder`` and its manifest (listing them
    alone) so that a process stopped at any point leaves a folder :func:`strangers` takes as
    grindtwin's: each file is written beside its place (twin.write_beside), the manifest then lists
    each file's old and new sha256, the files are renamed into place, and the manifest lists the new
    ones. (Written one after the other, a stop between the files and the manifest left files the old
    manifest called edited since, and the folder was refused.)"""
    old = (read_manifest(folder) or {}).get("sha256")
    old = old if isinstance(old, dict) else {}
    temps = {}
    try:
        for name, write in writers.items():
            temps[name] = write_beside(folder / name, write)
        new = {name: file_sha256(tmp) for name, tmp in temps.items()}
        either = {name: list(dict.fromkeys([*_hashes(old.get(name)), sha])) for name, sha in new.items()}
        write_text_atomically(folder / MANIFEST, json.dumps(manifest_of(folder, list(writers), kind, either),
                                                            indent=2) + "\n")
        for name, tmp in temps.items():
            os.replace(tmp, folder / name)
    except BaseException:
        for tmp in temps.values():
            tmp.unlink(missing_ok=True)
        raise
    write_text_atomically(folder / MANIFEST, json.dumps(manifest_of(folder, list(writers), kind, new), indent=2) + "\n")


def claim_output(out_dir, protect=()):
    """:class:`OutputClaim` for ``out_dir``, or a do-nothing context (yielding ``None``) when
    ``out_dir`` is ``None``. ``protect``: files (e.g. the scene file) whose folder is refused."""
    return nullcontext(None) if out_dir is None else OutputClaim(out_dir, protect)


def write_files(result, folder: Path, csv: bool = False, plots: bool = True, xlsx: bool = False) -> None:
    """The files of ``result`` (a :class:`scenarios.run.runner.RunResult`) into ``folder``."""
    frame = result.frame
    frame.to_parquet(folder / "timeseries.parquet", index=False)
    if csv:
        write_csv(frame, folder / "timeseries.csv", index=False)
    write_size_csvs(result, folder)
    if xlsx:
        write_workbook(result, folder / RUN_WORKBOOK)
    if plots:
        write_plots(result, folder)
    summary = dict(result.summary)
    summary["files"] = sorted(p.name for p in folder.iterdir() if p.name != INCOMPLETE_MARKER) \
        + ["summary.json"]
    (folder / "summary.json").write_text(json_text(summary, indent=2) + "\n")


def write_run(result, out_dir, csv: bool = False, plots: bool = True, xlsx: bool = False, protect=()) -> Path:
    """Claim ``out_dir`` and write ``result`` there atomically (see the module docstring)."""
    with OutputClaim(out_dir, protect) as claim:
        return claim.commit(lambda folder: write_files(result, folder, csv, plots, xlsx))
