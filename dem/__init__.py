"""numba discrete-element method: bonded-particle breakage tests and mill-charge collisions (SI units).

Public API (``dem`` imports nothing from twin, mpc or scenarios):

- :mod:`dem.materials`: ``Material``, ``STEEL``, ``RAYLEIGH_SAFETY_FACTOR``,
  ``damping_coefficient``, ``rayleigh_time_step_s``, ``hertz_contact_duration_s``;
- :mod:`dem.bonds`: ``BondParams``, ``BondSet``, ``kn_from_modulus_Pa_m``;
- :mod:`dem.agglomerate`: ``make_agglomerate`` -> ``Agglomerate``;
- :mod:`dem.lab`: ``compression_test`` -> ``CompressionResult``, ``drop_weight_test`` -> ``ImpactResult``,
  ``DEFAULT_TIME_STEP_FACTOR``;
- :mod:`dem.fragments`: ``find_fragments`` -> ``FragmentResult``;
- :mod:`dem.calibrate`: ``BondCalibrator`` (``n_jobs`` processes);
- :mod:`dem.parallel`: ``run_in_processes`` (independent runs on several processes, the answers
  those of one), ``available_cores``;
- :mod:`dem.drum`: ``drum_test`` -> ``DrumResult``, ``critical_speed_rad_s``;
- :mod:`dem.system`: ``System`` (low level: state + kernels), ``PlaneWall``, ``DrumGeometry``;
- :mod:`dem.errors`: ``DemError``, ``DemInputError``, ``DemInstabilityError``, ``UnfracturedWarning``;
- ``kernel_cache_dir``: where numba keeps the compiled kernels (not inside the package; a folder
  per version of dem's sources); a ``RuntimeWarning`` at import if that folder cannot be written
  (numba would compile every time). In grindtwin's own cache folder (not a ``NUMBA_CACHE_DIR``
  of the user's), the folders of other versions unused for :data:`STALE_KERNEL_DAYS` days are
  removed at import (:func:`prune_stale_kernel_caches`).
"""

import hashlib
import os
import re
import shutil
import time
import warnings
from pathlib import Path

import numba


def kernel_source_hash() -> str:
    """A hash of every source file of dem. numba keys a cached kernel on its own file only: a
    kernel compiled with functions of another file (``dem.bonds`` into ``dem.kernels``) would be
    loaded unchanged after that file changed, the old physics run silently."""
    h = hashlib.sha256()
    for f in sorted(Path(__file__).parent.glob("*.py")):
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


#: A kernel folder of another version of dem's sources unused this long is removed (each is
#: 3-13 MB; every edit or upgrade of dem makes a new one). Another installed version that runs
#: again after that compiles once more (one to two minutes); nothing else is lost.
STALE_KERNEL_DAYS = 30
#: The file whose time says when a kernel folder was last used (touched at every import).
LAST_USED = "last-used"
_KERNEL_FOLDER = re.compile(r"dem-[0-9a-f]{16}")


def prune_stale_kernel_caches(base: Path, keep: str, now: float | None = None) -> list[Path]:
    """Remove from ``base`` (grindtwin's own folder of kernel folders, never the user's
    ``NUMBA_CACHE_DIR``) the kernel folders of other versions of dem (``dem-<hash>``, but ``keep``)
    whose :data:`LAST_USED` file is more than :data:`STALE_KERNEL_DAYS` days older than ``now``. A
    folder without that file is left: only the marker shows that grindtwin made it. Returns what
    was removed; a folder that cannot be removed is left, without a word (it is a cache)."""
    if not base.is_dir():
        return []
    now = time.time() if now is None else now
    removed = []
    for folder in base.iterdir():
        if folder.name == keep or not _KERNEL_FOLDER.fullmatch(folder.name) or folder.is_symlink() \
                or not folder.is_dir():
            continue
        marker = folder / LAST_USED
        if marker.is_file() and now - marker.stat().st_mtime > STALE_KERNEL_DAYS * 86400.0:
            shutil.rmtree(folder, ignore_errors=True)
            if not folder.exists():
                removed.append(folder)
    return removed


def kernel_cache_dir() -> Path:
    """Where numba keeps the compiled kernels: under ``$NUMBA_CACHE_DIR`` if set, else grindtwin's
    cache folder (``$GRINDTWIN_CACHE_DIR``, else ``$XDG_CACHE_HOME/grindtwin`` or
    ``~/.cache/grindtwin``, the folder of the compiled controllers; dem sits below mpc and cannot ask
    it) / ``numba``, in a folder named by :func:`kernel_source_hash` (a changed source compiles
    anew). numba's default is a ``__pycache__`` beside the sources, inside the installed package."""
    if numba.config.CACHE_DIR:
        base = Path(numba.config.CACHE_DIR)
    else:
        root = os.environ.get("GRINDTWIN_CACHE_DIR")
        if not root:
            root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "grindtwin"
        base = Path(root).expanduser() / "numba"
    return base / f"dem-{kernel_source_hash()}"


def _warn_if_unwritable(folder: Path) -> None:
    """numba compiles without caching, silently, where it cannot write: say so once, at import."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        ok = os.access(folder, os.W_OK | os.X_OK)
        reason = "not writable"
    except OSError as exc:
        ok, reason = False, f"{type(exc).__name__}: {exc.strerror or exc}"
    if not ok:
        warnings.warn(f"grindtwin: the DEM kernels cannot be cached in {str(folder)!r} ({reason}); every new "
                      "process compiles them again (one to two minutes). Set GRINDTWIN_CACHE_DIR (or "
                      "NUMBA_CACHE_DIR) to a writable folder.", RuntimeWarning, stacklevel=2)


# numba binds a kernel to its cache folder when it is decorated, that is when its module is
# imported here: the folder is set for dem's kernels only, and the user's setting put back after
_user_cache_dir = numba.config.CACHE_DIR
_kernels = kernel_cache_dir()
numba.config.CACHE_DIR = str(_kernels)
_warn_if_unwritable(_kernels)
try:  # this version's folder is in use (for another version's pruning); then prune grindtwin's own
    (_kernels / LAST_USED).touch()
    if not _user_cache_dir:
        prune_stale_kernel_caches(_kernels.parent, _kernels.name)
except OSError:
    pass  # a cache that cannot be written was reported above
try:
    from dem.agglomerate import Agglomerate, make_agglomerate
    from dem.bonds import BondParams, kn_from_modulus_Pa_m
    from dem.calibrate import BondCalibrator
    from dem.drum import DrumResult, critical_speed_rad_s, drum_test
    from dem.errors import DemError, DemInputError, DemInstabilityError, UnfracturedWarning
    from dem.fragments import FragmentResult, find_fragments
    from dem.lab import (DEFAULT_TIME_STEP_FACTOR, CompressionResult, ImpactResult, compression_test,
                         drop_weight_test)
    from dem.materials import RAYLEIGH_SAFETY_FACTOR, STEEL, Material
    from dem.parallel import available_cores, run_in_processes
finally:
    numba.config.CACHE_DIR = _user_cache_dir

__all__ = ["Agglomerate", "make_agglomerate", "BondParams", "kn_from_modulus_Pa_m",
           "BondCalibrator", "DrumResult", "critical_speed_rad_s", "drum_test", "DemError",
           "DemInputError", "DemInstabilityError", "UnfracturedWarning", "FragmentResult", "find_fragments",
           "CompressionResult", "ImpactResult", "compression_test", "drop_weight_test", "DEFAULT_TIME_STEP_FACTOR",
           "RAYLEIGH_SAFETY_FACTOR", "STEEL", "Material", "kernel_cache_dir", "kernel_source_hash",
           "prune_stale_kernel_caches", "STALE_KERNEL_DAYS", "available_cores", "run_in_processes"]
