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
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, model_validator

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
    scheme: Literal["cell_average", "austin"] = "cell_average"  # twin.breakage: 2nd-order default


class Mill(Section):
    """``[mill]``: a preset plus optional overrides; after loading every field is set."""

    preset: Literal["lab", "industrial"]
    diameter_m: float | None = Field(default=None, gt=0, lt=20)
    length_m: float | None = Field(default=None, gt=0, lt=30)
    ball_filling_frac: float | None = Field(default=None, gt=0, lt=0.5)
    n_mixers: int | None = Field(default=None, ge=1, le=20)
    size_classes: SizeClasses = Field(default_factory=SizeClasses)
    # the mixers' shares of the hold-up, e.g. Whiten's one large and two small [0.7, 0.15, 0.15]
    mixer_volume_fracs: list[float] | None = Field(default=None, min_length=1, max_length=20)
    ball_size_mm: float | None = Field(default=None, gt=0, le=200)
    discharge_solids_frac: float | None = Field(default=None, gt=0, lt=1)  # 0.72, not 72
    power_model: Literal["bond", "hogg_fuerstenau"] | None = None
    net_power_kw: float | None = Field(default=None, gt=0, le=1e5)  # given net power at the nominal speed

    @model_validator(mode="after")
    def _mixers_agree(self):
        fracs = self.mixer_volume_fracs
        if fracs is not None:
            if any(not f > 0 for f in fracs):
                raise ValueError(f"mixer_volume_fracs must be positive shares of the hold-up (got {fracs})")
            if self.n_mixers is not None and self.n_mixers != len(fracs):
                raise ValueError(f"n_mixers = {self.n_mixers} but mixer_volume_fracs has {len(fracs)} shares: "
                                 "give one of them, or both agreeing")
        return self


class OreBreakage(Section):
    """``[ores.NAME.breakage]``: the ore's selection and breakage parameters given directly (they
    replace the calibration's mineralogy map for this ore; twin.BreakageParams).

    ``form = "energy_specific"`` (Moly-Cop Tools, Herbst & Fuerstenau): S^E = alpha0_t_kwh
    d^alpha1 / (1 + (d / critical_size_um)^alpha2), d in um. ``form = "austin"``: Austin's rate
    S = a_per_min (d/1 mm)^alpha / (1 + (d/mu_um)^Lambda) [1/min], measured at the scene mill's
    nominal power and hold-up. Breakage B = beta0 (x/y)^beta1 + (1 - beta0)(x/y)^beta2 (Austin's
    phi, gamma, beta) for both."""

    form: Literal["energy_specific", "austin"] = "energy_specific"
    alpha0_t_kwh: float | None = Field(default=None, gt=0, le=1e6)
    alpha1: float | None = Field(default=None, ge=0, le=5)
    alpha2: float | None = Field(default=None, ge=0, le=20)
    critical_size_um: float | None = Field(default=None, gt=0, le=1e7)
    a_per_min: float | None = Field(default=None, gt=0, le=1e6)
    alpha: float | None = Field(default=None, ge=0, le=5)
    mu_um: float | None = Field(default=None, gt=0, le=1e7)
    Lambda: float | None = Field(default=None, ge=0, le=20)
    beta0: float = Field(ge=0, le=1)
    beta1: float = Field(gt=0, le=5)
    beta2: float = Field(gt=0, le=20)

    @model_validator(mode="after")
    def _form_complete(self):
        need = {"energy_specific": ("alpha0_t_kwh", "alpha1", "alpha2", "critical_size_um"),
                "austin": ("a_per_min", "alpha", "mu_um", "Lambda")}
        missing = [k for k in need[self.form] if getattr(self, k) is None]
        extra = [k for f, keys in need.items() if f != self.form for k in keys if getattr(self, k) is not None]
        if missing:
            raise ValueError(f"form = {self.form!r} needs {', '.join(missing)}")
        if extra:
            raise ValueError(f"{', '.join(extra)} belong to the other form, not form = {self.form!r}")
        return self


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
    breakage: OreBreakage | None = None  # given parameters instead of the calibration's map
    density_t_m3: float | None = Field(default=None, gt=1, le=25)  # instead of the minerals' density


class ScheduleEvent(Section):
    """``[[feed.schedule]]``: from ``at_h`` the blend moves to ``blend`` (step or linear ramp)."""

    at_h: float = Field(ge=0)
    blend: dict[str, float]
    kind: Literal["step", "ramp"] = "step"
    ramp_h: float = Field(default=0.0, ge=0)


class FeedPSD(Section):
    """``[feed.psd]``: a screen analysis: sieve sizes [um] and cumulative % passing (94.43, not
    0.9443), any order (twin.sizes.TabulatedPSD)."""

    sizes_um: list[float] = Field(min_length=2)
    passing_pct: list[float] = Field(min_length=2)

    @model_validator(mode="after")
    def _paired(self):
        if len(self.sizes_um) != len(self.passing_pct):
            raise ValueError(f"{len(self.sizes_um)} sizes_um but {len(self.passing_pct)} passing_pct: one each")
        if any(not s > 0 for s in self.sizes_um) or len(set(self.sizes_um)) != len(self.sizes_um):
            raise ValueError("sizes_um must be distinct positive sieve sizes")
        if any(not 0 <= v <= 100 for v in self.passing_pct):
            raise ValueError("passing_pct must be percentages in [0, 100]")
        pairs = sorted(zip(self.sizes_um, self.passing_pct))
        if any(b[1] < a[1] for a, b in zip(pairs, pairs[1:])):
            raise ValueError("passing_pct must not fall as the sieve size rises")
        return self


class Feed(Section):
    """``[feed]``: initial blend and operating point, feed size, then a schedule or a history.

    Feed size: Gates-Gaudin-Schuhmann distribution with ``p80_um`` and ``ggs_modulus`` (as the
    twin's feed), or a screen analysis as ``[feed.psd]`` or ``psd_csv`` (then not ``p80_um``). ``blend`` is required unless a ``history`` gives the feed from t = 0.
    ``feed_tph`` is required with the ``transport`` effect (continuous mill); without it the
    scene is a batch grind of ``batch_charge_kg``.

    ``history`` is a recorded file (path relative to the scene file) read by
    :mod:`scenarios.scene.history`; ``history_texture`` is required when it records mineralogy
    without texture columns; ``history_max_gap_h`` is how long a value may be held.
    """

    blend: dict[str, float] | None = None
    feed_tph: float | None = Field(default=None, gt=0, le=1e4)
    batch_charge_kg: float | None = Field(default=None, gt=0, le=1e6)
    speed_frac_critical: float = Field(gt=0, lt=1)
    p80_um: float = Field(default=3200.0, gt=0, le=1e6)
    ggs_modulus: float = Field(default=0.8, gt=0, le=5)
    psd: FeedPSD | None = None
    psd_csv: str | None = None  # columns size_um, passing_pct; path relative to the scene file
    schedule: list[ScheduleEvent] = Field(default_factory=list)
    history: str | None = None
    history_texture: Texture | None = None
    history_max_gap_h: float = Field(default=10 / 60, gt=0)

    @model_validator(mode="after")
    def _one_size_distribution(self):
        given = [k for k in ("psd", "psd_csv") if getattr(self, k) is not None]
        ggs = [k for k in ("p80_um", "ggs_modulus") if k in self.model_fields_set]
        if len(given) > 1 or (given and ggs):
            raise ValueError("give the feed size once: " + " or ".join(given + ggs) + " (psd, psd_csv, "
                             "or p80_um with ggs_modulus)")
        return self


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
        return self.resolve_path(self.feed.history)

    def resolve_path(self, path: str) -> Path:
        """A path of the scene resolved against the scene file's folder."""
        p = Path(path)
        if not p.is_absolute() and self._source_path is not None:
            p = self._source_path.parent / p
        return p

    def time_grid_h(self) -> np.ndarray:
        """Sample times 0, dt, ..., duration (inclusive)."""
        n = int(round(self.scene.duration_h / self.scene.sample_period_h))
        return np.arange(n + 1) * self.scene.sample_period_h
