"""A scene's models: the controller's twin and, where ``[plant]`` differs, the plant's twin,
each built once from the scene's ores, mill, effects and size classes."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from scenarios.errors import RunError, SceneError
from scenarios.scene import Scene, ore_mineralogies
from twin import Mineralogy, SizeGrid, Twin, TwinError, get_mill, reference_ores
from twin.calibration import shipped_calibration


@dataclass
class Models:
    """The twins of a run: ``control`` (the controller's model) and ``plant`` (simulated)."""

    control: Any
    plant: Any
    components: list[str]
    notes: list[str] = field(default_factory=list)


def is_batch(scene: Scene) -> bool:
    """A batch grind: the scene has no ``transport`` effect."""
    return "transport" not in scene.effects


def component_ores(scene: Scene) -> dict:
    """Component name -> twin Mineralogy: the scene's ores, or the reference types A-D for a
    mineralogy history in a scene without ores."""
    if scene.ores:
        return ore_mineralogies(scene)
    return {name: Mineralogy(dict(o.wt_pct), o.texture, name=name)
            for name, o in sorted(reference_ores().items())}


def scene_mill(scene: Scene):
    """The scene's mill: its preset with the fitted values of the calibration, and the scene's
    dimensions."""
    m = scene.mill
    return get_mill(m.preset, shipped_calibration()).with_(
        diameter_m=m.diameter_m, length_m=m.length_m, ball_filling_frac=m.ball_filling_frac)


def build_twin(scene: Scene, ores: dict, effects, effect_options, size_classes, n_mixers=None):
    """A twin of the scene's mill and feed with the given effects and grid; SceneError if the
    twin refuses it."""
    try:
        return Twin(list(ores.values()), mill=scene_mill(scene), effects=list(effects),
                    effect_options=dict(effect_options or {}),
                    grid=SizeGrid(size_classes.top_um, size_classes.ratio, size_classes.count),
                    n_mixers=int(n_mixers or scene.mill.n_mixers), feed_p80_um=scene.feed.p80_um,
                    feed_modulus=scene.feed.ggs_modulus)
    except TwinError as exc:
        src = scene.source_path or scene.scene.name
        raise SceneError(f"{src}: the twin refused the scene: {exc}") from None


def build_models(scene: Scene) -> Models:
    """The controller's twin and, if ``[plant]`` differs, the plant's twin (built once)."""
    ores = component_ores(scene)
    control = build_twin(scene, ores, scene.effects, scene.effect_options, scene.mill.size_classes)
    notes = []
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
        # the scene's options apply to the plant's effects that have them
        options = p.effect_options if p.effect_options is not None else {
            k: v for k, v in scene.effect_options.items() if k in effects}
        sizes = p.size_classes if p.size_classes is not None else scene.mill.size_classes
        mixers = p.n_mixers if p.n_mixers is not None else scene.mill.n_mixers
        if (list(effects), dict(options), sizes, mixers) != (
                list(scene.effects), dict(scene.effect_options), scene.mill.size_classes, scene.mill.n_mixers):
            plant = build_twin(scene, ores, effects, options, sizes, mixers)
            notes.append("the plant is a separate twin (effects " + ", ".join(effects) + ")")
    return Models(control=control, plant=plant, components=list(ores), notes=notes)
