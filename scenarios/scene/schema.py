"""The scene schema: one pydantic model per TOML section, unknown keys refused.

Field-level rules (types, ranges, allowed words) live here; rules that relate several
fields (blends sum to 1, ores exist, schedule order, bounds order, effect names) live in
:mod:`scenarios.scene.loader`, which validates a whole file and reports every error at once.
Units are in the field names (``feed_tph``, ``speed_frac_critical`` as 0.70, ``p80_um``).

Every field carries a docstring (read by pydantic as its description): the scene-file reference
``docs/scenes.md`` is generated from this module by ``python -m scenarios.scene.reference``, so
what a key means is written here and only here.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, field_validator, model_validator

from mpc import DISTURBANCE_MODELS, QP_SOLVERS, SOLVERS
from twin import (BALL_SIZE_MAX_MM, BALL_SIZE_MIN_MM, CRITICAL_SIZE_MIN_UM, MILLS, MIXER_SHARES_SUM_TOL,
                  exponent_order_problem, file_sha256, get_mill, is_preset_file, mixer_shares_sum_ok)
from twin.ore import MEAN_GRAIN_RANGE_UM

from scenarios.scene.keypaths import did_you_mean

#: The twin's default number of mixers in series (twin.Twin's ``n_mixers``).
DEFAULT_N_MIXERS = 3
#: Largest mill inside diameter and length [m] a scene takes: the largest ball mills are ~8.5 m across
#: and ~14 m long (28 x 45 ft); a size in feet (18 ft for 5.5 m, 28 ft for 8.5 m) lands above.
MILL_DIAMETER_MAX_M = 10.0
MILL_LENGTH_MAX_M = 20.0

ORE_TYPES = ("A", "B", "C", "D")
CONTROLLER_KINDS = ("none", "pi", "nmpc")

def mill_preset(spec) -> dict[str, float | int]:
    """Dimensions of a mill preset of ``twin.MILLS`` or of a preset file (the sized ``industrial``
    preset as its file gives it, :func:`twin.get_mill`) and the twin's default number of mixers."""
    mill = get_mill(spec)
    return {"diameter_m": mill.diameter_m, "length_m": mill.length_m,
            "ball_filling_frac": mill.ball_filling_frac, "n_mixers": DEFAULT_N_MIXERS}


class Section(BaseModel):
    """Base of every section: unknown keys are errors; values are not coerced (strict), except
    that an integer is accepted where a float is expected; NaN and infinities are refused
    wherever a number is expected (TOML allows ``nan`` and ``inf``, no quantity here is)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, use_attribute_docstrings=True)


#: The most samples a run may have: the longest run (a year) at 15-s samples, about the fastest a
#: plant historian logs; memory and time grow with the count (the feed schedule alone ~0.2 kB a
#: sample). Above Excel's 1,048,576 rows, so a workbook too long is its own refusal.
MAX_SAMPLES = 24 * 366 * 240


class SceneInfo(Section):
    """``[scene]``: identity, time axis and seed of the run."""

    name: str = Field(min_length=1)
    """Name of the scene: the title of its plots, report and workbook."""
    description: str = ""
    """One line on what the scene shows (printed in the report)."""
    duration_h: float = Field(gt=0, le=24 * 366)
    """Length of the run [h]; the run has one row per sample from 0 to this time, inclusive."""
    sample_period_h: float = Field(default=1 / 60, gt=0, le=24)
    """Sample period [h]: inputs are held over a sample, the controller acts once a sample, and
    the time series has one row per sample (1/60 = one minute)."""
    seed: int = Field(default=0, ge=0)
    """Seed of the sensors' noise (analyser, power and load readings): runs are reproducible."""

    @model_validator(mode="after")
    def _samples(self):
        n = round(self.duration_h / self.sample_period_h)
        if n > MAX_SAMPLES:  # 5e-8 h (seconds written as hours?) took 18 GB before any check
            raise ValueError(f"duration_h = {self.duration_h:g} at sample_period_h = {self.sample_period_h:g} is {n:,} "
                             f"samples; at most {MAX_SAMPLES:,} (a year of 15-s samples): a longer sample "
                             "period or a shorter run")
        return self


class SizeClasses(Section):
    """``[mill.size_classes]``: geometric series of sieve sizes, coarsest first."""

    top_um: float = Field(default=6700.0, gt=0, le=1e6)
    """Upper size of the coarsest class [um]; must lie above ``feed.p80_um``."""
    ratio: float = Field(default=math.sqrt(2), gt=1, le=10, json_schema_extra={"unit": "-"})
    """Ratio of neighbouring sieve sizes (sqrt 2 is the standard sieve series); the
    calibration is fitted at 25 classes of ratio sqrt 2, a coarser grid moves P80
    (benchmarks/results/twin_accuracy.md)."""
    count: int = Field(default=25, ge=3, le=200, json_schema_extra={"unit": "-"})
    """Number of size classes; a sink class below the finest is added by the twin."""
    scheme: Literal["cell_average", "austin"] = "cell_average"
    """Discretisation of breakage on the grid (twin.breakage): ``"cell_average"``, second order in
    the class width; ``"austin"``, the classical first-order discrete form in which a tool's
    parameters are defined on its own sieve series. Parameters of ``form = "austin"`` are rates of
    leaving sqrt(2) intervals (Austin's convention, where they are measured) whatever this grid's
    ratio: on another ratio the twin moves them to particle sizes and evaluates them at its own classes."""


class Mill(Section):
    """``[mill]``: a preset plus optional overrides; after loading every field is set."""

    preset: str = Field(examples=["industrial", "my_mill.json"])
    """The mill: ``"lab"`` is MISSION.md's laboratory mill (0.5 m x 0.3 m, 31 kg/h nominal),
    ``"industrial"`` the mill `grindtwin size-mill` sizes for 31 t/h of Type B at 210 um in closed
    circuit with hydrocyclones (twin/data/industrial_mill.json); or a preset file (ending in .json,
    relative to the scene file) that `grindtwin size-mill --write-preset PATH` wrote: the mill it
    sized, with its hydrocyclones (run when ``classification`` is a hydrocyclone without a
    ``cyclone`` table), on the industrial preset's calibrated values. Calibrated values of the preset
    (power factor, grate, discharge) come from the scene's calibration (its ``calibration``, the
    shipped ``dem`` by default)."""

    @field_validator("preset")
    @classmethod
    def _preset(cls, value: str) -> str:
        if value in MILLS or is_preset_file(value):
            return value
        raise ValueError(f"must be one of {', '.join(repr(m) for m in MILLS)} or a preset file ending in .json "
                         f"(`grindtwin size-mill --write-preset PATH` writes one){did_you_mean(value, MILLS)}")
    diameter_m: float | None = Field(default=None, gt=0, le=MILL_DIAMETER_MAX_M, examples=[3.2])
    """Inside diameter [m]; default: the preset's. A diameter in feet (18 for 5.5 m) lands above the
    range and is refused."""
    length_m: float | None = Field(default=None, gt=0, le=MILL_LENGTH_MAX_M, examples=[4.8])
    """Inside length [m]; default: the preset's."""
    ball_filling_frac: float | None = Field(default=None, gt=0, lt=0.5, examples=[0.35])
    """Ball-bed volume over mill volume; default: the preset's (0.35)."""
    n_mixers: int | None = Field(default=None, ge=1, le=20, json_schema_extra={"unit": "-"})
    """Perfect mixers in series (the residence-time distribution) of the controller's model and,
    unless ``[plant]`` says otherwise, of the plant; default 3."""
    size_classes: SizeClasses = Field(default_factory=SizeClasses)
    """The size grid of the controller's model and, unless ``[plant]`` says otherwise, of the plant."""
    mixer_volume_fracs: list[float] | None = Field(default=None, min_length=1, max_length=20, examples=[[0.7, 0.15, 0.15]],
                                                   json_schema_extra={"unit": "fraction of hold-up"})
    """The mixers' shares of the hold-up in the order the slurry flows, e.g. Whiten's one large and two
    small [0.7, 0.15, 0.15]; the order matters where a grate classifies, at the last mixer's discharge;
    sets ``n_mixers`` (which must agree if given); default: equal shares."""
    ball_size_mm: float | None = Field(default=None, ge=BALL_SIZE_MIN_MM, le=BALL_SIZE_MAX_MM, examples=[25.0],
                                       json_schema_extra={"unit": "mm"})
    """Make-up ball size [mm] (Austin's scale-up factors on S); default: the preset's (25)."""
    discharge_solids_frac: float | None = Field(default=None, gt=0, lt=1)
    """Solids mass fraction of the mill discharge (0.72, not 72), held by the mill's feed water in a
    hydrocyclone circuit's water balance (read by nothing else: refused beside a grate); default 0.70."""
    power_model: Literal["bond", "hogg_fuerstenau"] | None = Field(default=None, examples=["hogg_fuerstenau"])
    """Net-power model of the mill, read by the ``power`` effect only (refused without it); default: the
    preset's (``"bond"``)."""
    net_power_kw: float | None = Field(default=None, gt=0, le=1e5)
    """A given (measured or published) net power [kW] at the scene's speed (``feed.speed_frac_critical``,
    where the plant measured it); the power model then only shapes how power moves with speed."""
    @model_validator(mode="after")
    def _mixers_agree(self):
        fracs = self.mixer_volume_fracs
        if fracs is not None:
            if any(not f > 0 for f in fracs):
                raise ValueError(f"mixer_volume_fracs must be positive shares of the hold-up (got {fracs})")
            if not mixer_shares_sum_ok(sum(fracs)):  # 1.1 is a slip, not a rounding: say so
                raise ValueError(f"mixer_volume_fracs must sum to 1 within {MIXER_SHARES_SUM_TOL:g} (shares of the "
                                 f"hold-up; got {fracs}, sum {sum(fracs):.4g})")
            if self.n_mixers is not None and self.n_mixers != len(fracs):
                raise ValueError(f"n_mixers = {self.n_mixers} but mixer_volume_fracs has {len(fracs)} shares: "
                                 "give one of them, or both agreeing")
        return self




class OreBreakage(Section):
    """``[ores.NAME.breakage]``: the ore's selection and breakage parameters given directly (they
    replace the calibration's mineralogy map for this ore; twin.BreakageParams).

    ``form = "energy_specific"`` (Moly-Cop Tools, Herbst & Fuerstenau): S^E = alpha0_t_kwh
    d^alpha1 / (1 + (d / critical_size_um)^alpha2), d in um. ``form = "austin"``: Austin's rate
    S = a_per_min (d/1 mm)^alpha / (1 + (d/mu_um)^Lambda) [1/min], the rate at which ore leaves
    Austin's sqrt(2) interval whose upper size is d, all its fragments leaving it (Austin, Klimpel &
    Luckie 1984, eq. 4.5: a one-interval feed's first-order disappearance; the twin moves it to its
    particle sizes and, on the cell-average scheme, where fragments may stay in their parent's class,
    raises it so that the interval whose top is 1 mm is left at that rate), measured at the scene
    mill's nominal hold-up and its power at the scene's speed (``feed.speed_frac_critical``: given
    parameters of either form are the mill's at that speed).
    Breakage B = beta0 (x/y)^beta1 + (1 - beta0)(x/y)^beta2 (Austin's
    phi, gamma, beta) for both."""

    form: Literal["energy_specific", "austin"] = "energy_specific"
    """Which selection form the keys below give."""
    alpha0_t_kwh: float | None = Field(default=None, gt=0, le=1e6)
    """Energy-specific selection coefficient [t/kWh] with sizes in um (energy_specific)."""
    alpha1: float | None = Field(default=None, gt=0, le=5, json_schema_extra={"unit": "-"})
    """Size exponent of the energy-specific selection (energy_specific)."""
    alpha2: float | None = Field(default=None, gt=0, le=20, json_schema_extra={"unit": "-"})
    """Exponent of the fall of the selection above the critical size (energy_specific)."""
    critical_size_um: float | None = Field(default=None, ge=CRITICAL_SIZE_MIN_UM, le=1e7)
    """Critical size of the selection [um] (energy_specific); at least 100 um (see ``mu_um``)."""
    selection_power_frac: float | None = Field(default=None, gt=0, le=1, json_schema_extra={"unit": "-"})
    """The share of the mill's net power that ``alpha0_t_kwh`` is stated per kWh of (energy_specific; unset: 1,
    the net power, Herbst & Fuerstenau 1980). Moly-Cop Tools states it per kWh the balls draw: its specific
    energy per pass is the balls' kW over the mill feed, not the net kW (the interstitial slurry's share left
    out), so its share is its Mill Outputs' balls kW over net kW."""
    a_per_min: float | None = Field(default=None, gt=0, le=1e6, examples=[0.7], json_schema_extra={"unit": "1/min"})
    """Austin's rate constant at 1 mm [1/min] (austin)."""
    alpha: float | None = Field(default=None, gt=0, le=5, examples=[1.0], json_schema_extra={"unit": "-"})
    """Austin's size exponent (austin)."""
    mu_um: float | None = Field(default=None, ge=CRITICAL_SIZE_MIN_UM, le=1e7, examples=[3000.0])
    """Austin's mu, the size where the rate falls to half its power law [um] (austin); at least 100 um:
    ball mills' lie at millimetres (Austin et al. 1984, ch. 4: ~3 mm for 25 mm balls, scaling as the ball
    size squared, ~0.5 mm for 10 mm balls), and a size in mm (5 for 5 mm) overloaded the mill while
    the feed rate was blamed."""
    Lambda: float | None = Field(default=None, gt=0, le=20, examples=[3.0], json_schema_extra={"unit": "-"})
    """Austin's Lambda, the steepness of that fall (austin)."""
    beta0: float = Field(ge=0, le=1, json_schema_extra={"unit": "-"})
    """Share of the fine-fragment term of B (Austin's phi)."""
    beta1: float = Field(gt=0, le=5, json_schema_extra={"unit": "-"})
    """Exponent of the fine-fragment term of B (Austin's gamma), at most ``beta2``."""
    beta2: float = Field(gt=0, le=20, json_schema_extra={"unit": "-"})
    """Exponent of the coarse-fragment term of B (Austin's beta)."""

    @model_validator(mode="after")
    def _form_complete(self):
        need = {"energy_specific": ("alpha0_t_kwh", "alpha1", "alpha2", "critical_size_um"),
                "austin": ("a_per_min", "alpha", "mu_um", "Lambda")}
        missing = [k for k in need[self.form] if getattr(self, k) is None]
        extra = [k for f, keys in need.items() if f != self.form for k in keys if getattr(self, k) is not None]
        if missing:
            raise ValueError(f"form = {self.form!r} needs {', '.join(missing)}")
        if self.form != "energy_specific" and self.selection_power_frac is not None:
            extra.append("selection_power_frac")
        if extra:
            raise ValueError(f"{', '.join(extra)} belong to the other form, not form = {self.form!r}")
        order = exponent_order_problem(self.beta1, self.beta2, self.beta0, names=("beta0", "beta1", "beta2"))
        if order:
            raise ValueError(order)
        return self


class Texture(Section):
    """``[ores.NAME.texture]``: mean grain size, grain-size uniformity in (0, 1] (1 =
    equigranular), mineral-association entropy in [0, 1] (1 = fully intergrown); as
    ``twin.ore.mineralogy.Texture``."""

    mean_grain_um: float = Field(ge=MEAN_GRAIN_RANGE_UM[0], le=MEAN_GRAIN_RANGE_UM[1])
    """Mean mineral grain size [um] (automated mineralogy)."""
    uniformity: float = Field(gt=0, le=1, json_schema_extra={"unit": "-"})
    """Grain-size uniformity: 1 = equigranular."""
    association_entropy: float = Field(ge=0, le=1, json_schema_extra={"unit": "-"})
    """Mineral-association entropy, normalised: 0 = each mineral touches only itself, 1 = fully
    intergrown."""


class Ore(Section):
    """``[ores.NAME]``: a reference ore ``type`` or an explicit mineralogy (wt%) and texture."""

    type: Literal["A", "B", "C", "D"] | None = None
    """A reference ore type of the porphyry deposit (MISSION.md; ``twin/ore/data/ores.toml``);
    give either ``type`` or ``mineralogy`` and ``texture``."""
    mineralogy: dict[str, float] | None = Field(default=None, json_schema_extra={"unit": "wt%"})
    """Modal mineralogy, mineral -> wt% (minerals of ``twin/ore/data/minerals.csv``), summing to
    100 within 0.5 wt%; required with ``texture`` when there is no ``type``."""
    texture: Texture | None = None
    """The ore's texture (``[ores.NAME.texture]``); required with ``mineralogy``."""
    breakage: OreBreakage | None = None
    """Selection and breakage parameters given directly (``[ores.NAME.breakage]``), in place of
    the calibration's mineralogy map for this ore."""
    density_t_m3: float | None = Field(default=None, gt=1, le=25, json_schema_extra={"unit": "t/m3"})
    """Solids density [t/m3] of this ore in place of its minerals' (the mill holds and classifies each ore at its
    own density; the other ores keep theirs)."""


class ScheduleEvent(Section):
    """``[[feed.schedule]]``: from ``at_h`` the blend moves to ``blend`` (step or linear ramp)."""

    at_h: float = Field(ge=0)
    """When the change starts [h]; events in increasing time, each after the previous ramp ends."""
    blend: dict[str, float] = Field(json_schema_extra={"unit": "mass fraction"})
    """The blend the feed moves to, ore -> mass fraction (ores of ``[ores]``, summing to 1)."""
    kind: Literal["step", "ramp"] = "step"
    """``"step"``: the new blend from ``at_h``; ``"ramp"``: linear over ``ramp_h``."""
    ramp_h: float = Field(default=0.0, ge=0)
    """Length of a ramp [h] (> 0 for a ramp; only for ``kind = "ramp"``)."""


class FeedPSD(Section):
    """``[feed.psd]``: a screen analysis: sieve sizes [um] and cumulative % passing (94.43, not
    0.9443), any order (twin.sizes.TabulatedPSD)."""

    sizes_um: list[float] = Field(min_length=2)
    """Sieve sizes [um]."""
    passing_pct: list[float] = Field(min_length=2)
    """Cumulative % passing each sieve."""

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

    blend: dict[str, float] | None = Field(default=None, json_schema_extra={"unit": "mass fraction"})
    """Blend at t = 0, ore -> mass fraction (ores of ``[ores]``, summing to 1 within 5e-4 per ore: fractions
    typed to three decimals, rescaled to sum to 1); required unless ``history`` gives the feed from t = 0."""
    start: Literal["scene", "target"] | None = None
    """Where a continuous run starts: ``"scene"`` at the steady state of ``feed_tph``;
    ``"target"`` at the steady state whose feed rate holds ``controller.target_p80_um`` at the
    initial blend and speed (an open loop then holds that feed rate; needs the target). Unset:
    ``"target"`` for a closed loop (``controller.kind`` pi or nmpc), ``"scene"`` for an open
    loop (a scene runs at its own feed rate unless it says ``start = "target"``)."""
    feed_tph: float | None = Field(default=None, gt=0, le=1e4)
    """Fresh feed rate [t/h] (dry solids); required with the ``transport`` effect. Open loop it is
    held throughout unless ``start = "target"``; a closed loop starts the plant at the feed rate
    that holds the target unless ``start = "scene"`` (the run's notes say which). It is also the
    mill's nominal feed, at which its free discharge holds its nominal hold-up
    (:meth:`twin.Mill.free_discharge_tph`): a scene at twice the feed states a mill built to
    discharge twice as much, not the same mill fed twice as much (that is ``grindtwin steady
    --scene FILE --feed-tph``, a controller's moves or a history's ``feed_tph``)."""
    batch_charge_kg: float | None = Field(default=None, gt=0, le=1e6)
    """Charge of a batch grind [kg] (a scene without ``transport``); only for batch scenes."""
    speed_frac_critical: float = Field(gt=0, lt=1)
    """Mill speed as a fraction of critical (0.70, not 70); held open loop, the start of a
    closed loop."""
    p80_um: float = Field(default=3200.0, gt=0, le=1e6)
    """P80 of the fresh feed [um] (80 % passing), below ``mill.size_classes.top_um``."""
    ggs_modulus: float = Field(default=0.8, gt=0, le=5, json_schema_extra={"unit": "-"})
    """Distribution modulus m of the Gates-Gaudin-Schuhmann feed, passing = (x / x_max)^m with
    x_max from ``p80_um``."""
    psd: FeedPSD | None = None
    """A screen analysis of the fresh feed (``[feed.psd]``), in place of ``p80_um``."""
    psd_csv: str | None = Field(default=None, examples=["data/feed_screen.csv"])
    """A CSV of the fresh feed's screen analysis (columns ``size_um``, ``passing_pct``; lines starting
    with ``#`` are comments, as in a history; path relative to the scene file), in place of ``p80_um``;
    summary.json, the report and the workbook record its SHA-256, as a history's."""
    schedule: list[ScheduleEvent] = Field(default_factory=list)
    """Blend changes over time (``[[feed.schedule]]``); not with ``history``."""
    history: str | None = None
    """A recorded history, CSV or Parquet (path relative to the scene file): a time column
    (``timestamp`` or ``time_h``), mineral wt% (``<mineral>_wt_pct``) or ore fractions
    (``ore_<name>_frac``), optionally ``feed_tph``, ``speed_frac_critical``, ``p80_um`` and the
    three texture columns; rules in ``scenarios/scene/history.py``. A mineralogy is mapped onto the
    scene's ores (the reference types A-D without ``[ores]``) by non-negative least squares; the
    recorded texture is compared with the mix's (a run warns when their textural indices differ
    beyond ``scenarios.run.feed.TEXTURE_RATIO_WARN``): the ores' own textures are what break."""
    history_texture: Texture | None = Field(default=None, examples=[
        {"mean_grain_um": 120.0, "uniformity": 0.6, "association_entropy": 0.5}])
    """Texture of a mineralogy history without texture columns (required then; only with
    ``history``)."""
    history_max_gap_h: float = Field(default=10 / 60, gt=0)
    """Longest stretch [h] over which a missing recorded value is held; longer gaps are refused."""

    @model_validator(mode="after")
    def _one_size_distribution(self):
        given = [k for k in ("psd", "psd_csv") if getattr(self, k) is not None]
        # a GGS key at its default is not a second size (a scene dumped with its defaults and
        # loaded again, as replays and the shipped-scene runs do, keeps its screen analysis)
        ggs = [k for k in ("p80_um", "ggs_modulus")
               if k in self.model_fields_set and getattr(self, k) != type(self).model_fields[k].default]
        if len(given) > 1 or (given and ggs):
            raise ValueError("give the feed size once: " + " or ".join(given + ggs) + " (psd, psd_csv, "
                             "or p80_um with ggs_modulus)")
        return self


class Weights(Section):
    """``[controller.weights]``: P80 tracking, move suppression, energy."""

    p80: float = Field(default=1.0, ge=0, json_schema_extra={"unit": "-"})
    """NMPC weight on (100 (passing fraction at the target size - 0.80))^2 per sample."""
    du_feed: float = Field(default=0.1, ge=0, json_schema_extra={"unit": "1/(t/h)^2"})
    """NMPC weight on (feed move [t/h])^2."""
    du_speed: float = Field(default=0.1, ge=0, json_schema_extra={"unit": "1/(% of critical)^2"})
    """NMPC weight on (speed move [% of critical])^2."""
    energy: float = Field(default=0.0, ge=0, json_schema_extra={"unit": "1/(kWh/t)"})
    """NMPC economic weight on specific energy per sample (0: none)."""


class Bounds(Section):
    """``[controller.bounds]``: input bounds and rate limits (``None`` = no rate limit)."""

    feed_tph_min: float | None = Field(default=None, gt=0)
    """Lowest feed rate [t/h], at least 5 % of the mill's nominal feed (below it the KPIs read a feed stop);
    required for ``pi`` and ``nmpc``."""
    feed_tph_max: float | None = Field(default=None, gt=0)
    """Highest feed rate [t/h], above ``feed_tph_min``; required for ``pi`` and ``nmpc``."""
    speed_min: float = Field(default=0.60, gt=0, lt=1, json_schema_extra={"unit": "fraction of critical"})
    """Lowest mill speed (NMPC)."""
    speed_max: float = Field(default=0.85, gt=0, lt=1, json_schema_extra={"unit": "fraction of critical"})
    """Highest mill speed (NMPC), above ``speed_min``."""
    feed_rate_max_tph_per_h: float | None = Field(default=None, gt=0, json_schema_extra={"unit": "t/h per h"})
    """Largest feed-rate change per hour (NMPC and PI); none: no limit."""
    speed_rate_max_per_h: float | None = Field(default=None, gt=0,
                                               json_schema_extra={"unit": "fraction of critical per h"})
    """Largest speed change per hour (NMPC); none: no limit."""


class Controller(Section):
    """``[controller]``: kind, target, horizon and tuning, bounds, solver.

    ``load_band_frac`` is the mill hold-up as a fraction of its nominal hold-up (the ore its ball bed
    holds at the mill's nominal powder filling, :meth:`twin.Mill.nominal_holdup_t`: the ``load_frac``
    output), not of the hold-up at the start (23.6 t/h of the reference scene starts at 0.94);
    ``preview_lead_h`` is how far ahead the feed is known (belt analyser);
    ``disturbance_model`` what the EKF's disturbance states absorb (``mpc.DISTURBANCE_MODELS``).
    Open loop (``"none"``) reads ``target_p80_um`` and ``load_band_frac`` (the KPIs); ``"pi"`` these and
    ``bounds.feed_tph_min``, ``feed_tph_max`` and ``feed_rate_max_tph_per_h``; a batch grind only ``kind``;
    a scene file giving a key its kind does not read is refused (read by nothing).
    """

    kind: Literal["none", "pi", "nmpc"] = "none"
    """``"none"``: open loop, the scene's inputs. ``"pi"``: a PI loop from the analyser's P80 to
    the feed rate only (speed held), SIMC-tuned on the linearised plant twin with the analyser's
    delay and anti-windup. ``"nmpc"``: the NMPC moves feed rate and speed, with an EKF estimating
    the mill contents and the ore hardness from the analyser, power and load readings."""
    target_p80_um: float | None = Field(default=None, gt=0)
    """Product P80 target [um]; required for ``pi`` and ``nmpc``; open loop it is the reference
    of the P80 KPIs. A closed loop starts the plant at the steady state that holds it."""
    horizon_steps: int = Field(default=30, ge=1, le=10_000, json_schema_extra={"unit": "samples"})
    """NMPC prediction horizon."""
    move_block: int = Field(default=5, ge=1, json_schema_extra={"unit": "samples"})
    """NMPC samples per input block (1: a free move every sample); at most ``horizon_steps``."""
    rk4_substeps: int = Field(default=3, ge=1, le=100, json_schema_extra={"unit": "per sample"})
    """RK4 steps per sample in the NMPC's prediction (and the EKF's, which takes at least 3); a
    count below the stable one at the initial steady state, or at the top of the load band (the
    highest feed whose steady load stays in it, each blend of the feed), is refused before the run."""
    preview_lead_h: float = Field(default=0.0, ge=0)
    """How far ahead [h] the feed blend is known (a belt analyser): the NMPC sees the blend over
    its horizon up to this lead (0: feedback only)."""
    weights: Weights = Field(default_factory=Weights)
    """NMPC weights (``[controller.weights]``)."""
    bounds: Bounds = Field(default_factory=Bounds)
    """Input bounds and rate limits (``[controller.bounds]``)."""
    solver: Literal[SOLVERS] = "ipopt"
    """NMPC solver: ``"ipopt"`` (interior point, exact Hessian; the default), ``"sqpmethod"``
    (SQP), ``"fatrop"`` (structure-exploiting interior point), ``"rti"`` (real-time iteration:
    one Gauss-Newton QP a sample; the reference scene's choice)."""
    qpsol: Literal[QP_SOLVERS] | None = Field(default=None, examples=["hpipm"])
    """QP solver of ``rti`` (default ``"hpipm"``; ``"condensed"``: the same QP condensed onto the
    inputs and solved in compiled C, what ``grindtwin export-controller`` exports) or
    ``sqpmethod`` (``"qrqp"``, its only choice)."""
    load_band_frac: list[float] = Field(default_factory=lambda: [0.8, 1.2], min_length=2,
                                        max_length=2, json_schema_extra={"unit": "hold-up / nominal"})
    """Stable band of the mill load [low, high], 0 < low < 1 < high: a soft constraint of the NMPC
    and the band of the ``load_outside_band_frac`` KPI."""
    power_max_kw: float | None = Field(default=None, gt=0, examples=[180.0])
    """Soft upper limit of mill power [kW] for the NMPC; none: no limit. Within a factor 2 of the mill's
    power at ``bounds.speed_min`` and ``speed_max`` (below, no speed meets it; above, it never binds)."""
    disturbance_model: Literal[DISTURBANCE_MODELS] = "hardness"
    """What the NMPC's estimator reads the plant/model mismatch as: ``"hardness"`` (everything,
    including a coarse model's structural P80 error, is read as ore hardness), ``"p80_bias"``
    (hardness held at 1; the analyser reads the model's P80 plus a bias) or
    ``"hardness+p80_bias"`` (both: the bias takes the slow P80 mismatch); see mpc.estimator."""


class Sensors(Section):
    """``[sensors]``: noise (one standard deviation), dead time and sampling of the analysers.

    ``p80_sample_period_h = None`` means the scene's sample period.
    """

    p80_noise_um: float = Field(default=0.0, ge=0)
    """Standard deviation of the P80 analyser's Gaussian noise [um]."""
    p80_dead_time_h: float = Field(default=0.0, ge=0)
    """Analyser dead time [h]: a sample taken at t is reported at t + dead time; shorter than
    the scene. To let the NMPC's model know it, also list ``sensor_delay`` with this
    ``dead_time_h``."""
    p80_sample_period_h: float | None = Field(default=None, gt=0)
    """Analyser sampling period [h], at least ``scene.sample_period_h``; the reading is held in
    between; default: the scene's sample period."""
    power_noise_kw: float = Field(default=0.0, ge=0)
    """Standard deviation of the mill power reading's noise [kW]; read by a controller's loop only (a scene
    file with ``controller.kind = "none"`` giving it is refused: read by nothing)."""
    load_noise_frac: float = Field(default=0.0, ge=0, lt=1, json_schema_extra={"unit": "hold-up / nominal"})
    """Standard deviation of the load reading's noise [hold-up / nominal]; read by a controller's loop only
    (refused beside ``controller.kind = "none"``, as the power's)."""


class Plant(Section):
    """``[plant]``: the simulated plant when it differs from the controller's model.

    ``model = "twin"`` uses the twin with the effects and size classes given here (missing
    ones are taken from the scene); ``"leroux2013"`` is the literature milling-circuit model.
    Only an NMPC runs the controller's model: beside an open loop, PI or a batch grind, a scene file's
    ``mill.size_classes``, ``mill.n_mixers`` and ``effect_options`` that the plant replaces or lacks are
    refused (read by nothing).
    """

    model: Literal["twin", "leroux2013"] = "twin"
    """``"twin"``: a twin built with the settings below; ``"leroux2013"`` (le Roux et al. 2013) is
    refused by scenes for now (it runs from benchmarks/mpc_leroux_case.py)."""
    effects: list[str] | None = None
    """The plant's effects (names as in ``effects``); default: the scene's."""
    size_classes: SizeClasses | None = None
    """The plant's size grid; default: ``mill.size_classes`` (the controller's model's grid)."""
    n_mixers: int | None = Field(default=None, ge=1, le=20, json_schema_extra={"unit": "-"})
    """The plant's mixers in series; default: ``mill.n_mixers``."""
    effect_options: dict[str, dict[str, Any]] | None = Field(default=None, examples=[
        {"classification": {"kind": "hydrocyclone"}}])
    """Options of the plant's effects, by effect: an effect's table here replaces the scene's table
    of that effect (``{}``: the effect's defaults); the plant's other effects keep the scene's."""


class Scene(Section):
    """A validated scene. Build it with :func:`scenarios.scene.loader.load_scene`.

    ``effect_options`` maps an effect of ``effects`` to its options (option names are checked
    against those the twin's effect declares; values are passed to the twin as written).
    ``calibration`` names the calibration the twins run (a shipped name such as ``"dem"``, the
    default, or a calibration file, relative to the scene's folder); a model whose effects or
    size grid (or, on the calibration's own mill, mixers) differ from the calibration's is refused
    unless ``calibration_mismatch_ok = true`` says the scene means it (the check names both).
    ``source_path`` is the file it came from (``None`` if built from a dict); relative paths
    in the scene (``feed.history``) are resolved against its folder.
    """

    scene: SceneInfo
    """Identity, time axis and seed (``[scene]``)."""
    mill: Mill
    """The mill and the size grid (``[mill]``)."""
    ores: dict[str, Ore] = Field(default_factory=dict)
    """The ores the feed is blended from, by name (``[ores.NAME]``); at least one, unless a
    mineralogy ``feed.history`` is given (then the reference types A-D are the components)."""
    feed: Feed
    """Feed blend over time, rate, speed and size (``[feed]``)."""
    effects: list[str]
    """The physical effects the model contains, and nothing else (see "Effects" below); a
    top-level key, so in TOML it comes before the first ``[table]``. Without ``transport`` the
    scene is a batch grind."""
    effect_options: dict[str, dict[str, Any]] = Field(default_factory=dict)
    """Options of listed effects, ``[effect_options.EFFECT]`` (see "Effects" below)."""
    controller: Controller = Field(default_factory=Controller)
    """What moves the inputs (``[controller]``)."""
    sensors: Sensors = Field(default_factory=Sensors)
    """The plant's measurements (``[sensors]``); used by closed loops and for the analyser trace
    of open-loop runs."""
    plant: Plant | None = None
    """The simulated plant when it differs from the controller's model (``[plant]``); default: the
    same twin."""
    calibration: str = Field(default="dem", min_length=1)
    """The calibration the twins run: a shipped name (``"dem"``, the DEM chain, or ``"table"``) or
    a calibration file made by ``grindtwin calibrate`` (a path relative to the scene's folder); a
    top-level key."""
    calibration_mismatch_ok: bool = False
    """``true`` runs a model whose effects or size grid differ from the calibration's, or, on the
    calibration's own mill (``lab``), whose mixers (``n_mixers``, ``mixer_volume_fracs``) differ
    from the equal mixers its mill values were fitted with (which ``grindtwin check`` otherwise
    refuses, naming both): the scene says it means it."""

    _source_path: Path | None = PrivateAttr(default=None)
    #: The SHA-256 of the mill preset file as the scene was loaded (:meth:`preset_file_identity`).
    _preset_file_sha256: str | None = PrivateAttr(default=None)

    @property
    def source_path(self) -> Path | None:
        """The scene file, or ``None``."""
        return self._source_path

    def calibration_spec(self) -> str:
        """``calibration`` as a shipped name, or its file resolved against the scene's folder."""
        p = Path(self.calibration)
        if p.suffix == ".json" and not p.is_absolute() and self._source_path is not None:
            return str(self._source_path.parent / p)
        return self.calibration

    def history_path(self) -> Path | None:
        """``feed.history`` resolved against the scene file's folder, or ``None``."""
        if self.feed.history is None:
            return None
        return self.resolve_path(self.feed.history)

    def mill_spec(self) -> str | Path:
        """The scene's mill as twin.get_mill takes it: a preset's name, or its preset file resolved
        against the scene file's folder."""
        preset = self.mill.preset
        return self.resolve_path(preset) if is_preset_file(preset) else preset

    def preset_file_identity(self) -> dict | None:
        """The mill preset file the scene names, its resolved path and SHA-256 as the scene was loaded (before any
        work: a file rewritten during a run is not recorded with its new hash), or None for a preset's name."""
        spec = self.mill_spec()
        if not isinstance(spec, Path):
            return None
        return {"path": str(spec.resolve()), "sha256": self._preset_file_sha256 or file_sha256(spec)}

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
