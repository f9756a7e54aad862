"""The physically possible values of a mill's measurements (the product's P80, the motor's power, the
load, the actual feed and speed): a reading outside is an instrument or scaling fault, never a state of the
plant. ``grindtwin serve`` judges its tags by them (:mod:`scenarios.online.tags`) and the exported controller
its measurements (:func:`scenarios.run.export_scene_controller`)."""

from __future__ import annotations

import math

from scenarios.scene.ranges import FEED_MAX_NOMINAL_MULTIPLE, P80_MIN_UM, nominal_feed_tph

# Physical limits of the measurements: a reading outside is Bad (an instrument or scaling fault,
# never a state of the plant) and is not used; a tag map may narrow a range, never widen it.
# The P80 of the product is a size of at least scenarios.scene.ranges.P80_MIN_UM (no mill's product is
# finer; 0 is what a dead analyser sends, and a P80 in mm, 0.21, lands below: it was taken as Good and drove
# the feed to its bound), and a mill only breaks, so it lies below the top of the coarsest feed class
# (:func:`p80_max_um`).
#: The mill's motor draws power: below 0 is a sign or scaling fault (a stopped mill reads 0); above
#: POWER_MAX_MODEL_MULTIPLE times the most the mill's power model draws (at critical speed, clay-free
#: slurry: :func:`power_max_kw`) it is one too. The multiple allows the drive's losses in a gross
#: reading (gross over net 1.11 in the Moly-Cop BallSim base case: 4316 over 3885 kW) and the power
#: model's own error, and still catches a reading in W, or a digit too many.
POWER_MIN_KW = 0.0
POWER_MAX_MODEL_MULTIPLE = 2.0
#: The load is a hold-up (over nominal): an empty mill reads 0, never less; its upper limit is the
#: mill filled to its shell around its balls (:meth:`twin.Mill.max_holdup_t` over the nominal hold-up,
#: :func:`load_max_frac`): a mill holding more overflows.
LOAD_MIN_FRAC = 0.0
#: The actual feed is a weightometer's rate: a stopped belt reads 0, never less; above
#: FEED_MAX_NOMINAL_MULTIPLE times the mill's nominal feed it is no operating point of the mill
#: (the limit of recorded feeds, :mod:`scenarios.scene.ranges`).
FEED_MIN_TPH = 0.0
#: Mill speed as a fraction of critical, both ends excluded: 0 is a stopped mill, and at 1 the
#: charge centrifuges and grinds nothing (scenes and recorded histories are held to it too).
SPEED_RANGE_FRAC_CRITICAL = (0.0, 1.0)


def p80_max_um(scene) -> float:
    """The top of the coarsest feed class (``mill.size_classes.top_um``, the plant's if coarser):
    no product particle of the mill, so no P80, is coarser."""
    tops = [scene.mill.size_classes.top_um]
    if scene.plant is not None and scene.plant.size_classes is not None:
        tops.append(scene.plant.size_classes.top_um)
    return float(max(tops))


def load_max_frac(scene) -> float:
    """The hold-up of the scene's mill filled to its shell over its nominal hold-up (both scale
    with the ore's density, which cancels)."""
    from scenarios.run.models import scene_mill

    mill = scene_mill(scene)
    return mill.max_holdup_t(1.0) / mill.nominal_holdup_t(1.0)


def power_max_kw(scene) -> float:
    """The most net power the scene's mill draws by its power models (the mill's and any the scene's
    or its plant's power effect names): at critical speed, where both models are largest (Bond's
    grows with speed below it, Hogg & Fuerstenau's is linear in it), in a clay-free slurry (the
    rheology's factor is at most 1: clay only thickens it)."""
    from scenarios.run.models import scene_mill
    from twin import power_kw

    mill = scene_mill(scene)
    tables = [scene.effect_options, getattr(scene.plant, "effect_options", None)]
    models = {mill.power_model} | {t["power"]["model"] for t in tables
                                   if isinstance((t or {}).get("power"), dict) and t["power"].get("model")}
    return max(float(power_kw(mill.with_(power_model=m), 1.0)) for m in models)


def physical_limits(name: str, scene) -> tuple[float, float, bool, bool, str]:
    """``(low, high, low_open, high_open, unit)``: the physically possible values of the measurement ``name``
    (p80_um, power_kw, load_frac, feed_tph or speed_frac_critical) on the scene's mill (the constants above)."""
    if name == "p80_um":
        return P80_MIN_UM, p80_max_um(scene), False, True, "um"
    if name == "power_kw":
        return POWER_MIN_KW, POWER_MAX_MODEL_MULTIPLE * power_max_kw(scene), False, False, "kW"
    if name == "load_frac":
        return LOAD_MIN_FRAC, load_max_frac(scene), False, False, "of the nominal hold-up"
    if name == "feed_tph":  # the mill's nominal feed, as scenes and recorded histories are judged
        nominal = nominal_feed_tph(scene.mill_spec(), scene.mill.model_dump())
        return FEED_MIN_TPH, math.inf if nominal is None else FEED_MAX_NOMINAL_MULTIPLE * nominal, False, False, "t/h"
    if name == "speed_frac_critical":
        return *SPEED_RANGE_FRAC_CRITICAL, True, True, "of critical"
    raise KeyError(f"no physical limits for measurement {name!r}")
