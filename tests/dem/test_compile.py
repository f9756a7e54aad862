"""Compiled kernels: one copy serves every system, and numba keeps it in grindtwin's cache folder,
never inside the installed package."""

import os
import shutil
import time
from pathlib import Path

import dem
from dem import kernel_source_hash

from . import in_fresh_interpreter

#: the cache folders of this suite's own environment, left out where a test sets its own
CACHE_VARS = ("NUMBA_CACHE_DIR", "GRINDTWIN_CACHE_DIR", "XDG_CACHE_HOME")


def test_every_system_runs_on_one_compiled_copy_of_the_kernels():
    """Spheres without bonds, one bond, an agglomerate and the drum: one signature each of the
    step kernels in a fresh interpreter, and no kernel of dem compiled twice. A second signature
    compiles the whole step again (the bond table of 0 or 1 rows typed C-contiguous, or a
    constant argument typed as a literal, each cost minutes on a cold cache). Kernels called only
    from other kernels list their signatures when compiled in this interpreter, that is on a cold
    cache (a fresh machine, or any change to dem's kernels); loaded from the cache, only the
    step kernels' own count is checked."""
    code = """
import numpy as np
from dem import kernels as K
from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams, BondSet, kn_from_modulus_Pa_m
from dem.drum import drum_system
from dem.materials import Material
from dem.system import PlaneWall, System
pos, rad = np.array([[0.0, 0, 0], [1.9e-3, 0, 0]]), np.array([1e-3, 1e-3])
bp = BondParams(kn_Pa_m=1e13, ks_Pa_m=4e12, tensile_strength_Pa=2e6, cohesion_Pa=4e6)
System(pos, rad, Material()).run(5)
System(pos, rad, Material(), bonds=BondSet([[0, 1]], pos, rad, bp)).run(5)
agg = make_agglomerate(0.01, 60, random_state=1)
bs = BondSet(agg.bond_pairs, agg.pos_m, agg.radius_m, bp)
z = float(np.min(agg.pos_m[:, 2] - agg.radius_m))
System(agg.pos_m, agg.radius_m, Material(), bonds=bs, walls=[PlaneWall((0, 0, z), (0, 0, 1))]).run(5)
drum_system(0.7, 0.3, ball_diameter_m=0.04, section_length_m=0.1, random_state=2).system.run(5)
import numba
from dem import bonds, contacts, state
twice = [f"{m.__name__}.{k}" for m in (K, bonds, contacts, state) for k, f in vars(m).items()
         if isinstance(f, numba.core.registry.CPUDispatcher) and len(f.signatures) > 1]
print([len(f.signatures) for f in (K.run_steps, K.compute_forces)], twice)
"""
    assert in_fresh_interpreter(code) == "[1, 1] []"


CACHE_PATHS = ("import numba, dem, dem.kernels as K, dem.contacts as C; "
               "print(K.run_steps._cache._cache_path, C.pair_contact._cache._cache_path, repr(numba.config.CACHE_DIR))")


def test_kernels_are_cached_in_grindtwins_folder_not_in_the_package(tmp_path):
    version = f"dem-{kernel_source_hash()}"
    kernels, contacts, after = in_fresh_interpreter(CACHE_PATHS, CACHE_VARS, XDG_CACHE_HOME=str(tmp_path)).split()
    for path in (kernels, contacts):
        assert Path(path).parent == tmp_path / "grindtwin" / "numba" / version, path
    assert after == "''"  # numba's own setting put back for the user's functions
    # a grindtwin cache folder and a user's numba setting are both honoured
    mine = in_fresh_interpreter(CACHE_PATHS, CACHE_VARS, GRINDTWIN_CACHE_DIR=str(tmp_path / "g")).split()[0]
    assert Path(mine).parent == tmp_path / "g" / "numba" / version
    theirs = in_fresh_interpreter(CACHE_PATHS, CACHE_VARS, NUMBA_CACHE_DIR=str(tmp_path / "n")).split()
    assert Path(theirs[0]).parent == tmp_path / "n" / version and theirs[2] == repr(str(tmp_path / "n"))


def test_a_changed_source_of_dem_gets_a_new_kernel_cache(tmp_path):
    """numba keys a cached kernel on its own file only: after an edit of dem/bonds.py (compiled into
    dem.kernels' step), doubling the bond stiffness, the old kernels were loaded and the old physics
    ran with no word. The cache folder is named by a hash of every dem source, so a changed file
    (an edit, an upgrade) compiles anew."""
    copy = tmp_path / "src"
    shutil.copytree(Path(dem.__file__).parent, copy / "dem", ignore=shutil.ignore_patterns("__pycache__"))
    where = "import dem; print(dem.__file__, dem.kernel_cache_dir())"
    env = dict(cwd=copy, XDG_CACHE_HOME=str(tmp_path / "cache"))
    source, before = in_fresh_interpreter(where, CACHE_VARS + ("PYTHONPATH",), **env).split()
    assert source == str(copy / "dem" / "__init__.py")
    assert before == str(tmp_path / "cache" / "grindtwin" / "numba" / f"dem-{kernel_source_hash()}")
    bonds = copy / "dem" / "bonds.py"
    text = bonds.read_text()
    assert "+ g[G_KNA, t] * " in text
    bonds.write_text(text.replace("+ g[G_KNA, t] * ", "+ 2.0 * g[G_KNA, t] * "))
    after = in_fresh_interpreter(where, CACHE_VARS + ("PYTHONPATH",), **env).split()[1]
    assert Path(after).parent == Path(before).parent and after != before


def test_an_unwritable_cache_folder_is_reported_not_silent(tmp_path):
    """numba compiles without caching where it cannot write, and says nothing: dem warns at import,
    naming the folder and how to choose another. A file where the folder should be stands in
    for an unwritable folder (permissions do not stop root)."""
    (tmp_path / "grindtwin").write_text("not a folder")
    code = ("import warnings; warnings.simplefilter('always')\n"
            "with warnings.catch_warnings(record=True) as w:\n"
            "    import dem\n"
            "print(repr([str(x.message) for x in w if issubclass(x.category, RuntimeWarning)]))")
    said = in_fresh_interpreter(code, CACHE_VARS, XDG_CACHE_HOME=str(tmp_path))
    assert str(tmp_path / "grindtwin" / "numba") in said and "GRINDTWIN_CACHE_DIR" in said, said
    # a writable folder: no warning
    assert in_fresh_interpreter(code, CACHE_VARS, XDG_CACHE_HOME=str(tmp_path / "ok")) == "[]"


def _kernel_folder(base: Path, name: str, days_ago: float, marker: bool = True) -> Path:
    """A kernel folder of another version, last used ``days_ago`` (by its marker, if ``marker``)."""
    folder = base / name
    (folder / "dem_0123").mkdir(parents=True)
    (folder / "dem_0123" / "kernels.nbi").write_text("index")
    t = time.time() - days_ago * 86400.0
    if marker:
        (folder / dem.LAST_USED).touch()
        os.utime(folder / dem.LAST_USED, (t, t))
    os.utime(folder, (t, t))
    return folder


def test_stale_kernel_folders_of_other_versions_are_pruned_and_nothing_else(tmp_path):
    """Every edit or upgrade of dem leaves a 3-13 MB kernel folder: those of other versions unused
    for STALE_KERNEL_DAYS go, by their last-used marker, and nothing else in the folder does."""
    old, days = "dem-" + "a" * 16, dem.STALE_KERNEL_DAYS
    stale = _kernel_folder(tmp_path, old, days + 1)
    stale_unmarked = _kernel_folder(tmp_path, "dem-" + "b" * 16, days + 1, marker=False)
    recent = _kernel_folder(tmp_path, "dem-" + "c" * 16, days - 1)
    mine = _kernel_folder(tmp_path, "dem-" + "d" * 16, days + 5)  # this version's, however old
    other = _kernel_folder(tmp_path, "dem-notahash", days + 5)
    (tmp_path / ("dem-" + "e" * 16)).write_text("a file, not a folder")
    (tmp_path / ("dem-" + "f" * 16)).symlink_to(stale_unmarked)
    removed = dem.prune_stale_kernel_caches(tmp_path, mine.name)
    assert removed == [stale] and not stale.exists()
    # without grindtwin's marker a folder is not known to be grindtwin's: it stays, however old
    assert stale_unmarked.is_dir() and (stale_unmarked / "dem_0123" / "kernels.nbi").is_file()
    assert recent.is_dir() and mine.is_dir() and other.is_dir() and (tmp_path / ("dem-" + "e" * 16)).is_file()


def test_importing_dem_prunes_its_own_cache_but_never_the_users_numba_folder(tmp_path):
    old = "dem-" + "a" * 16
    own = _kernel_folder(tmp_path / "x" / "grindtwin" / "numba", old, dem.STALE_KERNEL_DAYS + 1)
    users = _kernel_folder(tmp_path / "n", old, dem.STALE_KERNEL_DAYS + 1)
    where = "import dem; print(dem.kernel_cache_dir())"
    current = Path(in_fresh_interpreter(where, CACHE_VARS, XDG_CACHE_HOME=str(tmp_path / "x")))
    assert not own.exists() and (current / dem.LAST_USED).is_file()  # and this version's use is marked
    in_fresh_interpreter(where, CACHE_VARS, NUMBA_CACHE_DIR=str(tmp_path / "n"))
    assert users.is_dir()
