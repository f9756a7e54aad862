"""The scene schema: one pydantic model per TOML section, unknown keys refused.

Field-level rules (types, ranges, allowed words) live here; rules that relate several
fields (blends sum to 1, ores exist, schedule order, bounds order, effect names) live in
:mod:`scenarios.scene.loader`, which validates a whole file and reports every error at once.
Units are in the field names (``feed_tph``, ``speed_frac_critical`` as 0.70, ``p80_um``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr

from mpc import DISTURBANCE_MODELS, QP_SOLVERS, SOLVERS
from twin import MILLS

#: The twin's default number of mixers in series (twin.Twin's ``n_mixers``).
DEFAULT_N_MIXERS = 3

ORE_TYPES = ("A", "B", "C", "D")
CONTROLLER_KINDS = ("none", "pi", "nmpc")

def mill_preset(name: str) -> dict[str, float | int]:
    """Dimensions of a mill preset of ``twin.MILLS`` and the twin's default number of mixers."""
    mill = MILLS[name]
    return {"diameter_m": mill.diameter_m, "length_m": mill.length_m,
            "ball_filling_frac": mill.ball_filling_frac, "n_mixers": DEFAULT_N_MIXERS}


class Section(BaseModel):
    """Base of every section: unknown keys are errors; values are not coerced (strict), except
    that an integer is accepted where a float is expected."""

    model_config = ConfigDict(extra="forbid", strict=True)


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
    count: int = Field(default=25, ge=3, le=200)


class Mill(Section):
    """``[mill]``: a preset plus optional overrides; after loading every field is set."""

    preset: Literal["lab", "industrial"]
    diameter_m: float | None = Field(default=None, gt=0, lt=20)
    length_m: float | None = Field(default=None, gt=0, lt=30)
    ball_filling_frac: float | None = Field(default=None, gt=0, lt=0.5)
    n_mixers: int | None = Field(default=None, ge=1, le=20)
    size_classes: SizeClasses = Field(default_factory=SizeClasses)


class Texture(Section):
    """``[ores.NAME.texture]``: mean grain size, grain-size uniformity in (0, 1] (1 =
    equigranular), mineral-association entropy in [0, 1] (1 = fully intergrown); as
    ``twin.ore.mineralogy.Texture``."""

    mean_grain_um: float = Field(gt=0, le=1e5)
    uniformity: float = Field(gt=0, le=1)
    association_entropy: float = Field(ge=0, le=1)


class Ore(Section):
    """``[ores.NAME]``: a reference ore ``type`` or an explicit mineralogy (wt%) and texture."""

    type: Literal["A", "B", "C", "D"] | None = None
    mineralogy: dict[str, float] | None = None
    texture: Texture | None = None


class ScheduleEvent(Section):
    """``[[feed.schedule]]``: from ``at_h`` the blend moves to ``blend`` (step or linear ramp)."""

    at_h: float = Field(ge=0)
    blend: dict[str, float]
    kind: Literal["step", "ramp"] = "step"
    ramp_h: float = Field(default=0.0, ge=0)


class Feed(Section):
    """``[feed]``: initial blend and operating point, feed size, then a schedule or a history.

    Feed size: Gates-Gaudin-Schuhmann distribution with ``p80_um`` and ``ggs_modulus`` (as the
    twin's feed). ``blend`` is required unless a ``history`` gives the feed from t = 0.
    ``feed_tph`` is required with the ``transport`` effect (continuous mill); without it the
    scene is a batch grind of ``batch_charge_kg``.

    ``history`` is a recorded file (path relative to the scene file) read by
    :mod:`scenarios.scene.history`; ``history_texture`` is required when it records mineralogy
    without texture columns; ``history_max_gap_h`` is how long a value may be held.

    ``start`` is where a continuous run starts: ``"scene"`` at the steady state of ``feed_tph``;
    ``"target"`` at the steady state whose feed rate holds ``controller.target_p80_um`` at the
    initial blend and speed, and an open loop then holds that feed rate. Default (``None``):
    ``"target"`` for a closed loop (controller ``pi`` or ``nmpc``), ``"scene"`` for an open loop
    (controller ``none``: a scene runs at its own feed rate unless it says ``start = "target"``).
    """

    blend: dict[str, float] | None = None
    start: Literal["scene", "target"] | None = None
    feed_tph: float | None = Field(default=None, gt=0, le=1e4)
    batch_charge_kg: float | None = Field(default=None, gt=0, le=1e6)
    speed_frac_critical: float = Field(gt=0, lt=1)
    p80_um: float = Field(default=3200.0, gt=0, le=1e6)
    ggs_modulus: float = Field(default=0.8, gt=0, le=5)
    schedule: list[ScheduleEvent] = Field(default_factory=list)
    history: str | None = None
    history_texture: Texture | None = None
    history_max_gap_h: float = Field(default=10 / 60, gt=0)


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
    operating point; ``preview_lead_h`` is how far ahead the feed is known (belt analyser);
    ``disturbance_model`` what the EKF's disturbance states absorb (``mpc.DISTURBANCE_MODELS``).
    """

    kind: Literal["none", "pi", "nmpc"] = "none"
    target_p80_um: float | None = Field(default=None, gt=0)
    horizon_steps: int = Field(default=30, ge=1, le=10_000)
    move_block: int = Field(default=5, ge=1)
    rk4_substeps: int = Field(default=3, ge=1, le=100)  # RK4 steps per sample in the prediction
    preview_lead_h: float = Field(default=0.0, ge=0)
    weights: Weights = Field(default_factory=Weights)
    bounds: Bounds = Field(default_factory=Bounds)
    solver: Literal[SOLVERS] = "ipopt"
    qpsol: Literal[QP_SOLVERS] | None = None  # QP solver of rti / sqpmethod
    load_band_frac: list[float] = Field(default_factory=lambda: [0.8, 1.2], min_length=2,
                                        max_length=2)
    power_max_kw: float | None = Field(default=None, gt=0)
    # what the NMPC's estimator reads the plant/model mismatch as (mpc.estimator)
    disturbance_model: Literal[DISTURBANCE_MODELS] = "hardness"


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
    n_mixers: int | None = Field(default=None, ge=1, le=20)
    effect_options: dict[str, dict[str, Any]] | None = None


class Scene(Section):
    """A validated scene. Build it with :func:`scenarios.scene.loader.load_scene`.

    ``effect_options`` maps an effect of ``effects`` to its options (option names are checked
    against those the twin's effect declares; values are passed to the twin as written).
    ``source_path`` is the file it came from (``None`` if built from a dict); relative paths
    in the scene (``feed.history``) are resolved against its folder.
    """

    scene: SceneInfo
    mill: Mill
    ores: dict[str, Ore] = Field(default_factory=dict)
    feed: Feed
    effects: list[str]
    effect_options: dict[str, dict[str, Any]] = Field(default_factory=dict)
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

    def time_grid_h(self) -> np.ndarray:
        """Sample times 0, dt, ..., duration (inclusive)."""
        n = int(round(self.scene.duration_h / self.scene.sample_period_h))
        return np.arange(n + 1) * self.scene.sample_period_h
