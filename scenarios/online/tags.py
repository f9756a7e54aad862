"""The tag map: which OPC UA node holds each measurement, setpoint and status of a served scene.

A TOML file validated as a whole like a scene (every problem at once, each as ``FILE: key.path:
what is wrong and what is allowed (got VALUE)``), then checked against the scene it serves (the
belt analyser names the scene's ores, a P80 freeze limit longer than the analyser's period, no
node in two roles, a measurement's plausible range within its physical one), then completed
visibly from the scene (the returned :class:`TagMap` shows every default it took; a range left
unset is the physical one, :func:`plausible_range`). Times are plant hours (a speed-up divides
them in wall-clock time).

Node ids are OPC UA's string form: ``ns=2;s=Mill.P80_um`` (namespace index, then ``i=`` numeric,
``s=`` string, ``g=`` GUID or ``b=`` opaque id) or ``nsu=URI;s=...`` (namespace by its URI,
resolved on connection). Example: ``scenarios/online/data/virtual_plant_tags.toml``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from scenarios.errors import SceneError
from scenarios.online.quality import PlausibleRange
from scenarios.run.closed_loop import feed_bounds
from scenarios.scene import Scene, pydantic_message, read_toml
from scenarios.scene.physical import POWER_MAX_MODEL_MULTIPLE, physical_limits
from scenarios.scene.ranges import FEED_MAX_NOMINAL_MULTIPLE, P80_MIN_UM

#: A node id in OPC UA's string form (Part 6, 5.3.1.10): namespace, then identifier type and value.
NODE_ID_PATTERN = r"^(ns=\d+|nsu=[^;]+);(i=\d+|s=.+|g=[0-9a-fA-F-]{36}|b=.+)$"
NodeId = Annotated[str, Field(pattern=NODE_ID_PATTERN)]

#: A reading older than this many sample periods (the slower of the loop's and, for P80, the
#: analyser's) is stale: one period is the normal age of a held value, three leave room for a
#: late scan without taking a dead source for a live one.
STALE_AFTER_SAMPLES = 3
#: Default of ``fallback.inputs_hold_after_h`` in samples: without the actual feed and speed the
#: estimator and the rate limits use the last written setpoints; two samples of that is a hiccup,
#: longer and the setpoints are held.
INPUTS_HOLD_AFTER_SAMPLES = 2

#: A belt analyser's ore fraction is >= 0, and at most 1 + ``sum_tolerance``: a larger one cannot
#: sum to 1 with the other ores' within the tolerance.
BLEND_FRAC_MIN = 0.0
#: Why each measurement's physical range is what it is (in the tag map's messages).
PHYSICAL_REASONS = {
    "p80_um": f"a size of at least {P80_MIN_UM:g} um, as no mill's product is finer (mm? um expected), and "
              "below the top of the coarsest feed class: a mill only breaks",
    "power_kw": f"a motor draws power; a stopped mill reads 0, and it draws at most {POWER_MAX_MODEL_MULTIPLE:g} x "
                "what its power model gives at critical speed",
    "load_frac": "a hold-up; an empty mill reads 0, and above the mill filled to its shell it overflows",
    "feed_tph": f"a stopped belt reads 0; above {FEED_MAX_NOMINAL_MULTIPLE:g} x the mill's nominal feed "
                "(its preset's, scaled by its power) is no operating point of it",
    "speed_frac_critical": "0 is a stopped mill; at 1 the charge centrifuges",
}


log = logging.getLogger("grindtwin.online.tags")


class TagMapError(SceneError):
    """A tag map is invalid; the message names the file, the key path, the value and what is allowed."""


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class Measurement(_Section):
    """A measured value: its node and the rules that make a reading usable."""

    node: NodeId
    max_age_h: float | None = Field(default=None, gt=0)
    """A source timestamp older than this is stale (default: STALE_AFTER_SAMPLES sample periods; at
    most :func:`max_age_limit_h`)."""
    frozen_after_h: float | None = Field(default=None, gt=0)
    """A value unchanged for longer than this is frozen (default: no check)."""
    freeze_tolerance: float = Field(default=0.0, ge=0)
    """Changes up to this size count as unchanged (0: exactly the same value)."""
    uncertain: Literal["reject", "accept"] = "reject"
    """What an Uncertain status code means here: reject the reading, or use it."""
    plausible_min: float | None = Field(default=None, allow_inf_nan=False)
    """A reading below this is Bad (default: the quantity's physical limit, PHYSICAL_REASONS); it
    may narrow the physical range (an instrument's span), never widen it."""
    plausible_max: float | None = Field(default=None, allow_inf_nan=False)
    """A reading above this is Bad (default: the physical limit, as ``plausible_min``)."""


class Measurements(_Section):
    """``[measurements]``: the P80 analyser, mill power and load, the actual feed and speed."""

    p80_um: Measurement
    power_kw: Measurement | None = None
    load_frac: Measurement | None = None
    feed_tph: Measurement
    speed_frac_critical: Measurement


class BeltAnalyser(_Section):
    """``[belt_analyser]``: the fraction of each of the scene's ores on the belt, reported
    ``lead_h`` before it reaches the mill."""

    nodes: dict[str, NodeId] = Field(min_length=1)
    lead_h: float | None = Field(default=None, ge=0)
    max_age_h: float | None = Field(default=None, gt=0)
    frozen_after_h: float | None = Field(default=None, gt=0)
    freeze_tolerance: float = Field(default=0.0, ge=0)
    uncertain: Literal["reject", "accept"] = "reject"
    sum_tolerance: float = Field(default=0.02, gt=0, lt=1)
    """Fractions summing to 1 within this are rescaled to 1; further off the reading is refused."""


class Mode(_Section):
    """``[mode]``: the operator's mode switch; ``auto_value`` means auto, anything else manual."""

    node: NodeId
    auto_value: str | int = "auto"


class Setpoint(_Section):
    """A setpoint the service writes, with the limits enforced again at the writer (defaults:
    the scene's controller bounds and rate limits)."""

    node: NodeId
    min: float | None = None
    max: float | None = None
    rate_max_per_h: float | None = Field(default=None, gt=0)


class Setpoints(_Section):
    """``[setpoints]``: feed rate and mill speed."""

    feed_tph: Setpoint
    speed_frac_critical: Setpoint


class Node(_Section):
    node: NodeId


class SoftSensor(_Section):
    """``[soft_sensor]``: where the predicted P80 and specific energy of the incoming ore are
    published: the twin's steady state and, for the surrogate's mill, the PLS surrogate."""

    p80_um: NodeId | None = None
    specific_energy_kwh_t: NodeId | None = None
    surrogate_p80_um: NodeId | None = None
    surrogate_specific_energy_kwh_t: NodeId | None = None


class Fallback(_Section):
    """``[fallback]``: how long the controller runs on its model before it holds the setpoints."""

    p80_hold_after_h: float | None = Field(default=None, gt=0)
    """P80 unusable this long: hold the setpoints (default: the NMPC's horizon)."""
    inputs_hold_after_h: float | None = Field(default=None, gt=0)
    """Actual feed or speed unusable this long: hold (default: INPUTS_HOLD_AFTER_SAMPLES samples)."""


class Connection(_Section):
    """``[connection]``: request time-out and reconnection back-off (wall-clock seconds)."""

    request_timeout_s: float = Field(default=2.0, gt=0, le=60)
    reconnect_initial_s: float = Field(default=0.5, gt=0, le=60)
    reconnect_max_s: float = Field(default=30.0, gt=0, le=3600)


class Cycle(_Section):
    """``[cycle]``: what starts the service's cycle. ``on_new`` names a measurement whose new
    value starts it (a subscription to its node), so that the cycle follows the plant's sample
    at once, as an APC that executes on a new analyser report; when no new value has come
    ``timeout_samples`` sample periods after the last cycle, or without ``on_new``, the
    service's own timer starts it, every sample period."""

    on_new: Literal["p80_um", "power_kw", "load_frac", "feed_tph", "speed_frac_critical"] | None = None
    timeout_samples: float = Field(default=1.5, gt=1, le=10)


class TagMap(_Section):
    """A validated, completed tag map (see the module docstring)."""

    measurements: Measurements
    belt_analyser: BeltAnalyser | None = None
    mode: Mode
    setpoints: Setpoints
    heartbeat: Node
    status: Node | None = None
    soft_sensor: SoftSensor | None = None
    fallback: Fallback = Field(default_factory=Fallback)
    connection: Connection = Field(default_factory=Connection)
    cycle: Cycle = Field(default_factory=Cycle)

    def read_roles(self) -> dict[str, str]:
        """Role -> node id of everything read each cycle (belt ores as ``blend.<ore>``)."""
        roles = {name: m.node for name, m in self.measurements if m is not None}
        if self.belt_analyser is not None:
            roles |= {f"blend.{ore}": node for ore, node in self.belt_analyser.nodes.items()}
        return roles | {"mode": self.mode.node}

    def write_roles(self) -> dict[str, str]:
        """Role -> node id of everything the service may write."""
        roles = {f"setpoints.{name}": sp.node for name, sp in self.setpoints}
        roles["heartbeat"] = self.heartbeat.node
        if self.status is not None:
            roles["status"] = self.status.node
        if self.soft_sensor is not None:
            roles |= {f"soft_sensor.{k}": v for k, v in self.soft_sensor if v is not None}
        return roles


def load_tags(path: str | Path, scene: Scene) -> TagMap:
    """Read, validate, check against ``scene`` and complete a tag map; TagMapError listing
    every problem, before anything connects."""
    path = Path(path)
    data = read_toml(path, what="tag map")
    try:
        tags = TagMap.model_validate(data)
    except ValidationError as exc:
        raise TagMapError(_summary(path, [pydantic_message(str(path), e, TagMap) for e in exc.errors()])) from None
    problems = [f"{path}: {m}" for m in scene_problems(tags, scene)]
    if problems:
        raise TagMapError(_summary(path, problems))
    for note in scene_notes(tags, scene):
        log.warning("%s: %s", path, note)
    return complete(tags, scene)


def scene_notes(tags: TagMap, scene: Scene) -> list[str]:
    """What in a valid tag map makes the served loop differ from the scene's own runs: a belt analyser's lead
    other than the scene's preview (30, minutes given as hours, had the service take the belt's first reading as
    the mill's feed for 30 h, unsaid)."""
    ba, lead = tags.belt_analyser, scene.controller.preview_lead_h
    if ba is None or ba.lead_h is None or math.isclose(ba.lead_h, lead, rel_tol=1e-9, abs_tol=1e-12):
        return []
    return [f"belt_analyser.lead_h {ba.lead_h:g} h differs from the scene's controller.preview_lead_h {lead:g} h: the "
            f"service takes the belt reading of {ba.lead_h:g} h before as the mill's feed now (the first reading "
            f"until one is that old), where the scene's own runs preview the feed {lead:g} h ahead"]


def _summary(path: Path, errors: list[str]) -> str:
    errors = list(dict.fromkeys(errors))
    return f"{path}: {len(errors)} problem{'s' if len(errors) > 1 else ''} in the tag map\n  " + "\n  ".join(errors)


def scene_problems(tags: TagMap, scene: Scene) -> list[str]:
    """What in a schema-valid tag map does not fit the scene it serves."""
    out = []
    ores = sorted(scene.ores)
    if tags.belt_analyser is not None and sorted(tags.belt_analyser.nodes) != ores:
        out.append(f"belt_analyser.nodes: must name exactly the scene's ores {ores} "
                   f"(got {sorted(tags.belt_analyser.nodes)})")
    p80 = tags.measurements.p80_um
    period = scene.sensors.p80_sample_period_h or scene.scene.sample_period_h
    if p80.frozen_after_h is not None and p80.frozen_after_h <= period:
        out.append(f"measurements.p80_um.frozen_after_h: must be longer than the analyser's sample period "
                   f"{period:g} h, or every held reading counts as frozen (got {p80.frozen_after_h!r})")
    out += _setpoint_problems(tags, scene)
    out += _range_problems(tags, scene)
    out += _max_age_problems(tags, scene)
    seen: dict[str, str] = {}
    for role, node in (tags.read_roles() | {k: v for k, v in tags.write_roles().items()}).items():
        if node in seen:
            out.append(f"{_role_path(role)}: node {node!r} is already the node of {_role_path(seen[node])}; "
                       "each role needs a node of its own")
        seen.setdefault(node, role)
    on_new = tags.cycle.on_new
    if on_new is not None and getattr(tags.measurements, on_new) is None:
        out.append(f"cycle.on_new: names a measurement the map reads; [measurements.{on_new}] has no node "
                   f"(got {on_new!r})")
    if scene.controller.kind != "nmpc":
        out.append(f"(scene) controller.kind: grindtwin serve runs the scene's NMPC; must be 'nmpc' "
                   f"(got {scene.controller.kind!r})")
    return out


def physical_range(name: str, scene: Scene) -> PlausibleRange:
    """The physically possible values of the measurement ``name`` of :class:`Measurements` on
    the scene's mill (:func:`scenarios.scene.physical.physical_limits`, the reasons in PHYSICAL_REASONS)."""
    if name not in PHYSICAL_REASONS:
        raise KeyError(f"no physical range for measurement {name!r}; known: {', '.join(PHYSICAL_REASONS)}")
    return PlausibleRange(*physical_limits(name, scene))


def setpoint_range(name: str, scene: Scene) -> PlausibleRange:
    """What the service may find in the node of setpoint ``name`` of :class:`Setpoints` on connecting, in the
    service's units: the quantity's physical range (:func:`physical_range`) with 0 included, a stopped belt's or
    mill's setpoint."""
    return replace(physical_range(name, scene), low_open=False)


def plausible_range(name: str, m: Measurement, scene: Scene) -> PlausibleRange:
    """The range a reading of measurement ``name`` must lie in: the physical one, narrowed by the
    map's ``plausible_min`` / ``plausible_max`` (included ends)."""
    r = physical_range(name, scene)
    if m.plausible_min is not None:
        r = replace(r, low=m.plausible_min, low_open=False)
    if m.plausible_max is not None:
        r = replace(r, high=m.plausible_max, high_open=False)
    return r


def blend_range(ba: BeltAnalyser) -> PlausibleRange:
    """The range of a belt analyser's ore fraction (BLEND_FRAC_MIN)."""
    return PlausibleRange(BLEND_FRAC_MIN, 1.0 + ba.sum_tolerance, unit="of the belt")


def _range_problems(tags: TagMap, scene: Scene) -> list[str]:
    """A measurement's plausible_min / plausible_max outside its physical range, or not in order."""
    out = []
    for name, m in tags.measurements:
        if m is None:
            continue
        physical = physical_range(name, scene)
        for key in ("plausible_min", "plausible_max"):
            value = getattr(m, key)
            if value is not None and value not in physical:
                out.append(f"measurements.{name}.{key}: must lie in the physical range {physical} "
                           f"({PHYSICAL_REASONS[name]}); it may narrow it, not widen it (got {value!r})")
        if m.plausible_min is not None and m.plausible_max is not None and not m.plausible_min < m.plausible_max:
            out.append(f"measurements.{name}: plausible_min must be below plausible_max (got min "
                       f"{m.plausible_min!r}, max {m.plausible_max!r})")
    return out


def source_period_h(name: str, scene: Scene) -> float:
    """How often the source of reading ``name`` reports: the P80 analyser every ``p80_sample_period_h``
    (at least a sample), the others (and the belt analyser, ``belt_analyser``) every sample."""
    dt = scene.scene.sample_period_h
    return max(dt, scene.sensors.p80_sample_period_h or dt) if name == "p80_um" else dt


def max_age_limit_h(name: str, scene: Scene) -> float:
    """The longest ``max_age_h`` of reading ``name``: the NMPC's horizon, or STALE_AFTER_SAMPLES of its source's
    periods (the default) if longer. A reading older than the horizon was taken before all that the controller
    plans from it; and a dead source is found, and the fallbacks (``[fallback]``) start counting, only when its
    readings turn stale: without a bound a dead analyser or weightometer passed for a live one."""
    return max(_horizon_h(scene), STALE_AFTER_SAMPLES * source_period_h(name, scene))


def _horizon_h(scene: Scene) -> float:
    """The NMPC's horizon [h]; 0 for another controller (it plans nothing ahead)."""
    return scene.controller.horizon_steps * scene.scene.sample_period_h if scene.controller.kind == "nmpc" else 0.0


def _max_age_problems(tags: TagMap, scene: Scene) -> list[str]:
    """A ``max_age_h`` above :func:`max_age_limit_h`, or not above its source's period (a held reading is up to
    one period old when the next arrives: a shorter max age turned live readings stale between reports, and the
    fallbacks started on a live source)."""
    rules = [(f"measurements.{name}", name, m) for name, m in tags.measurements if m is not None]
    if tags.belt_analyser is not None:
        rules.append(("belt_analyser", "belt_analyser", tags.belt_analyser))
    out = []
    n, dt, horizon_h = scene.controller.horizon_steps, scene.scene.sample_period_h, _horizon_h(scene)
    for key, name, rule in rules:
        limit = max_age_limit_h(name, scene)
        if rule.max_age_h is not None and rule.max_age_h > limit:
            periods = f"{STALE_AFTER_SAMPLES} of its source's {source_period_h(name, scene):g} h periods"
            why = (f"the NMPC's horizon ({n} samples of {dt:g} h)" if horizon_h > 0 and limit == horizon_h else
                   f"{periods}, longer than the NMPC's horizon {horizon_h:g} h" if horizon_h > 0 else
                   f"{periods} ({scene.controller.kind}: no horizon)")
            out.append(f"{key}.max_age_h: must be at most {limit:g} h, {why}: an older reading was taken before all "
                       "that the controller plans from it, and a dead source is found (and the fallbacks start) only "
                       f"when its readings turn stale (got {rule.max_age_h!r})")
        elif rule.max_age_h is not None and rule.max_age_h <= (period := source_period_h(name, scene)):
            out.append(f"{key}.max_age_h: must be more than its source's period, {period:g} h (it reports that often, "
                       "so a held reading is up to that old when the next arrives: a shorter max age marks live "
                       f"readings stale and starts the fallbacks; the default is {STALE_AFTER_SAMPLES} periods) "
                       f"(got {rule.max_age_h!r})")
    return out


def _setpoint_problems(tags: TagMap, scene: Scene) -> list[str]:
    """Set-point limits the writer would enforce against the controller: each within the quantity's
    range (a speed in (0, 1), a feed >= 0), ``min`` below ``max`` once the scene's defaults fill the
    rest, and containing the scene's controller bounds. A map whose feed max was 10 t/h under bounds
    of 20-45 t/h had the writer put 10 t/h on the plant in one cycle while the controller planned 23.6
    (its model and the plant apart), exit 0; speed limits in percent made it write 60.0."""
    out = []
    b = scene.controller.bounds
    feed_lo, feed_hi = feed_bounds(scene)
    planned = {"feed_tph": (feed_lo, feed_hi, "controller.bounds.feed_tph_min", "controller.bounds.feed_tph_max"),
               "speed_frac_critical": (b.speed_min, b.speed_max, "controller.bounds.speed_min",
                                       "controller.bounds.speed_max")}
    for name, sp in tags.setpoints:
        for key in ("min", "max"):
            v = getattr(sp, key)
            bad = v is not None and (not math.isfinite(v) or v < 0 or (name == "speed_frac_critical" and not 0 < v < 1))
            if bad:
                percent = name == "speed_frac_critical" and 1 <= v <= 100
                hint = " (a fraction of critical, not percent)" if percent else ""
                allowed = "in (0, 1)" if name == "speed_frac_critical" else ">= 0 t/h"
                out.append(f"setpoints.{name}.{key}: must be {allowed}{hint} (got {v!r})")
        lo, hi, lo_key, hi_key = planned[name]
        sp_min = lo if sp.min is None else sp.min
        sp_max = hi if sp.max is None else sp.max
        if not sp_min < sp_max:
            out.append(f"setpoints.{name}: min must be below max once the scene's bounds fill the one not given "
                       f"(min {sp_min!r}, max {sp_max!r})")
        elif sp_min > lo or sp_max < hi:
            out.append(f"setpoints.{name}: limits [{sp_min:g}, {sp_max:g}] must contain the controller's "
                       f"[{lo:g}, {hi:g}] ({lo_key}, {hi_key}): the controller would plan moves the writer cannot "
                       "make, its model and the plant apart; narrow the scene's bounds to the plant's limits")
    return out


def _role_path(role: str) -> str:
    """The tag map's key path of a role of :meth:`TagMap.read_roles` / ``write_roles``."""
    if role.startswith("blend."):
        return f"belt_analyser.nodes.{role[6:]}"
    if role in Measurements.model_fields:
        return f"measurements.{role}.node"
    if role.startswith("setpoints."):
        return f"{role}.node"
    return role if role.startswith("soft_sensor.") else f"{role}.node"


def complete(tags: TagMap, scene: Scene) -> TagMap:
    """The tag map with the scene's defaults filled in (a new object)."""
    t = tags.model_copy(deep=True)
    dt = scene.scene.sample_period_h
    for name, m in t.measurements:
        if m is not None and m.max_age_h is None:
            m.max_age_h = STALE_AFTER_SAMPLES * source_period_h(name, scene)
    if t.belt_analyser is not None:
        if t.belt_analyser.lead_h is None:
            t.belt_analyser.lead_h = scene.controller.preview_lead_h
        if t.belt_analyser.max_age_h is None:
            t.belt_analyser.max_age_h = STALE_AFTER_SAMPLES * source_period_h("belt_analyser", scene)
    b = scene.controller.bounds
    feed_lo, feed_hi = feed_bounds(scene)
    _fill(t.setpoints.feed_tph, feed_lo, feed_hi, b.feed_rate_max_tph_per_h)
    _fill(t.setpoints.speed_frac_critical, b.speed_min, b.speed_max, b.speed_rate_max_per_h)
    if t.fallback.p80_hold_after_h is None:
        t.fallback.p80_hold_after_h = scene.controller.horizon_steps * dt
    if t.fallback.inputs_hold_after_h is None:
        t.fallback.inputs_hold_after_h = INPUTS_HOLD_AFTER_SAMPLES * dt
    return t


def _fill(sp: Setpoint, lo: float, hi: float, rate: float | None) -> None:
    sp.min = lo if sp.min is None else sp.min
    sp.max = hi if sp.max is None else sp.max
    if sp.rate_max_per_h is None:
        sp.rate_max_per_h = rate if rate is not None else math.inf
