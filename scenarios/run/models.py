"""A scene's models: the controller's twin and, where ``[plant]`` differs, the plant's twin,
each built once from the scene's ores, mill, effects and size classes, with the scene's
calibration (refused where a twin's effects, grid or, on the calibration's own mill, mixers differ
from it, unless the scene says ``calibration_mismatch_ok = true``)."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scenarios.errors import RunError, SceneError
from scenarios.scene import Scene
from scenarios.scene.ranges import own_dimensions
from scenarios.run.feed import component_ores
from twin import BreakageParams, SizeGrid, TabulatedPSD, Twin, TwinError, get_mill, power_kw
from twin.calibration import Calibration, load_calibration


@dataclass
class Models:
    """The twins of a run: ``control`` (the controller's model) and ``plant`` (simulated)."""

    control: Any
    plant: Any
    components: list[str]
    notes: list[str] = field(default_factory=list)
    calibration: Calibration | None = None


def is_batch(scene: Scene) -> bool:
    """A batch grind: the scene has no ``transport`` effect."""
    return "transport" not in scene.effects


def scene_calibration(scene: Scene) -> Calibration:
    """The scene's calibration (``calibration``: a shipped name or a file); SceneError if missing."""
    try:
        return load_calibration(scene.calibration_spec())
    except TwinError as exc:
        raise SceneError(f"{scene.source_path or scene.scene.name}: calibration: {exc}") from None


#: Scene [mill] keys passed to the twin's Mill when given (the rest keep the preset's values).
MILL_OVERRIDES = ("diameter_m", "length_m", "ball_filling_frac", "ball_size_mm", "discharge_solids_frac",
                  "power_model", "net_power_kw")


def scene_mill(scene: Scene, calibration: Calibration | None = None):
    """The scene's mill: its preset with the fitted values of the calibration, the scene's
    dimensions and mill keys, and the scene's feed rate as the nominal one. A mill of the scene's own
    dimensions draws Bond's power (factor 1): the preset's fitted power factor is its own (the lab
    mill's 0.755 applied to a 5.5 m mill). A given net power is the power at the scene's speed, where
    the plant measured it (it was taken at the preset's 0.70 and scaled to the scene's 0.75 by the
    power model: 4770 kW for a measured 4500). Breakage parameters a scene gives are likewise its mill's
    at the scene's speed (with the ``speed`` effect, a user's Austin rates were taken at the preset's
    0.70 and ran 5.5 % faster at the scene's own 0.75)."""
    m = scene.mill
    cal = calibration or scene_calibration(scene)
    given = {k: getattr(m, k) for k in MILL_OVERRIDES if getattr(m, k) is not None}
    if scene.feed.feed_tph is not None:
        given["feed_nominal_tph"] = scene.feed.feed_tph
    base = get_mill(scene.mill_spec(), cal.record)
    if own_dimensions(m, base):
        given["power_factor"] = 1.0
    if m.net_power_kw is not None or any(o.breakage is not None for o in scene.ores.values()):
        given["speed_nominal_frac_critical"] = scene.feed.speed_frac_critical
    return base.with_(**given)



def scene_feed_psd(scene: Scene):
    """The scene's feed size distribution: its screen analysis (table or CSV), or None (GGS)."""
    f = scene.feed
    if f.psd is not None:
        return TabulatedPSD.from_sieves(f.psd.sizes_um, f.psd.passing_pct)
    if f.psd_csv is not None:
        return read_psd_csv_once(scene.resolve_path(f.psd_csv))[0]
    return None


def feed_psd_file(scene: Scene) -> dict | None:
    """The screen analysis (``feed.psd_csv``) the scene's twins are fed, as summary.json records it: ``{"path",
    "sha256"}`` of the bytes read (as a history file's), or None without one."""
    if scene.feed.psd_csv is None:
        return None
    path = scene.resolve_path(scene.feed.psd_csv)
    return {"path": str(Path(path).resolve()), "sha256": read_psd_csv_once(path)[1]}


def read_psd_csv_once(path) -> tuple[TabulatedPSD, str]:
    """:meth:`TabulatedPSD.read_csv`, read again only when the file has changed (its modification time or size),
    as a history is (:func:`scenarios.scene.history.read_history_once`): the run's twins and its record of the
    file are of one reading."""
    stat = Path(path).stat()
    return _read_psd_cached(str(path), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=8)
def _read_psd_cached(path: str, _mtime_ns: int, _size: int) -> tuple[TabulatedPSD, str]:
    return TabulatedPSD.read_csv(path)


def scene_breakage(scene: Scene, ores: dict, mill) -> tuple[dict, dict]:
    """Breakage parameters the scene gives per ore, and the solids densities [t/m3] it gives per ore (each ore
    is held and cut at its own: one density for all, the initial blend's, held a later feed of another ore at
    the first one's)."""
    densities = {name: scene.ores[name].density_t_m3 for name in ores
                 if name in scene.ores and scene.ores[name].density_t_m3}
    # Austin's A becomes S^E at the hold-up the ore fills the mill with at its nominal point (the twin holds each
    # ore at its own density), so that the twin's rate there is A: at the feed blend's density one ore of two ran
    # at 0.87 A, at the listed ores' 1.12 A
    out = {}
    for name, ore in scene.ores.items():
        b = ore.breakage
        if b is None or name not in ores:
            continue
        if b.form == "energy_specific":
            # S^E per net kWh, the twin's basis (S = S^E P / H): a coefficient stated per kWh of a share of it
            share = 1.0 if b.selection_power_frac is None else b.selection_power_frac
            out[name] = BreakageParams.energy_specific(b.alpha0_t_kwh * share, b.alpha1, b.alpha2, b.critical_size_um,
                                                       b.beta0, b.beta1, b.beta2, source=f"scene ores.{name}.breakage")
        else:
            out[name] = BreakageParams.austin_rate(
                b.a_per_min, b.alpha, b.mu_um, b.Lambda, gamma=b.beta1, beta=b.beta2, phi=b.beta0,
                power_kw=power_kw(mill, mill.speed_nominal_frac_critical),
                holdup_t=mill.nominal_holdup_t(densities.get(name, ores[name].density_t_m3)),
                source=f"scene ores.{name}.breakage")
    return out, densities


def build_twin(scene: Scene, ores: dict, effects, effect_options, size_classes, n_mixers=None,
                calibration: Calibration | None = None):
    """A twin of the scene's mill and feed with the given effects, grid and mixers; SceneError if
    the twin refuses it, or if its effects, grid or mixers differ from the calibration's (the
    twin's ``calibration_mismatch``, twin.calibration.Calibration.mismatch: mixers on the
    calibration's own mill only) and the scene does not say ``calibration_mismatch_ok = true``."""
    cal = calibration or scene_calibration(scene)
    src = scene.source_path or scene.scene.name
    grid = SizeGrid(size_classes.top_um, size_classes.ratio, size_classes.count, size_classes.scheme)
    try:
        mill = scene_mill(scene, cal)
        breakage, densities = scene_breakage(scene, ores, mill)
        fracs = scene.mill.mixer_volume_fracs  # the mill's shares, for any twin with its number of mixers
        if fracs is not None and n_mixers is not None and int(n_mixers) != len(fracs):
            fracs = None
        twin = Twin(list(ores.values()), mill=mill, effects=list(effects),
                    effect_options=dict(effect_options or {}), grid=grid,
                    n_mixers=int(n_mixers or scene.mill.n_mixers), feed_p80_um=scene.feed.p80_um,
                    feed_modulus=scene.feed.ggs_modulus, feed_psd=scene_feed_psd(scene),
                    ore_breakage=breakage, solids_density_t_m3=densities or None, mixer_volume_fracs=fracs,
                    calibration=cal)
    except TwinError as exc:
        raise SceneError(f"{src}: the twin refused the scene: {exc}") from None
    if twin.calibration_mismatch and not scene.calibration_mismatch_ok:
        raise SceneError(f"{src}: " + "; ".join(twin.calibration_mismatch) + " (set calibration_mismatch_ok = true "
                         "if the scene means it)")
    return twin


#: A surveyed cyclone feed implying a circulating load (at the scene's feed) this far from the twin's
#: nominal one, relatively, is noted: the nominal sets the mill's through-flow and so its load, the
#: load the NMPC's band constrains (the load went from 1.25 to 0.60 for a nominal of 1 to 8, at the
#: same P80), and nothing said the survey implied another.
SURVEY_LOAD_NOTE_REL = 0.25


def survey_load_note(scene: Scene, feed_nominal_tph: float) -> str:
    """A note when the scene's cyclone survey implies a circulating load (its feed solids over the mill's
    nominal feed, less 1: the underflow over the fresh feed in a direct or a reverse circuit) other
    than ``effect_options.classification.circulating_load_nominal`` (its default if not given), else ""."""
    from twin import EFFECTS

    opts = scene.effect_options.get("classification") or {}
    survey = (opts.get("cyclone") or {}).get("survey") if opts.get("kind") == "hydrocyclone" else None
    if not isinstance(survey, dict) or not feed_nominal_tph > 0:
        return ""
    implied = float(survey["feed_solids_tph"]) / feed_nominal_tph - 1.0
    key = "circulating_load_nominal"
    nominal = float(opts.get(key, EFFECTS["classification"].options[key].default))
    if not implied > 0 or abs(implied / nominal - 1.0) <= SURVEY_LOAD_NOTE_REL:
        return ""
    return (f"the cyclone survey's feed ({float(survey['feed_solids_tph']):.4g} t/h of solids) implies a circulating "
            f"load of {implied:.3g} at the mill's nominal feed {feed_nominal_tph:.4g} t/h; the twin's nominal is "
            f"{nominal:g} (effect_options.classification.{key}{'' if key in opts else ', its default'}), which sets "
            "the mill's nominal through-flow and so its load (the load the controller's band constrains): give "
            f"{key} = {implied:.3g} if the survey was taken at that feed")


def build_models(scene: Scene) -> Models:
    """The controller's twin and, if ``[plant]`` differs, the plant's twin (built once)."""
    ores = component_ores(scene)
    cal = scene_calibration(scene)
    control = build_twin(scene, ores, scene.effects, scene.effect_options, scene.mill.size_classes, calibration=cal)
    notes = [f"calibration {cal.label()}"]
    # what the scene runs unlike its calibration (the twin's own words: one text, not a copy)
    notes += [f"calibration_mismatch_ok: {problem}" for problem in control.calibration_mismatch]
    if not scene.ores:
        notes.append("no [ores]: components are the reference types " + ", ".join(ores))
    plant = control
    p = scene.plant
    if p is not None:
        if p.model != "twin":
            raise RunError(f"plant model {p.model!r} is not supported by the runner yet; use "
                           "plant.model = 'twin'")
        effects = p.effects if p.effects is not None else scene.effects
        if ("transport" in effects) != ("transport" in scene.effects):
            raise SceneError(f"{scene.source_path or scene.scene.name}: plant.effects: the plant must be "
                             "the same kind of mill as the scene (continuous with `transport`, or a "
                             f"batch grind without); got {list(effects)}")
        # the scene's options apply to the plant's effects that have them, each effect's table replaced by
        # the plant's own where it gives one: a plant table of one effect dropped every other (the
        # cyclone circuit of a scene whose plant only named its power model)
        options = {k: v for k, v in scene.effect_options.items() if k in effects} | (p.effect_options or {})
        sizes = p.size_classes if p.size_classes is not None else scene.mill.size_classes
        mixers = p.n_mixers if p.n_mixers is not None else scene.mill.n_mixers
        if (list(effects), dict(options), sizes, mixers) != (
                list(scene.effects), dict(scene.effect_options), scene.mill.size_classes, scene.mill.n_mixers):
            plant = build_twin(scene, ores, effects, options, sizes, mixers, calibration=cal)
            notes.append("the plant is a separate twin (effects " + ", ".join(effects) + ")")
            notes += [f"calibration_mismatch_ok: the plant's {problem}" for problem in plant.calibration_mismatch]
            fracs = scene.mill.mixer_volume_fracs
            if fracs is not None and mixers != len(fracs):
                notes.append(f"the plant's {mixers} mixers have equal shares (mill.mixer_volume_fracs gives "
                             f"{len(fracs)})")
    # what the twins cannot show of the ores; their mismatch notes are the calibration_mismatch_ok ones above
    notes += list(dict.fromkeys(n for t in (control, plant) for n in t.notes if n not in t.mismatch_notes))
    notes += [n for n in (survey_load_note(scene, control.spec.feed_nominal_tph),) if n]
    return Models(control=control, plant=plant, components=list(ores), notes=notes, calibration=cal)
