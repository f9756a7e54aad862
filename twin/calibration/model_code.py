"""Whether the twin's equations are still those a calibration was fitted with.

A calibration's fitted numbers answer MISSION.md's table through the twin's equations as they
were at the fit. If the equations change (a corrected formula, a new term), the same numbers give
other predictions, with exit 0. So a calibration records

- ``model_code``: a digest of the sources that decide its predictions (:func:`model_digest`:
  their syntax trees without docstrings and comments, so rewording a comment changes nothing),
- ``fit.predicted``: the table's KPIs its fit computed,

and the first time a twin is built from a calibration file in a process (:func:`check_model`),
a digest that differs from the sources now makes the table's KPIs be computed again: a refactor
that leaves every KPI within :data:`PREDICTION_RTOL` passes, other equations are refused, naming
the ore, the KPI, both values and the command that refits.

The DEM step a calibration records (twin.calibration.dem_link.run_dem) carries the digest of the
DEM sources it ran (:func:`dem_step_digest`); ``grindtwin calibrate --from`` says when it reuses a
step run by other DEM sources (:func:`dem_step_note`), and records that.
"""

from __future__ import annotations

import ast
import hashlib
import importlib.util
from functools import lru_cache
from pathlib import Path

from ..errors import TwinInputError

#: Relative agreement the table's KPIs recomputed by the twin now must have with those the fit
#: recorded: far above the steady states' round-off (they reproduce bit for bit on one machine,
#: another BLAS moves the last digits), far below what a changed term moves (the power formula
#: corrected in 2026 moved the laboratory P80 by 40 %).
PREDICTION_RTOL = 1e-6
#: Sources of ``twin`` that do not decide a calibration's predictions: the surrogate is trained
#: on a calibration (downstream of it).
NOT_MODEL = ("surrogate",)


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    """``tree`` without its string statements (docstrings, attribute docstrings): they do nothing."""
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list):
            kept = [s for s in body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant)
                                             and isinstance(s.value.value, str))]
            node.body = kept or [ast.Pass()]
    return tree


def source_digest(root: Path, skip: tuple[str, ...] = ()) -> str:
    """SHA-256 (hex, 16 digits) of the Python sources under ``root`` (less the sub-folders
    ``skip``), each as its syntax tree without docstrings: comments, docstrings and layout do not
    count; names, numbers and statements do."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        if rel.parts[0] in skip:
            continue
        tree = _strip_docstrings(ast.parse(path.read_text(encoding="utf-8"), str(path)))
        h.update(rel.as_posix().encode() + b"\0" + ast.dump(tree).encode() + b"\0")
    return h.hexdigest()[:16]


def _package_dir(name: str) -> Path:
    return Path(importlib.util.find_spec(name).origin).parent


@lru_cache(maxsize=1)
def model_digest() -> str:
    """The digest of ``twin``'s sources less :data:`NOT_MODEL` (:func:`source_digest`)."""
    return source_digest(_package_dir("twin"), NOT_MODEL)


@lru_cache(maxsize=1)
def dem_step_digest() -> str:
    """The digest of what a DEM step runs: ``dem``'s sources and the virtual tests that drive them
    (twin.calibration.dem_link) (:func:`source_digest`)."""
    here = Path(__file__).parent
    link = ast.dump(_strip_docstrings(ast.parse((here / "dem_link.py").read_text(encoding="utf-8"))))
    return hashlib.sha256((source_digest(_package_dir("dem")) + link).encode()).hexdigest()[:16]


def dem_step_note(dem: dict) -> str | None:
    """What to say of a recorded DEM step (``dem``, a calibration's ``dem`` record) run by other
    DEM sources than those now (None: the same)."""
    then = dem.get("sources_sha256", "not recorded")
    if then == dem_step_digest():
        return None
    return (f"the DEM step was run by other DEM sources (digest {then}; now {dem_step_digest()}): its breakage is "
            "that DEM's; `grindtwin calibrate` without --from reruns it")


def model_identity() -> dict:
    """What a new calibration records of the twin it is fitted with (its ``model_code``)."""
    return {"sha256": model_digest(), "sources": "twin/**/*.py less twin/surrogate, syntax trees without docstrings "
            "(twin.calibration.model_code)"}


def refit_command(record: dict, shown_path: str | None = None) -> str:
    """The command that makes ``record`` again: for a DEM calibration read from a file (its path as
    a run records it, twin.calibration.Calibration.identity), with its DEM step reused
    (``--from``, into the same file) and the user's table it was fitted to (``--table``); else the
    command it was made with."""
    command = str((record.get("provenance") or {}).get("command") or "")
    if record.get("breakage_map") == "dem" and shown_path is not None:
        source = record["name"] if shown_path.startswith("twin/calibration/files/") else shown_path
        table = ((record.get("fit") or {}).get("fitted_to") or {}).get("path")
        given = "values" in ((record.get("fit") or {}).get("fitted_to") or {})
        return (f"grindtwin calibrate --from {source}" + (f" --table {table or 'YOUR_TABLE.csv'}" if given else "")
                + f" --out {shown_path}")
    if command.startswith("grindtwin calibrate"):
        return command
    return "grindtwin calibrate" + (" --map mineralogy" if record.get("breakage_map") == "mineralogy" else "")


#: (path, sha256) of the calibrations whose predictions were checked in this process.
_CHECKED: set = set()


def check_model(calibration, predict) -> None:
    """Refuse ``calibration`` if the twin's equations now give other table KPIs than its fit
    recorded (module docstring); ``predict(calibration, ores)`` computes them
    (twin.calibration.fitting.predict_table). Once per file or record (its hash) and process;
    nothing for a calibration made in memory without a hash (a fit's trial values: their
    ``fit.predicted`` is not theirs yet)."""
    key = (calibration.path, calibration.sha256)
    if calibration.sha256 is None or key in _CHECKED:
        return
    recorded = calibration.record.get("model_code")
    if isinstance(recorded, dict) and recorded.get("sha256") == model_digest():
        _CHECKED.add(key)
        return
    _CHECKED.add(key)  # the recomputation builds twins of this calibration: no recursion
    try:
        _compare_predictions(calibration, recorded, predict)
    except BaseException:
        _CHECKED.discard(key)
        raise


def _compare_predictions(calibration, recorded, predict) -> None:
    from .reference import fitted_ores

    want = calibration.record["fit"]["predicted"]
    got = predict(calibration, fitted_ores(calibration.record["fit"]))
    worst = max(((ore, kpi) for ore in want for kpi in want[ore]),
                key=lambda ok: abs(got[ok[0]][ok[1]] / want[ok[0]][ok[1]] - 1.0))
    ore, kpi = worst
    then, now = want[ore][kpi], got[ore][kpi]
    if abs(now / then - 1.0) <= PREDICTION_RTOL:
        return
    at_fit = recorded.get("sha256") if isinstance(recorded, dict) else "not recorded"
    raise TwinInputError(
        f"Calibration {calibration.label()} was fitted with other model equations than this twin's: its fit "
        f"recorded ore {ore}'s {kpi} = {then:.6g} at the table's operating point (fit.predicted), the twin now "
        f"computes {now:.6g} ({100 * (now / then - 1):+.3g} %; model sources {at_fit} at the fit, "
        f"{model_digest()} now). Its fitted numbers answer other equations: make a new calibration "
        f"(`{refit_command(calibration.record, calibration.identity()['path'])}`).")
