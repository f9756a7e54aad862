"""The scene schema: one pydantic model per TOML section, unknown keys refused.

Field-level rules (types, ranges, allowed words) live here; rules that relate several
fields (blends sum to 1, ores exist, schedule order, bounds order, effect names) live in
:mod:`scenarios.loader`, which validates a whole file and reports every error at once.
Units are in the field names (``feed_tph``, ``speed_frac_critical`` as 0.70, ``p80_um``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr

ORE_TYPES = ("A", "B", "C", "D")
CONTROLLER_KINDS = ("none", "pi", "nmpc")
SOLVERS = ("ipopt", "fatrop", "sqpmethod")

#: Mill presets. ``lab`` is the reference laboratory mill of MISSION.md; ``industrial`` is
#: sized for ~30 t/h of Type B by scaling the lab throughput (31 kg/h) with D**2.5 * L.
MILL_PRESETS: dict[str, dict[str, float | int]] = {
    "lab": {"diameter_m": 0.5, "length_m": 0.3, "ball_filling_frac": 0.35, "n_mixers": 1},
    "industrial": {"diameter_m": 2.8, "length_m": 4.0, "ball_filling_frac": 0.30, "n_mixers": 3},
}


class Section(BaseModel):
    """Base of every section: unknown keys are errors, values are not coerced from strings."""

    model_config = ConfigDict(extra="forbid", strict=False, frozen=False)


class SceneInfo(Section):
    """``[scene]``: identity, time axis and seed of the run."""

    name: str = Field(min_length=1)
    description: str = ""
    duration_h: float = Field(gt=0, le=24 * 366)
    sample_period_h: float = Field(default=1 / 60, gt=0, le=24)
    seed: int = Field(default=0, ge=0)


class SizeClasses(Section):
    """``[mill.size_classes]``: geometric series of sieve sizes, coarsest first."""

    top_um: float = Field(default=6700.0, gt=0, le=1e6)
    ratio: float = Field(default=math.sqrt(2), gt=1, le=10)
    count: int = Field(default=24, ge=2, le=200)


class Mill(Section):
    """``[mill]``: a preset plus optional overrides; after loading every field is set."""

    preset: Literal["lab", "industrial"]
    diameter_m: float | None = Field(default=None, gt=0, le=15)
    length_m: float | None = Field(default=None, gt=0, le=30)
    ball_filling_frac: float | None = Field(default=None, gt=0, lt=0.6)
    n_mixers: int | None = Field(default=None, ge=1, le=50)
    size_classes: SizeClasses = Field(default_factory=SizeClasses)


class Texture(Section):
    """``[ores.NAME.texture]``: mean grain size, grain-size uniformity in (0, 1] (1 =
    equigranular), mineral-association entropy in [0, 1] (1 = fully intergrown); as
    ``twin.mineralogy.Texture``."""

    mean_grain_um: float = Field(gt=0, le=1e5)
    uniformity: float = Field(gt=0, le=1)
    association_entropy: float = Field(ge=0, le=1)


class Ore(Section):
    """``[ores.NAME]``: a reference ore ``type`` or an explicit mineralogy (wt%) and texture."""

    type: Literal["A", "B", "C", "D"] | None = None
    mineralogy: dict[str, float] | None = None
    texture: Texture | None = None


class RosinRammler(Section):
    """Feed size as a Rosin-Rammler distribution: 63.2 % passing size and spread."""

    x63_um: float = Field(gt=0, le=1e6)
    spread: float = Field(gt=0, le=20)


class ScheduleEvent(Section):
    """``[[feed.schedule]]``: from ``at_h`` the blend moves to ``blend`` (step or linear ramp)."""

    at_h: float = Field(ge=0)
    blend: dict[str, float]
    kind: Literal["step", "ramp"] = "step"
    ramp_h: float = Field(default=0.0, ge=0)


class Feed(Section):
    """``[feed]``: initial blend and operating point, feed size, then a schedule or a history.

    ``blend`` is required unless a ``history`` gives the feed from t = 0. ``feed_tph`` is
    required with the ``transport`` effect (continuous mill); without it the scene is a batch
    grind of ``batch_charge_kg``.

    ``history`` is a recorded file (path relative to the scene file) read by
    :mod:`scenarios.history`; ``history_texture`` is required when it records mineralogy
    without texture columns; ``history_max_gap_h`` is how long a value may be held.
    """

    blend: dict[str, float] | None = None
    feed_tph: float | None = Field(default=None, gt=0, le=1e4)
    batch_charge_kg: float | None = Field(default=None, gt=0, le=1e6)
    speed_frac_critical: float = Field(gt=0, lt=1)
    p80_um: float | None = Field(default=None, gt=0, le=1e6)
    rosin_rammler: RosinRammler | None = None
    schedule: list[ScheduleEvent] = Field(default_factory=list)
    history: str | None = None
    history_texture: Texture | None = None
    history_max_gap_h: float = Field(default=10 / 60, gt=0)


class TransportOptions(Section):
    """``[effect_options.transport]``."""

    n_mixers: int | None = Field(default=None, ge=1, le=50)


class ClassificationOptions(Section):
    """``[effect_options.classification]``: grate discharge or closed circuit with a cyclone."""

    kind: Literal["grate", "hydrocyclone"] = "grate"
    cut_size_um: float | None = Field(default=None, gt=0)
    sharpness: float | None = Field(default=None, gt=0)


class EffectOptions(Section):
    """``[effect_options]``: one table per effect; only effects listed in ``effects``.

    ``transport`` and ``classification`` are checked key by key; the other effects' tables
    are passed to the twin as given (the twin validates them when it builds the model).
    """

    breakage: dict[str, Any] | None = None
    transport: TransportOptions | None = None
    holdup: dict[str, Any] | None = None
    speed: dict[str, Any] | None = None
    cushioning: dict[str, Any] | None = None
    power: dict[str, Any] | None = None
    classification: ClassificationOptions | None = None
    slowing_down: dict[str, Any] | None = None
    sensor_delay: dict[str, Any] | None = None

    model_config = ConfigDict(extra="allow")  # names are checked against the effect registry

    def given(self) -> dict[str, Any]:
        """The tables actually written in the file, as plain dicts (effect name -> options)."""
        out = {k: (v.model_dump() if isinstance(v, BaseModel) else v)
               for k, v in self if v is not None}
        out.update(self.model_extra or {})
        return out


class Weights(Section):
    """``[controller.weights]``: P80 tracking, move suppression, energy."""

    p80: float = Field(default=1.0, ge=0)
    du_feed: float = Field(default=0.1, ge=0)
    du_speed: float = Field(default=0.1, ge=0)
    energy: float = Field(default=0.0, ge=0)


class Bounds(Section):
    """``[controller.bounds]``: input bounds and rate limits (``None`` = no rate limit)."""

    feed_tph_min: float | None = Field(default=None, ge=0)
    feed_tph_max: float | None = Field(default=None, gt=0)
    speed_min: float = Field(default=0.60, gt=0, lt=1)
    speed_max: float = Field(default=0.85, gt=0, lt=1)
    feed_rate_max_tph_per_h: float | None = Field(default=None, gt=0)
    speed_rate_max_per_h: float | None = Field(default=None, gt=0)


class Controller(Section):
    """``[controller]``: kind, target, horizon and tuning, bounds, solver.

    ``load_band_frac`` is the mill hold-up as a fraction of the nominal hold-up at the initial
    operating point; ``preview_lead_h`` is how far ahead the feed is known (belt analyser).
    """

    kind: Literal["none", "pi", "nmpc"] = "none"
    target_p80_um: float | None = Field(default=None, gt=0)
    horizon_steps: int = Field(default=30, ge=1, le=10_000)
    move_block: int = Field(default=5, ge=1)
    preview_lead_h: float = Field(default=0.0, ge=0)
    weights: Weights = Field(default_factory=Weights)
    bounds: Bounds = Field(default_factory=Bounds)
    solver: Literal["ipopt", "fatrop", "sqpmethod"] = "ipopt"
    load_band_frac: tuple[float, float] = (0.9, 1.1)
    power_max_kw: float | None = Field(default=None, gt=0)


class Sensors(Section):
    """``[sensors]``: noise (one standard deviation), dead time and sampling of the analysers.

    ``p80_sample_period_h = None`` means the scene's sample period.
    """

    p80_noise_um: float = Field(default=0.0, ge=0)
    p80_dead_time_h: float = Field(default=0.0, ge=0)
    p80_sample_period_h: float | None = Field(default=None, gt=0)
    power_noise_kw: float = Field(default=0.0, ge=0)
    load_noise_frac: float = Field(default=0.0, ge=0, lt=1)


class Plant(Section):
    """``[plant]``: the simulated plant when it differs from the controller's model.

    ``model = "twin"`` uses the twin with the effects and size classes given here (missing
    ones are taken from the scene); ``"leroux2013"`` is the literature milling-circuit model.
    """

    model: Literal["twin", "leroux2013"] = "twin"
    effects: list[str] | None = None
    size_classes: SizeClasses | None = None
    effect_options: EffectOptions | None = None


class Scene(Section):
    """A validated scene. Build it with :func:`scenarios.loader.load_scene`.

    ``source_path`` is the file it came from (``None`` if built from a dict); relative paths
    in the scene (``feed.history``) are resolved against its folder.
    """

    scene: SceneInfo
    mill: Mill
    ores: dict[str, Ore] = Field(default_factory=dict)
    feed: Feed
    effects: list[str]
    effect_options: EffectOptions = Field(default_factory=EffectOptions)
    controller: Controller = Field(default_factory=Controller)
    sensors: Sensors = Field(default_factory=Sensors)
    plant: Plant | None = None

    _source_path: Path | None = PrivateAttr(default=None)

    @property
    def source_path(self) -> Path | None:
        """The scene file, or ``None``."""
        return self._source_path

    def history_path(self) -> Path | None:
        """``feed.history`` resolved against the scene file's folder, or ``None``."""
        if self.feed.history is None:
            return None
        p = Path(self.feed.history)
        if not p.is_absolute() and self._source_path is not None:
            p = self._source_path.parent / p
        return p

    def time_grid_h(self):
        """Sample times 0, dt, ..., duration (inclusive), as a numpy array."""
        import numpy as np

        n = int(round(self.scene.duration_h / self.scene.sample_period_h))
        return np.arange(n + 1) * self.scene.sample_period_h

    def blend_at(self, t_h: float) -> dict[str, float]:
        """Blend fractions (ore name -> fraction) at time ``t_h``; see :mod:`scenarios.schedule`."""
        from scenarios.schedule import blend_at

        return blend_at(self, t_h)

    def feed_table(self, times_h=None):
        """Feed composition over time as a DataFrame indexed by ``time_h``."""
        from scenarios.schedule import feed_table

        return feed_table(self, times_h)
