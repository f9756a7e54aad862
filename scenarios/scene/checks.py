"""Checks that relate several fields of a scene, run on the raw TOML table.

They run even when the schema pass found errors, so they read the table defensively: a
check whose inputs have the wrong type is skipped (the schema pass reports those). Each
message is ``key.path: what is wrong and what is allowed (got VALUE)``.

Tolerances: blend fractions must sum to 1 within the twin's ``blend_sum_tolerance``; explicit mineralogy
must sum to 100 wt% within ``MINERAL_SUM_TOL_PCT``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from scenarios.errors import SceneError
from scenarios.scene.history import read_history_once
from scenarios.scene.keypaths import did_you_mean, format_path
from scenarios.scene.ranges import (controller_feed_min_problem, feed_problem, net_power_problem, nominal_feed_tph,
                                     power_limit_problem, preset_mill)
from scenarios.scene.schema import DEFAULT_N_MIXERS, Feed, Sensors
from twin import SizeGrid, TwinError, get_mill, hydrocyclone_from, is_preset_file, read_preset
from twin.calibration import DEFAULT_CALIBRATION, load_calibration
from twin.effects import problems as effect_problems
from twin.ore import (SUM_TOLERANCE_WT_PCT, blend_sum_ok, blend_sum_tolerance, fractions_hint, mineral_names,
                      mineral_table, reference_ores)

MINERAL_SUM_TOL_PCT = SUM_TOLERANCE_WT_PCT  # the twin's Mineralogy's own
#: How far an ore's given solids density may lie outside the range of its minerals' densities (minerals.csv),
#: relatively: a mixture's solids density (the mass-weighted harmonic mean) lies inside that range, and a mineral's
#: own density spreads by about this much with its composition (Deer, Howie & Zussman 2013: biotite 2.7-3.3 t/m3
#: about the table's 3.05). Further out it is a bulk density (broken ore with its voids, 1.5-2.0 t/m3) or a slip.
ORE_DENSITY_TOL_FRAC = 0.10

TEXTURE_KEYS = ("mean_grain_um", "uniformity", "association_entropy")


def _get(data: Any, *loc) -> Any:
    for step in loc:
        if isinstance(data, dict) and isinstance(step, str) and step in data:
            data = data[step]
        elif isinstance(data, list) and isinstance(step, int) and 0 <= step < len(data):
            data = data[step]
        else:
            return None
    return data


def _num(x: Any) -> float | None:
    """A finite number, else None (NaN and infinities are the schema pass's to report)."""
    ok = isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
    return float(x) if ok else None


class _Report:
    def __init__(self) -> None:
        self.messages: list[str] = []

    def add(self, loc: tuple, problem: str, value: Any = ..., ) -> None:
        got = "" if value is ... else f" (got {value!r})"
        self.messages.append(f"{format_path(loc)}: {problem}{got}")


def cross_check(data: dict[str, Any], base_dir: Path, as_written: bool = False) -> list[str]:
    """Every cross-field problem of a raw scene table (``base_dir`` resolves relative paths).

    ``as_written``: the table is a scene file as its author wrote it (:func:`scenarios.scene.load_scene`,
    ``grindtwin check``), so the keys its own controller kind reads nothing of are refused too
    (:func:`_check_idle_as_written`); a table a program derived from a file (a sweep's case varying
    ``controller.kind``, a guide's variant of an NMPC scene, a replay's scene) keeps the file's other keys."""
    r = _Report()
    if not isinstance(data, dict):
        return ["(top level): a scene must be a TOML table"]
    data = _with_preset_file(data, base_dir, r)
    _check_time(data, r)
    _check_effects(data, r)
    ore_names = _check_ores(data, r)
    _check_feed(data, ore_names, r, base_dir)
    _check_schedule(data, ore_names, r)
    _check_history(data, ore_names, base_dir, r)
    _check_controller(data, r)
    _check_sensors(data, r)
    _check_plant(data, r)
    _check_calibration(data, base_dir, r)
    if as_written:
        _check_idle_as_written(data, r)
    return r.messages


def _with_preset_file(data: dict, base_dir: Path, r: _Report) -> dict:
    """``data`` with a preset file in ``mill.preset`` resolved against the scene's folder for the checks that
    read the mill (None, and said here, when the file is no preset grindtwin wrote)."""
    preset = _get(data, "mill", "preset")
    if not (isinstance(preset, str) and is_preset_file(preset)):
        return data
    path = Path(preset) if Path(preset).is_absolute() else base_dir / preset
    try:
        read_preset(path)
    except TwinError as exc:
        r.add(("mill", "preset"), str(exc), preset)
        path = None
    return {**data, "mill": {**data["mill"], "preset": path}}


def _check_time(data, r: _Report) -> None:
    dur, dt = _num(_get(data, "scene", "duration_h")), _num(_get(data, "scene", "sample_period_h"))
    if dur and dt and dur > 0 and dt > 0:
        if dt >= dur:
            r.add(("scene", "sample_period_h"), f"must be shorter than scene.duration_h = {dur:g}", dt)
        elif abs(dur / dt - round(dur / dt)) > 1e-6 * dur / dt:
            r.add(("scene", "duration_h"), f"must be a whole number of sample periods ({dt:g} h)", dur)


def _check_effects(data, r: _Report) -> None:
    _check_effect_table(data.get("effects"), data.get("effect_options", {}), (), r)


def _check_effect_table(effects, options, prefix: tuple, r: _Report) -> None:
    """Effects and their options (under ``prefix``), by the twin's own validation
    (:func:`twin.effects.problems`): names, requirements, exclusions, needed variables,
    option names and values."""
    if not isinstance(effects, list) or not isinstance(options, dict):
        return  # the schema pass reports the types
    bad = [name for name, table in options.items() if not isinstance(table, dict)]
    for name in bad:
        r.add(prefix + ("effect_options", name), "must be a table of options", options[name])
    if not bad:
        for p in effect_problems(effects, options):
            r.add(prefix + p.loc, p.message)
        _check_cyclone(options, prefix, r)


def _check_cyclone(options: dict, prefix: tuple, r: _Report) -> None:
    """A hydrocyclone table's fields, by the twin's own Hydrocyclone validation."""
    cyc = options.get("classification", {}).get("cyclone")
    if isinstance(cyc, dict):
        loc = prefix + ("effect_options", "classification", "cyclone")
        try:
            hydrocyclone_from(cyc)
        except TwinError as exc:
            r.add(loc, str(exc))
        # read by nothing beside it: a feed's mass fraction is used over its volume %
        if "feed_solids_frac" in cyc and "feed_solids_vol_pct" in cyc:
            r.add(loc + ("feed_solids_vol_pct",), "give the cyclone feed's solids as feed_solids_frac (by mass) or "
                  "feed_solids_vol_pct (by volume), not both", cyc["feed_solids_vol_pct"])


def _check_ores(data, r: _Report) -> list[str]:
    ores = data.get("ores", {})
    if not isinstance(ores, dict):
        return []
    if not ores and _get(data, "feed", "history") is None:
        r.add(("ores",), "define at least one ore (only a scene with feed.history may have none)")
    minerals = mineral_names()
    for name, ore in ores.items():
        if not isinstance(ore, dict):
            continue
        has_type = "type" in ore
        has_explicit = "mineralogy" in ore or "texture" in ore
        if has_type and has_explicit:
            r.add(("ores", name), "give either `type` or an explicit mineralogy and texture, "
                  "not both")
        elif not has_type:
            for part in ("mineralogy", "texture"):
                if part not in ore:
                    r.add(("ores", name, part), "required for an ore without `type` "
                          "(or give type = \"A\"..\"D\")")
        mineralogy = ore.get("mineralogy")
        if isinstance(mineralogy, dict):
            _check_mineralogy(mineralogy, ("ores", name, "mineralogy"), minerals, r)
        elif ore.get("type") in reference_ores():
            mineralogy = reference_ores()[ore["type"]].wt_pct
        if isinstance(mineralogy, dict):
            _check_density(ore.get("density_t_m3"), mineralogy, ("ores", name, "density_t_m3"), r)
    return list(ores)


def _check_density(density: Any, mineralogy: dict, loc: tuple, r: _Report) -> None:
    """A given solids density within its minerals' range (:data:`ORE_DENSITY_TOL_FRAC`): a bulk density of 1.6
    for an ore of 2.8 t/m3 minerals held 1.75 times the volume of solids and ground it to a quarter of the P80."""
    rho = _num(density)
    table = mineral_table()
    own = {m: table[m].density_t_m3 for m, v in mineralogy.items() if m in table and (_num(v) or 0.0) > 0}
    if rho is None or not own:
        return
    lo, hi = min(own.values()), max(own.values())
    if not lo * (1 - ORE_DENSITY_TOL_FRAC) <= rho <= hi * (1 + ORE_DENSITY_TOL_FRAC):
        light, dense = min(own, key=own.get), max(own, key=own.get)
        r.add(loc, f"the solids density of this ore's minerals lies between {lo:g} ({light}) and {hi:g} t/m3 "
              f"({dense}), within {ORE_DENSITY_TOL_FRAC:.0%}; give the density of its solids (pycnometer), not a "
              "bulk density of broken ore with its voids", density)


def _check_mineralogy(mineralogy: dict, loc: tuple, minerals: list[str], r: _Report) -> None:
    total = 0.0
    for mineral, wt in mineralogy.items():
        if mineral not in minerals:
            r.add(loc + (mineral,), f"unknown mineral{did_you_mean(mineral, minerals)}; known: "
                  + ", ".join(minerals))
        v = _num(wt)
        if v is not None and v < 0:
            r.add(loc + (mineral,), "wt% must be >= 0", wt)
        total += v or 0.0
    if abs(total - 100.0) > MINERAL_SUM_TOL_PCT:  # an empty table too: it failed later, naming no file or key
        r.add(loc, f"wt% must sum to 100 within {MINERAL_SUM_TOL_PCT:g}{fractions_hint(total)}", round(total, 6))


def _check_blend(blend: Any, loc: tuple, ore_names: list[str], r: _Report) -> None:
    if not isinstance(blend, dict):
        return
    if not blend:
        r.add(loc, "a blend needs at least one ore")
        return
    values = []
    for ore, frac in blend.items():
        if ore_names and ore not in ore_names:
            r.add(loc + (ore,), f"ore not defined in [ores]{did_you_mean(ore, ore_names)}; "
                  "defined: " + ", ".join(ore_names), ore)
        v = _num(frac)
        if v is not None and not 0.0 <= v <= 1.0:
            r.add(loc + (ore,), "fraction must be in [0, 1]", frac)
        values.append(v or 0.0)
    if not blend_sum_ok(values):
        r.add(loc, f"fractions must sum to 1 within {blend_sum_tolerance(len(values)):g}", round(sum(values), 6))


def _check_feed(data, ore_names: list[str], r: _Report, base_dir: Path = Path(".")) -> None:
    feed = data.get("feed")
    if not isinstance(feed, dict):
        return
    has_history = feed.get("history") is not None
    if feed.get("blend") is None and not has_history:
        r.add(("feed", "blend"), "required key is missing (the initial blend, e.g. "
              "{ B = 1.0 }); only a scene with feed.history has none")
    elif feed.get("blend") is not None and has_history:
        r.add(("feed", "blend"), "the history gives the feed from t = 0; remove feed.blend")
    _check_blend(feed.get("blend"), ("feed", "blend"), ore_names, r)
    effects = data.get("effects") if isinstance(data.get("effects"), list) else []
    continuous = "transport" in effects
    if continuous and feed.get("feed_tph") is None:
        r.add(("feed", "feed_tph"), "required with the `transport` effect (continuous mill)")
    if continuous and feed.get("batch_charge_kg") is not None:
        r.add(("feed", "batch_charge_kg"), "only for batch scenes (effects without `transport`)")
    if not continuous and isinstance(data.get("effects"), list):
        if feed.get("batch_charge_kg") is None:
            r.add(("feed", "batch_charge_kg"), "required for a batch scene (effects without "
                  "`transport`); or add `transport` to effects for a continuous mill")
        if feed.get("feed_tph") is not None:
            r.add(("feed", "feed_tph"), "a batch scene (effects without `transport`) has no "
                  "feed rate; use batch_charge_kg")
        if _get(data, "controller", "kind") not in (None, "none"):
            r.add(("controller", "kind"), "a batch scene (effects without `transport`) has "
                  "nothing to control; use kind = \"none\"", _get(data, "controller", "kind"))
        sensors = data.get("sensors") if isinstance(data.get("sensors"), dict) else {}
        # a scene's own table round-trips with its defaults (the analyser's period the scene's, once loaded)
        defaults = Sensors().model_dump() | {"p80_sample_period_h": _get(data, "scene", "sample_period_h")}
        given = sorted(k for k, v in sensors.items() if v is not None and v != defaults.get(k))
        if given:  # a run gave no analyser column and no word
            r.add(("sensors",), f"read by nothing: a batch scene (effects without `transport`) has no analyser and "
                  f"no controller to read one ({', '.join(given)} given); remove them, or add `transport` for a "
                  "continuous mill")
        if feed.get("start") is not None:  # changed no number: the charge is the start
            r.add(("feed", "start"), "read by nothing: a batch grind (effects without `transport`) starts with its "
                  "charge (feed.batch_charge_kg of feed.blend), not at a steady state; remove it", feed["start"])
        for key in ("schedule", "history"):  # the charge was ground as feed.blend, whatever they said later
            if feed.get(key):
                r.add(("feed", key), "a batch scene (effects without `transport`) grinds one charge of "
                      "feed.blend at feed.speed_frac_critical: a feed schedule or history (grindtwin replay's too) "
                      "is not used; add `transport` to effects for a continuous mill")
    if feed.get("start") == "target" and _get(data, "controller", "target_p80_um") is None:
        r.add(("feed", "start"), "\"target\" needs controller.target_p80_um (the P80 whose steady "
              "state the run starts at)", "target")
    ores = data.get("ores") if isinstance(data.get("ores"), dict) else {}
    if _get(data, "mill", "ball_size_mm") is not None and ores and all(
            isinstance(o, dict) and "breakage" in o for o in ores.values()):  # changed no number
        r.add(("mill", "ball_size_mm"), "read by nothing: every ore gives its own breakage parameters "
              "(ores.NAME.breakage), taken as measured on this mill, and the ball size scales only the "
              "calibration's mapped ones; remove it", _get(data, "mill", "ball_size_mm"))
    kinds = {_get(data, *at, "classification", "kind") for at in (("effect_options",), ("plant", "effect_options"))}
    if _get(data, "mill", "discharge_solids_frac") is not None and "hydrocyclone" not in kinds:  # changed no number
        r.add(("mill", "discharge_solids_frac"), "read by nothing: the discharge's solids enter a hydrocyclone "
              "circuit's water balance only (effect_options.classification.kind = \"hydrocyclone\"); a grate mill's "
              "slurry rheology is that of a 70 wt% pulp (twin.effects.rheology); remove it",
              _get(data, "mill", "discharge_solids_frac"))
    lists = [v for v in (_get(data, "effects"), _get(data, "plant", "effects")) if isinstance(v, list)]
    if _get(data, "mill", "power_model") is not None and lists and not any("power" in v for v in lists):
        r.add(("mill", "power_model"), "read by nothing: the net-power model gives the `power` effect's power and "
              "specific energy only (the breakage rates follow the mill's size, ball and speed, twin.scaleup: the "
              "reference scene's P80 is the same under both models), and no effects list of the scene has `power`; "
              "add it, or remove power_model", _get(data, "mill", "power_model"))
    # the scene's power option wins over the mill's model for the controller's twin and for a plant without its own
    # (a plant's own option beside the mill's model is a mismatch study: the controller's twin reads the mill's)
    option, own = _get(data, "effect_options", "power", "model"), _get(data, "mill", "power_model")
    if isinstance(option, str) and isinstance(own, str) and option != own:
        r.add(("mill", "power_model"), f"{own!r} but effect_options.power.model is {option!r}, which the power "
              "effect uses instead: give the model once", own)
    power = net_power_problem(_get(data, "mill", "preset"), _get(data, "mill"), _num(feed.get("feed_tph")),
                              _num(feed.get("speed_frac_critical")))
    if power:  # the nominal feed follows the power: the feed's check below would blame the feed for it
        r.add(("mill", "net_power_kw"), power, _get(data, "mill", "net_power_kw"))
    else:
        nominal = nominal_feed_tph(_get(data, "mill", "preset"), _get(data, "mill"))
        for loc in (("feed", "feed_tph"), ("controller", "bounds", "feed_tph_max")):
            v = _num(_get(data, *loc))
            problem = feed_problem(v, nominal) if v is not None and v > 0 else None
            if problem:
                r.add(loc, problem, v)
        low = _num(_get(data, "controller", "bounds", "feed_tph_min"))
        problem = controller_feed_min_problem(low, nominal) if low is not None and low > 0 else None
        if problem and _get(data, "controller", "kind") in ("pi", "nmpc"):
            r.add(("controller", "bounds", "feed_tph_min"), problem, low)
    csv = feed.get("psd_csv")
    if isinstance(csv, str) and not (Path(csv) if Path(csv).is_absolute() else base_dir / csv).is_file():
        r.add(("feed", "psd_csv"), "file not found (a CSV with columns size_um, passing_pct)", csv)
    p80 = _num(feed.get("p80_um", FEED_P80_DEFAULT_UM))
    top = _num(_get(data, "mill", "size_classes", "top_um") or 6700.0)
    if p80 is not None and top is not None and p80 >= top:
        r.add(("feed", "p80_um"), f"must be below the top size class mill.size_classes.top_um "
              f"= {top:g}", p80)


#: the feed P80 of a scene that gives none (the schema's default)
FEED_P80_DEFAULT_UM = Feed.model_fields["p80_um"].default


def _feed_p80_um(feed: dict) -> float | None:
    """The scene's feed P80 [um] when the scene gives it as ``p80_um`` or by its default (None with a
    screen analysis, or a value the schema refuses in its own check)."""
    if feed.get("psd") is not None or feed.get("psd_csv") is not None:
        return None
    p80 = _num(feed.get("p80_um", FEED_P80_DEFAULT_UM))
    return p80 if p80 is not None and p80 > 0 else None


def _check_schedule(data, ore_names: list[str], r: _Report) -> None:
    events = _get(data, "feed", "schedule")
    if not isinstance(events, list):
        return
    dur = _num(_get(data, "scene", "duration_h"))
    prev_at, prev_end = None, None
    for i, ev in enumerate(events):
        if not isinstance(ev, dict):
            continue
        loc = ("feed", "schedule", i)
        _check_blend(ev.get("blend"), loc + ("blend",), ore_names, r)
        at, ramp = _num(ev.get("at_h")), _num(ev.get("ramp_h", 0.0))
        kind = ev.get("kind", "step")
        if kind == "ramp" and ramp is not None and ramp <= 0:
            r.add(loc + ("ramp_h",), "a ramp needs ramp_h > 0", ramp)
        if kind == "step" and ramp:
            r.add(loc + ("ramp_h",), "ramp_h is only for kind = \"ramp\"", ramp)
        if at is None:
            continue
        if prev_at is not None and at <= prev_at:
            r.add(loc + ("at_h",), f"events must be in increasing time; previous event at "
                  f"{prev_at:g} h", at)
        elif prev_end is not None and at < prev_end:
            r.add(loc + ("at_h",), f"starts before the previous ramp ends at {prev_end:g} h", at)
        end = at + (ramp or 0.0)
        if dur is not None and end > dur:
            r.add(loc + ("at_h",), f"event ends at {end:g} h, after scene.duration_h = {dur:g}", at)
        prev_at, prev_end = at, end


def _check_history(data, ore_names: list[str], base_dir: Path, r: _Report) -> None:
    feed = data.get("feed")
    if not isinstance(feed, dict):
        return
    hist = feed.get("history")
    if hist is None:
        if feed.get("history_texture") is not None:
            r.add(("feed", "history_texture"), "only used with feed.history")
        return
    if not isinstance(hist, str):
        return
    if feed.get("schedule"):
        r.add(("feed", "schedule"), "give either a schedule or a history, not both")
    path = Path(hist) if Path(hist).is_absolute() else base_dir / hist
    dt = _num(_get(data, "scene", "sample_period_h"))
    if not path.is_file():
        r.add(("feed", "history"), f"file not found (looked for {path})", hist)
        return
    if dt is None or dt <= 0:
        return
    try:
        gap = _num(feed.get("history_max_gap_h", 10 / 60))
        history = read_history_once(path, dt, max_gap_h=gap if gap and gap > 0 else 10 / 60,
                                    feed_nominal_tph=nominal_feed_tph(_get(data, "mill", "preset"), _get(data, "mill")),
                                    feed_p80_um=_feed_p80_um(feed))
    except SceneError as exc:
        for line in str(exc).splitlines():
            r.add(("feed", "history"), line.strip())
        return
    if history.kind == "blend":
        if not ore_names:
            r.add(("ores",), "the history gives ore fractions; define those ores in [ores]")
        for ore in history.ores:
            if ore_names and ore not in ore_names:
                r.add(("feed", "history"), f"column ore_{ore}_frac names an ore not defined in "
                      f"[ores]{did_you_mean(ore, ore_names)}; defined: " + ", ".join(ore_names))
    else:
        has_cols = all(k in history.frame.columns for k in TEXTURE_KEYS)
        if has_cols and feed.get("history_texture") is not None:
            r.add(("feed", "history_texture"), "the history already has texture columns; give "
                  "the texture in one place only")
        if not has_cols and feed.get("history_texture") is None:
            r.add(("feed", "history_texture"), "required: the history gives mineralogy without "
                  "texture columns (" + ", ".join(TEXTURE_KEYS) + ")")
    dur = _num(_get(data, "scene", "duration_h"))
    if dur is not None and history.span_h + dt < dur - 1e-9:
        r.add(("feed", "history"), f"covers {history.span_h:g} h, the scene lasts {dur:g} h "
              "(shorten scene.duration_h)")


def _check_controller(data, r: _Report) -> None:
    ctl = data.get("controller")
    if not isinstance(ctl, dict):
        return
    kind = ctl.get("kind", "none")
    bounds = ctl.get("bounds") if isinstance(ctl.get("bounds"), dict) else {}
    if kind in ("pi", "nmpc"):
        if ctl.get("target_p80_um") is None:
            r.add(("controller", "target_p80_um"), f"required when kind = {kind!r}")
        for key in ("feed_tph_min", "feed_tph_max"):
            if bounds.get(key) is None:
                r.add(("controller", "bounds", key), f"required when kind = {kind!r}")
    fmin, fmax = _num(bounds.get("feed_tph_min")), _num(bounds.get("feed_tph_max"))
    smin, smax = _num(bounds.get("speed_min", 0.60)), _num(bounds.get("speed_max", 0.85))
    if fmin is not None and fmax is not None and fmin >= fmax:
        r.add(("controller", "bounds", "feed_tph_max"), f"must be above feed_tph_min = {fmin:g}",
              fmax)
    if smin is not None and smax is not None and smin >= smax:
        r.add(("controller", "bounds", "speed_max"), f"must be above speed_min = {smin:g}", smax)
    if kind != "none":
        feed, speed = _num(_get(data, "feed", "feed_tph")), _num(_get(data, "feed", "speed_frac_critical"))
        # a closed loop starts at feed_tph only with start = "scene"; the target's feed is checked once known
        starts_at_feed = _get(data, "feed", "start") == "scene"
        if starts_at_feed and feed is not None and fmin is not None and fmax is not None and fmin < fmax \
                and not fmin <= feed <= fmax:
            r.add(("feed", "feed_tph"), f"initial feed outside controller.bounds "
                  f"[{fmin:g}, {fmax:g}]", feed)
        # the speed bounds are the NMPC's: PI holds the scene's speed (and reads no speed bound)
        if kind == "nmpc" and speed is not None and smin is not None and smax is not None and smin < smax \
                and not smin <= speed <= smax:
            r.add(("feed", "speed_frac_critical"), f"initial speed outside controller.bounds "
                  f"[{smin:g}, {smax:g}]", speed)
    hor, block = _num(ctl.get("horizon_steps", 30)), _num(ctl.get("move_block", 5))
    if hor is not None and hor >= 1 and block is not None and block > hor:  # a horizon below 1 is its own error
        r.add(("controller", "move_block"), f"must not exceed horizon_steps = {hor:g}", ctl.get("move_block", 5))
    band = ctl.get("load_band_frac")
    if isinstance(band, list) and len(band) == 2 and all(_num(b) is not None for b in band):
        if not 0 < band[0] < 1 < band[1]:
            r.add(("controller", "load_band_frac"), "must be [low, high] with 0 < low < 1 < high "
                  "(hold-up over nominal hold-up)", band)
    limit = _num(ctl.get("power_max_kw"))
    models = [_get(data, *at, "power", "model") for at in (("effect_options",), ("plant", "effect_options"))]
    problem = power_limit_problem(_get(data, "mill", "preset"), _get(data, "mill"), limit, smin, smax, models) \
        if kind == "nmpc" and limit is not None and limit > 0 and smin is not None and smax is not None else None
    if problem:
        r.add(("controller", "power_max_kw"), problem, limit)
    dur, lead = _num(_get(data, "scene", "duration_h")), _num(ctl.get("preview_lead_h"))
    if dur is not None and lead is not None and lead > dur:
        r.add(("controller", "preview_lead_h"), f"longer than the scene ({dur:g} h)", lead)


def _check_sensors(data, r: _Report) -> None:
    dt = _num(_get(data, "scene", "sample_period_h"))
    p80_dt = _num(_get(data, "sensors", "p80_sample_period_h"))
    if dt is not None and p80_dt is not None and p80_dt < dt - 1e-12:
        r.add(("sensors", "p80_sample_period_h"), f"must be >= scene.sample_period_h = {dt:g}",
              p80_dt)
    dur, dead = _num(_get(data, "scene", "duration_h")), _num(_get(data, "sensors", "p80_dead_time_h"))
    if dur is not None and dead is not None and dead >= dur:
        r.add(("sensors", "p80_dead_time_h"), f"must be shorter than the scene ({dur:g} h)", dead)


def _check_plant(data, r: _Report) -> None:
    plant = data.get("plant")
    if not isinstance(plant, dict):
        return
    if plant.get("model") == "leroux2013":
        # the circuit needs a matched controller twin and its own disturbances (phi_f, rock
        # fraction), which scenes do not describe yet: say so before a run fails on it
        r.add(("plant", "model"), "\"leroux2013\" is not run by scenes yet; the le Roux case "
              "runs from benchmarks/mpc_leroux_case.py (allowed here: \"twin\")", "leroux2013")
        for key in ("effects", "size_classes", "effect_options"):
            if key in plant:
                r.add(("plant", key), "not used with model = \"leroux2013\"; remove it")
    if plant.get("model", "twin") == "twin" and (plant.get("effects") is not None
                                                 or plant.get("effect_options") is not None):
        _check_effect_table(plant.get("effects", data.get("effects")), plant.get("effect_options", {}),
                            ("plant",), r)
    scene_effects, effects = data.get("effects"), plant.get("effects")
    if isinstance(scene_effects, list) and isinstance(effects, list) \
            and ("transport" in scene_effects) != ("transport" in effects):
        continuous = "transport" in scene_effects
        kind = "a continuous mill (effects has `transport`)" if continuous else \
            "a batch grind (effects without `transport`)"
        r.add(("plant", "effects"), f"the scene is {kind}; the plant must be the same kind of mill, "
              f"not a {'batch grind' if continuous else 'continuous mill'}: "
              f"{'add' if continuous else 'remove'} `transport` here", effects)


def _grid_of(table) -> SizeGrid | None:
    """The size grid of a ``size_classes`` table (the schema's defaults for missing keys)."""
    table = table if isinstance(table, dict) else {}
    try:
        return SizeGrid(float(table.get("top_um", 6700.0)), float(table.get("ratio", 2.0 ** 0.5)),
                        int(table.get("count", 25)), str(table.get("scheme", "cell_average")))
    except (TwinError, TypeError, ValueError):
        return None  # the schema pass reports bad sizes


def _mixers_of(mill, plant) -> list | None:
    """The mixers' shares of the hold-up of the controller's model (``plant`` None) or of a
    separate plant, as scenarios.run.models.build_twin gives them to the twin (the mill's shares
    for a twin with their number, else equal ones); None where the table has the wrong types."""
    mill = mill if isinstance(mill, dict) else {}
    fracs = mill.get("mixer_volume_fracs")
    if fracs is not None and not (isinstance(fracs, list) and fracs and all(
            isinstance(f, (int, float)) and not isinstance(f, bool) and f > 0 for f in fracs)):
        return None  # the schema pass reports it
    n = mill.get("n_mixers", len(fracs) if fracs else DEFAULT_N_MIXERS)
    if plant is not None:
        n = plant.get("n_mixers", n)
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        return None
    return list(fracs) if fracs and len(fracs) == n else [1.0 / n] * n


def _check_calibration(data, base_dir: Path, r: _Report) -> None:
    """The calibration exists, and each twin of the scene (the controller's model and a
    separate plant) has its effects and size grid and, on the calibration's own mill, its mixers
    (twin.calibration.Calibration.mismatch), unless ``calibration_mismatch_ok = true``."""
    name = data.get("calibration", DEFAULT_CALIBRATION)
    if not isinstance(name, str):
        return
    spec = str(base_dir / name) if name.endswith(".json") and not Path(name).is_absolute() else name
    try:
        cal = load_calibration(spec)
    except TwinError as exc:
        r.add(("calibration",), str(exc), name)
        return
    if data.get("calibration_mismatch_ok") is True:
        return
    advice = ("the calibration's numbers were fitted with its own; use the calibration's (grindtwin calibrate fits "
              "the twin's default effects, grid and mixers only) or set calibration_mismatch_ok = true if the scene "
              "means it")
    effects = data.get("effects")
    plant = data.get("plant") if isinstance(data.get("plant"), dict) else None
    mill = data.get("mill") if isinstance(data.get("mill"), dict) else {}
    preset = preset_mill(mill.get("preset"))
    mixers_loc = ("mill", "mixer_volume_fracs") if "mixer_volume_fracs" in mill else ("mill", "n_mixers")
    models = [(("effects",), effects, _get(data, "mill", "size_classes"), mixers_loc, _mixers_of(mill, None))]
    if plant is not None and plant.get("model", "twin") == "twin":
        plant_mixers = _mixers_of(mill, plant)  # the mill's are reported at mill.*
        models.append((("plant", "effects"), plant.get("effects", effects),
                       plant.get("size_classes", _get(data, "mill", "size_classes")),
                       ("plant", "n_mixers"), plant_mixers if plant_mixers != models[0][4] else None))
    for loc, eff, sizes, loc_mixers, fracs in models:
        grid = _grid_of(sizes)
        if isinstance(eff, list) and grid is not None:
            for problem in cal.mismatch(eff, grid):
                r.add(loc, f"{problem}: {advice}")
        for problem in cal.mixers_mismatch(preset, fracs):
            r.add(loc_mixers, f"{problem}: {advice}")
    if preset is not None and preset.name == cal.mill and isinstance(mill.get("power_model"), str):
        try:  # the fitted power factor belongs to the power model it was fitted with
            own = get_mill(mill["preset"], cal.record).with_(power_model=mill["power_model"])
        except TwinError:
            return  # an unknown model is the schema's to report
        for problem in cal.mill_values_mismatch(own):
            r.add(("mill", "power_model"), f"{problem}: {advice}")


#: controller keys (paths below ``[controller]``) that a kind reads; an NMPC reads them all. Open loop: the target
#: of the P80 KPIs and of ``feed.start = "target"``, the band of the load KPI (scenarios.run.kpis); PI: those and
#: its feed bounds and rate limit (mpc.closed_loop.pi_baseline); a batch grind: its kind only.
CONTROLLER_KEYS_READ = {
    "batch": {("kind",)},
    "none": {("kind",), ("target_p80_um",), ("load_band_frac",)},
    "pi": {("kind",), ("target_p80_um",), ("load_band_frac",), ("bounds", "feed_tph_min"),
           ("bounds", "feed_tph_max"), ("bounds", "feed_rate_max_tph_per_h")},
}
#: why a kind reads nothing of its other keys, and what to do
_IDLE_WHY = {
    "batch": "a batch grind (effects without `transport`) has no controller and no KPI of a P80 target or a "
             "load band (its P80 is the charge's as it grinds); remove it",
    "none": "controller.kind = \"none\" is an open loop: the scene's feed rate and speed are held and only the "
            "target (the P80 KPIs, feed.start = \"target\") and load_band_frac (the load KPI) are read; remove it, or "
            "set kind = \"pi\" or \"nmpc\"",
    "pi": "controller.kind = \"pi\" moves the feed rate alone from the analyser's P80 (speed held), reading the "
          "target, load_band_frac and bounds feed_tph_min, feed_tph_max and feed_rate_max_tph_per_h only; this is "
          "the NMPC's; remove it, or set kind = \"nmpc\"",
}


def _check_idle_as_written(data, r: _Report) -> None:
    """Keys of a scene file that no number of its own run reads (the file as written: see :func:`cross_check`):
    the ``[controller]`` keys its kind does not read (:data:`CONTROLLER_KEYS_READ`), the controller's model's keys
    that ``[plant]`` overrides where no NMPC runs that model (:func:`_check_idle_control_model`), an open loop's
    power and load noise (no controller reads those readings)."""
    ctl = data.get("controller") if isinstance(data.get("controller"), dict) else {}
    effects = data.get("effects")
    batch = isinstance(effects, list) and "transport" not in effects
    kind = ctl.get("kind", "none")
    reads = "batch" if batch else kind  # a batch scene's kind other than "none": _check_feed
    for key, value in ctl.items() if reads in CONTROLLER_KEYS_READ else ():
        for sub, v in (value.items() if key in ("weights", "bounds") and isinstance(value, dict) else [(None, value)]):
            loc = (key,) if sub is None else (key, sub)
            if loc not in CONTROLLER_KEYS_READ[reads]:
                r.add(("controller",) + loc, f"read by nothing: {_IDLE_WHY[reads]}", v)
    plant = data.get("plant") if isinstance(data.get("plant"), dict) else None
    if kind != "nmpc" and plant is not None and plant.get("model", "twin") == "twin":
        what = {"none": "an open loop (controller.kind = \"none\")", "pi": "controller.kind = \"pi\" (tuned on "
                "the plant's twin)"}.get(kind, "a batch grind") if not batch else "a batch grind"
        _check_idle_control_model(data, plant, what, r)
    sensors = data.get("sensors") if isinstance(data.get("sensors"), dict) else {}
    if kind == "none" and not batch:  # a batch scene's [sensors] is refused whole (_check_feed)
        for key in ("power_noise_kw", "load_noise_frac"):
            if key in sensors:
                r.add(("sensors", key), "read by nothing: an open loop (controller.kind = \"none\") records the "
                      "analyser's P80 (p80_analyser_um) only; the power and load readings are a controller's "
                      "(its estimator's and the loop's power_meas_kw, load_meas_frac); remove it, or set kind = "
                      "\"pi\" or \"nmpc\"", sensors[key])


def _check_idle_control_model(data, plant: dict, what: str, r: _Report) -> None:
    """Keys of the controller's model that ``[plant]`` gives the plant its own of, in a scene whose controller
    (``what``: an open loop, PI or a batch grind) runs no model: only the plant is integrated (PI is tuned on
    the plant's twin), so the mill's grid and mixers and the options of an effect the plant lacks or replaces
    change no number (scenarios.run.models.build_models)."""
    tail = "" if what == "a batch grind" else ", or set controller.kind = \"nmpc\", whose model it is"
    why = (f"read by nothing: {what} runs no model of its own, only [plant]'s twin, which takes its own "
           f"{{own}}; remove it{tail}")
    mill = data.get("mill") if isinstance(data.get("mill"), dict) else {}
    for key in ("size_classes", "n_mixers"):
        if key in mill and plant.get(key) is not None:
            r.add(("mill", key), why.format(own=f"plant.{key}"), mill[key])
    options = data.get("effect_options") if isinstance(data.get("effect_options"), dict) else {}
    effects, own = plant.get("effects"), plant.get("effect_options")
    for name, table in options.items():
        if isinstance(effects, list) and name not in effects:
            r.add(("effect_options", name), why.format(own=f"effects (plant.effects, without {name!r})"), table)
        elif isinstance(own, dict) and name in own:
            r.add(("effect_options", name), why.format(own=f"options (plant.effect_options.{name})"), table)
