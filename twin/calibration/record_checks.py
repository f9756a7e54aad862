"""What a calibration record must be to be run (twin.calibration.files.check_record): every
field the twin reads has its type and is finite, every fitted number is the value its fit
recorded, and a DEM calibration's laws are those its own DEM step gives. A hand-edited or
truncated file is refused, naming the file, the field, its value and what is allowed."""

from __future__ import annotations

import hashlib
import json
import math

from ..errors import TwinInputError


def _short(value, width: int = 160) -> str:
    text = repr(value)
    return text if len(text) <= width else text[:width] + " ..."


def _bad(where: str, field: str, value, allowed: str) -> TwinInputError:
    return TwinInputError(f"{where}: the calibration field {field!r} must be {allowed}. Got {_short(value)}.")


def _is_number(value) -> bool:
    """A finite real number as JSON gives it (not a bool, a string, NaN or an infinity)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


#: The coefficients each breakage map and the effects read: the DEM chain's fitted ones
#: (twin.calibration.fitted.DEM_NAMES, less the lab mill's) and the mineralogy map's
#: (breakage_map.COEFFICIENT_NAMES); spelled out here because importing those loads CasADi,
#: which the surrogate's answer does not (a test checks they agree).
MAP_COEFFICIENTS = {"dem": ("dem_capture_scale", "cushioning_rate_coeff", "slurry_power_coeff",
                            "clay_crowding_coeff"),
                    "mineralogy": ("se_ref_t_kwh", "hardness_exponent", "texture_exponent", "alpha_texture_exponent",
                                   "cushioning_rate_coeff", "slurry_power_coeff", "clay_crowding_coeff")}


#: The one mill whose values a calibration fits (the laboratory mill of MISSION.md's table).
CALIBRATED_MILL = "lab"


def check_fields(record: dict, where: str) -> None:
    """Each field the twin reads has its type, every number is finite, every coefficient the map
    and effects read is there: a missing one must not fall back to a default silently."""
    from dataclasses import fields

    from ..mill import Mill

    if not isinstance(record["name"], str) or not record["name"].strip():
        raise _bad(where, "name", record["name"], "a non-empty string")
    effects = record["effects"]
    if (not isinstance(effects, list) or not effects or not all(isinstance(e, str) and e for e in effects)
            or len(set(effects)) != len(effects)):
        raise _bad(where, "effects", effects, "a list of distinct effect names")
    grid = record["size_grid"]
    if (not isinstance(grid, dict) or set(grid) - {"top_um", "ratio", "count", "scheme"}
            or not all(k in grid for k in ("top_um", "ratio", "count"))
            or not all(_is_number(grid[k]) for k in ("top_um", "ratio"))
            or not isinstance(grid["count"], int) or isinstance(grid["count"], bool)):
        raise _bad(where, "size_grid", grid, "a table of top_um and ratio (numbers), count (an integer) and "
                   "scheme")
    if not (grid["top_um"] > 0 and grid["ratio"] > 1 and 3 <= grid["count"] <= 400
            and grid.get("scheme", "austin") in ("austin", "cell_average")):
        raise _bad(where, "size_grid", grid, "a size grid (top_um > 0, ratio > 1, count in [3, 400], scheme "
                   "'cell_average' or 'austin'; twin.SizeGrid)")
    code = record.get("model_code", {"sha256": "(none: the file predates it)"})
    if not isinstance(code, dict) or not isinstance(code.get("sha256"), str):
        raise _bad(where, "model_code", code, "a table with the 'sha256' of the model's sources at the fit "
                   "(twin.calibration.model_code)")
    n = record["n_mixers"]
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise _bad(where, "n_mixers", n, "an integer >= 1")
    if record["mill"] != CALIBRATED_MILL:
        raise _bad(where, "mill", record["mill"], f"{CALIBRATED_MILL!r} (the mill the table step fits)")
    coef = record["coefficients"]
    if not isinstance(coef, dict):
        raise _bad(where, "coefficients", coef, "a table of names and numbers")
    for name in MAP_COEFFICIENTS[record["breakage_map"]]:
        if name not in coef:
            raise _bad(where, f"coefficients.{name}", "(missing)",
                       f"a number (the {record['breakage_map']} map reads it)")
    for name, value in coef.items():
        if not _is_number(value):
            raise _bad(where, f"coefficients.{name}", value, "a finite number")
    if record["breakage_map"] == "dem":  # what every label says of a --fast DEM step (Calibration.fast)
        settings = record["dem"].get("settings") if isinstance(record["dem"], dict) else None
        fast = settings.get("fast", "(missing)") if isinstance(settings, dict) else "(missing)"
        if not isinstance(fast, bool):
            raise _bad(where, "dem.settings.fast", fast, "true or false (whether the DEM step ran --fast)")
    mills = record["mills"]
    if not isinstance(mills, dict) or not isinstance(mills.get(CALIBRATED_MILL), dict):
        raise _bad(where, "mills", mills, f"a table with the fitted values of the {CALIBRATED_MILL!r} mill")
    allowed = {f.name for f in fields(Mill)}
    for mill, values in mills.items():
        if not isinstance(values, dict):
            raise _bad(where, f"mills.{mill}", values, "a table of Mill fields and numbers")
        for key, value in values.items():
            if key not in allowed:
                raise _bad(where, f"mills.{mill}.{key}", key, f"a field of twin.Mill ({sorted(allowed)})")
            if not _is_number(value):
                raise _bad(where, f"mills.{mill}.{key}", value, "a finite number")


def check_fitted(record: dict, where: str) -> None:
    """Every fitted number the twin reads (coefficients, lab mill values) is the value its fit
    recorded (``fitted`` and ``fit.values``): a number changed by hand is refused."""
    fitted = record.get("fitted")
    if not isinstance(fitted, dict) or not fitted:
        raise _bad(where, "fitted", fitted, "a table of each fitted number and its value")
    fit = record.get("fit")
    if not isinstance(fit, dict) or not isinstance(fit.get("values"), dict) or "fitted_to" not in fit:
        raise _bad(where, "fit", fit if not isinstance(fit, dict) else sorted(fit),
                   "a table of the fit with its 'values' and the data it was 'fitted_to'")
    values = fit["values"]
    lab = record["mills"][CALIBRATED_MILL]
    for name, item in fitted.items():
        value = item.get("value") if isinstance(item, dict) else None
        if not _is_number(value):
            raise _bad(where, f"fitted.{name}.value", value, "a finite number")
        _check_named(item, name, value, where)
        if name.startswith("lab_"):
            field, used = f"mills.lab.{name[len('lab_'):]}", lab.get(name[len("lab_"):])
        else:
            field, used = f"coefficients.{name}", record["coefficients"].get(name)
        if used is None:
            raise _bad(where, field, "(missing)", f"the fitted value {value!r} (fitted.{name})")
        for what, of in (("fitted", value), ("fit.values", values.get(name, value))):
            if not (_is_number(of) and math.isclose(used, of, rel_tol=1e-12, abs_tol=0.0)):
                raise _bad(where, field, used, f"the value its fit recorded, {of!r} ({what}.{name}); a fitted "
                           "number is not edited by hand: make a new calibration with `grindtwin calibrate`")
    for name in MAP_COEFFICIENTS[record["breakage_map"]]:
        if name not in fitted:
            raise _bad(where, f"fitted.{name}", "(missing)", "the fitted value of that coefficient")
    _check_nothing_typed_in(record, where)


#: Relative slack of a fitted value past its recorded bound: the fit packs a positive parameter as
#: its logarithm (twin.calibration.fitting.TableProblem), and exp(log(10)) is 10 + 2e-15.
BOUND_RTOL = 1e-9


def _check_named(item: dict, name: str, value: float, where: str) -> None:
    """A fitted number says the range it was fitted in (``bounds``, holding its value) and why it
    is fitted rather than derived (``why_not_derivable``): what the project asks of every fitted
    number, and what a reader checks a value at its bound against."""
    bounds = item.get("bounds", "(missing)")
    if not (isinstance(bounds, list) and len(bounds) == 2 and all(_is_number(b) for b in bounds)
            and bounds[0] < bounds[1]):
        raise _bad(where, f"fitted.{name}.bounds", bounds, "[lower, upper], the range it was fitted in")
    slack = BOUND_RTOL * max(abs(bounds[0]), abs(bounds[1]))
    if not bounds[0] - slack <= value <= bounds[1] + slack:
        raise _bad(where, f"fitted.{name}.value", value, f"within its bounds {bounds} (fitted.{name}.bounds)")
    why = item.get("why_not_derivable", "(missing)")
    if not isinstance(why, str) or not why.strip():
        raise _bad(where, f"fitted.{name}.why_not_derivable", why, "a sentence saying why it is fitted, not derived")


def _check_nothing_typed_in(record: dict, where: str) -> None:
    """Every number the twin reads from ``coefficients`` and ``mills`` is a fitted one: a number
    added by hand (a lab mill field such as its ball filling, another mill's values, which
    twin.mill.get_mill applies to that preset, another coefficient) would run silently."""
    fitted = record["fitted"]
    typed = "a number typed into the file, not fitted; make a new calibration with `grindtwin calibrate`"
    for mill, values in record["mills"].items():
        if mill != CALIBRATED_MILL:
            raise _bad(where, f"mills.{mill}", values, f"absent: a calibration fits the {CALIBRATED_MILL!r} mill's "
                       f"values only, and these would replace the {mill!r} preset's ({typed})")
    lab_fitted = sorted(n[len("lab_"):] for n in fitted if n.startswith("lab_"))
    for key, value in record["mills"][CALIBRATED_MILL].items():
        if key not in lab_fitted:
            raise _bad(where, f"mills.{CALIBRATED_MILL}.{key}", value, f"absent: the {CALIBRATED_MILL!r} mill's "
                       f"values are its fitted ones {lab_fitted} ({typed})")
    coef_fitted = sorted(n for n in fitted if not n.startswith("lab_"))
    for name, value in record["coefficients"].items():
        if name not in coef_fitted:
            raise _bad(where, f"coefficients.{name}", value, f"absent: the coefficients are the fitted ones "
                       f"{coef_fitted} ({typed})")


def check_data(record: dict, where: str) -> None:
    """The data the record was fitted to (``fit.fitted_to``: the reference table's path and
    SHA-256, twin.calibration.reference.reference_identity) is the shipped table as it is now: a
    table edited after the fit leaves the fitted numbers answering other data, so the file is
    refused (as a fitted number edited by hand is, :func:`check_fitted`), naming both hashes and
    the command that refits it. A user's table (twin.calibration.reference.given_reference) travels
    in the record: its values must still hash to the recorded SHA-256."""
    from .reference import given_values_sha256, reference_identity

    fitted_to = record["fit"]["fitted_to"]
    recorded = fitted_to.get("sha256") if isinstance(fitted_to, dict) else None
    if not isinstance(recorded, str):
        raise _bad(where, "fit.fitted_to", fitted_to, "the data it was fitted to: a table of its 'path' and "
                   "'sha256' (twin.calibration.reference.reference_identity)")
    now = reference_identity()
    if "values" in fitted_to:  # a table given to the fit (given_reference): its values travel with the file
        if given_values_sha256(fitted_to) != recorded:
            raise TwinInputError(
                f"{where} records the table values it was fitted to (fit.fitted_to.values) with sha256 {recorded}, "
                f"but they now hash to {given_values_sha256(fitted_to)}: edited after the fit, so its fitted numbers "
                "answer other data. Refit it (`grindtwin calibrate --table FILE`).")
        return
    if recorded != now["sha256"]:
        from .model_code import refit_command

        refit = refit_command(record)
        raise TwinInputError(
            f"{where} was fitted to the reference table {fitted_to.get('path', now['path'])} with sha256 {recorded}, "
            f"but the table's sha256 is now {now['sha256']} ({now['path']} changed after the fit): its fitted "
            f"numbers answer other data. Make a new calibration (`{refit}`), or restore the table.")


#: Relative tolerance of the DEM laws recomputed from the record's DEM step against the record's
#: (the same fit on another machine's BLAS may differ in the last digits, not more).
LAW_TOL = 1e-6


def dem_step_sha256(dem: dict) -> str:
    """Digest of a DEM step's record (its JSON with sorted keys, less this digest), recorded in it
    as ``dem.sha256`` when a calibration is made: a step edited after it ran is told from one run
    even where its laws cannot be compared (a file fitted by other twin sources)."""
    body = {k: v for k, v in dem.items() if k != "sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:16]


def check_law(record: dict, where: str, compare: bool = True) -> None:
    """The DEM laws are those of the record's own DEM step (refitted, twin.calibration.dem_map.fit_law,
    ~10 ms): a law edited by hand, or a DEM step that is not the law's, is refused. With
    ``compare=False`` only the DEM step is checked to be one the laws can be fitted to."""
    from .dem_link import fit_sizes_um
    from .dem_map import fit_law
    from .model_code import model_digest
    from ..sizes import SizeGrid

    dem = record["dem"]
    try:
        law = fit_law(dem["ores"], dem["drum"], fit_sizes_um(SizeGrid(**record["size_grid"])),
                      dem["settings"]["drop_energy_multiples"])
    except (KeyError, TypeError, ValueError, IndexError, ArithmeticError) as exc:
        raise _bad(where, "dem", f"({type(exc).__name__}: {exc})", "the record of a DEM step "
                   "(grindtwin calibrate; its ores, drum and settings)") from None
    diff = _first_difference(record["law"], law, "law") if compare else None
    if diff:
        field, got, refit = diff
        if (record.get("model_code") or {}).get("sha256") == model_digest():  # the same fit gave other laws
            how = "restore the file, or rerun its DEM step with `grindtwin calibrate`"
        else:
            how = "this twin's sources fit them otherwise: `grindtwin calibrate --from` refits them"
        raise _bad(where, field, got, f"{_short(refit)}, what the record's own DEM step gives (the laws are fitted "
                   f"to it, not edited by hand; {how})")


def check_dem_step(record: dict, where: str, compare: bool = True) -> dict:
    """A DEM calibration's record whose DEM step gives its laws (:func:`check_law`) and each
    ore's own selection function (what ``--from`` recomputes), else TwinInputError naming
    ``where`` and the field. With ``compare=False`` (a record fitted by other twin sources, whose
    laws today's fit may change) the DEM step is only checked to be one they can be fitted to.
    A step that records its digest (:func:`dem_step_sha256`) must have it."""
    from .dem_link import fit_sizes_um, per_ore_selection
    from ..sizes import SizeGrid

    check_law(record, where, compare)
    try:
        own = per_ore_selection(record["dem"], fit_sizes_um(SizeGrid(**record["size_grid"])))
    except (KeyError, TypeError, ValueError, IndexError, ArithmeticError) as exc:
        raise _bad(where, "dem", f"({type(exc).__name__}: {exc})", "the record of a DEM step "
                   "(grindtwin calibrate; its ores, drum and settings)") from None
    step = record["dem"].get("sha256")  # where the laws are not compared, the step's own digest tells an edit
    if step is not None and step != dem_step_sha256(record["dem"]):
        raise _bad(where, "dem.sha256", step, f"{dem_step_sha256(record['dem'])}, the digest of the DEM step the "
                   "file records: the step was edited after it ran; rerun it with `grindtwin calibrate`")
    recorded = (record.get("derived") or {}).get("per_ore_own_selection", own)
    diff = _first_difference(recorded, own, "derived.per_ore_own_selection") if compare else None
    if diff:
        raise _bad(where, diff[0], diff[1], f"{_short(diff[2])}, what the record's own DEM step gives")
    return record


def _first_difference(got, want, field: str):
    """(field, got, want) of the first value of ``got`` that is not ``want`` (numbers to
    :data:`LAW_TOL`), or None."""
    if isinstance(want, dict):
        if not isinstance(got, dict):
            return field, got, want
        for k in want:
            diff = _first_difference(got.get(k, "(missing)"), want[k], f"{field}.{k}")
            if diff:
                return diff
        extra = sorted(set(got) - set(want))
        return (f"{field}.{extra[0]}", got[extra[0]], "(absent)") if extra else None
    if isinstance(want, (list, tuple)):
        if not isinstance(got, list) or len(got) != len(want):
            return field, got, list(want)
        for i, (g, w) in enumerate(zip(got, want)):
            diff = _first_difference(g, w, f"{field}[{i}]")
            if diff:
                return diff
        return None
    if isinstance(want, (int, float)) and not isinstance(want, bool):
        ok = _is_number(got) and math.isclose(got, want, rel_tol=LAW_TOL, abs_tol=1e-300)
        return None if ok else (field, got, want)
    return None if got == want else (field, got, want)
