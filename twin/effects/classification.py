"""Size-dependent discharge: a grate at the mill's discharge end, or a closed circuit with a
hydrocyclone whose underflow returns to the mill feed (the industrial configuration).

- Grate: discharge factor c_i = 1 / (1 + (x_i / d50)^k) (Austin, Klimpel & Luckie 1984, ch. 9,
  internal classification of grate-discharge mills), d50 and k from the mill, d50 stated for a
  quartz slurry: a particle leaves with the slurry when it settles slower than the slurry
  moves, and Stokes' settling velocity g d^2 (rho_s - rho_w) / (18 mu) makes the cut size
  scale as (rho_s - rho_w)^-1/2, the density term Plitt's cyclone d50c has too. So a denser ore
  is held back finer (dense minerals are retained in grinding circuits and ground longer: gold in
  Banisi, Laplante & Marois 1991, CIM Bull. 84 (955), 72-78).
- Each ore is classified at its own density, grate and cyclone alike: a particle settles by its own
  density, so where the twin's ores differ an ore of density rho_k is cut at d50 ((rho_k - rho_w) /
  (rho - rho_w))^-1/2, rho the density the cut is stated for (the grate's: quartz; Plitt's d50c: the
  stream's, whose volume fraction sets the hindered settling). Minerals of different density in one
  cyclone feed have their own partition curves (Laplante & Finch 1984, Int. J. Miner. Process. 13,
  1-11; a blend's measured curve is their mass-weighted sum).
- The cut sizes are multiplied by the assembly's ``cut_size_factor`` (1 unless ``rheology`` is
  listed: the slurry's clay against a clay-free slurry): the grate's, and a Plitt cyclone's over the
  factor of the slurry its calibration was measured on (``surveyed_clay_frac``, the clay fraction of
  that slurry's solids; 0, a clay-free slurry, as Plitt's equations are, by default); a cyclone given
  directly not at all (fixed whatever the feed: its d50c of 300 um ran at 359 um on ore B's slurry, 560
  on a clay blend).
- Hydrocyclone: Plitt (1976, CIM Bull. 69, 114-123) with the corrections of Flintoff, Plitt &
  Turak (1987, CIM Bull. 80, 39-50): corrected cut size d50c, pressure, volumetric flow split and
  sharpness m from the cyclone geometry and its feed, each evaluated at the actual cyclone feed
  (the mill discharge diluted at the sump to a set solids content), each with a calibration
  factor; or d50c, m and the bypasses of a surveyed cyclone given directly; or the factors
  calibrated on a survey (:class:`CycloneSurvey`, Flintoff et al.'s one factor per equation), so a
  surveyed cyclone still answers changes of its feed as Plitt's equations do. Corrected efficiency
  E_c = 1 - exp(-ln 2 (d/d50c)^m), partition to underflow E = R_s + (1 - R_s) E_c with R_s the
  solids bypass; water splits by the water bypass R_f. Water and solids are balanced apart: the
  solids fraction of the mill discharge (the mill's), cyclone feed, overflow and underflow are
  outputs, with the cyclone pressure and the sump's and mill's water additions."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import ClassVar

import casadi as ca
import numpy as np
from scipy.constants import g as G_M_S2

from ..errors import ModelError, bad_value, check_int, check_range, close_matches
from ..mill import CYCLONE_CIRCUITS, DISCHARGE_REFERENCE_DENSITY_T_M3, refuse_bool_fields
from .base import Effect, EffectContext, Option, smooth_max


#: Plitt's (1976) equations in the metric form of Flintoff, Plitt & Turak (1987): coefficients
#: of d50c [um], pressure [kPa], volumetric split S = Qu/Qo and sharpness m, with sizes in cm,
#: flow in L/min per cyclone, phi the feed solids % by volume, head in m of slurry.
PLITT_D50C, PLITT_PRESSURE, PLITT_SPLIT, PLITT_SHARPNESS = 39.7, 1.88, 1.9, 1.94
#: Plitt's partition: corrected efficiency 1 - exp(-ln 2 (d/d50c)^m) (0.693 = ln 2: E_c(d50c) = 1/2).
LN2 = math.log(2.0)
#: The corrected efficiency curves a cyclone's ``curve`` takes (:func:`corrected_partition`).
PARTITION_CURVES = ("plitt", "whiten")


def corrected_partition(size_over_d50c, sharpness, curve: str = "plitt"):
    """The corrected partition to the underflow at sizes d/d50c (0.5 at 1): ``"plitt"``, 1 - exp(-ln 2
    (d/d50c)^m) (Plitt 1976, CIM Bull. 69, 114-123; the Rosin-Rammler form, m the sharpness); ``"whiten"``,
    (e^(alpha x) - 1) / (e^(alpha x) + e^alpha - 2), x = d/d50c (Whiten's efficiency curve without the
    fish-hook; Napier-Munn et al. 1996, *Mineral Comminution Circuits*, JKMRC, ch. 10), written with
    e^(-alpha x) so that coarse sizes do not overflow. Floats, arrays or CasADi expressions."""
    if curve == "whiten":
        fall = _exp(-sharpness * size_over_d50c)
        return (1.0 - fall) / (1.0 + (_exp(sharpness) - 2.0) * fall)
    return 1.0 - _exp(-LN2 * size_over_d50c ** sharpness)


WATER_DENSITY_T_M3 = 1.0
#: Densest cyclone feed [solids % by volume] a Hydrocyclone takes: past ~70 % a slurry no longer
#: flows (a packed bed of particles holds ~60-65 % solids by volume).
FEED_SOLIDS_VOL_PCT_MAX = 70.0
#: The most dilute cyclone feed [solids % by volume] a Hydrocyclone takes: grinding circuits feed their cyclones
#: at some 15-45 % (the Moly-Cop base case 36 %); below 1 % the value is a fraction given for percent (0.42 for
#: 42 %), which put Plitt's pressure at 1e15 kPa.
FEED_SOLIDS_VOL_PCT_MIN = 1.0
#: Feed pressures grinding-circuit cyclones run at [kPa], 5-40 psi: below, too little head to classify; above,
#: wear and roping (a design's range, :func:`twin.size_mill`; outside it a steady state carries a note).
CYCLONE_PRESSURE_RANGE_KPA = (34.0, 276.0)


def _check_feed_vol_pct(owner: str, field: str, value, what: str, vol_pct: float) -> float:
    """``vol_pct``, the cyclone feed's solids % by volume that ``field`` = ``value`` makes, if a slurry that flows
    (:data:`FEED_SOLIDS_VOL_PCT_MIN`-:data:`FEED_SOLIDS_VOL_PCT_MAX`, Plitt's phi); else an error saying ``what``."""
    if not FEED_SOLIDS_VOL_PCT_MIN <= vol_pct <= FEED_SOLIDS_VOL_PCT_MAX:
        raise bad_value(owner, field, value, f"{what} a feed of {FEED_SOLIDS_VOL_PCT_MIN:g}-{FEED_SOLIDS_VOL_PCT_MAX:g} "
                        f"% solids by volume (Plitt's phi; a slurry that flows), not {vol_pct:.3g} %")
    return vol_pct


def _exp(v):
    return ca.exp(v) if isinstance(v, (ca.SX, ca.MX)) else np.exp(v)


#: kPa per psi (a cyclone's pressure gauge often reads psi).
KPA_PER_PSI = 6.894757293168361

#: A cyclone's corrected cut size d50c [um] is at least this: hydrocyclones cut at ~5 um and coarser (the
#: smallest, 10 mm bodies; Wills & Finch 2016, ch. 9), and no particle-size analysis resolves below ~1 um;
#: a d50c in mm (0.18 for a 183-um cut) lands below, and its Plitt factor became 0.0008 without a word.
D50C_MIN_UM = 1.0
#: ... and below this [um] (10 cm: no classifier's cut; the bound the field had).
D50C_MAX_UM = 1e5
#: Plitt's viscosity is the liquid's [cP], at least water's near boiling (0.28 cP at 100 C; CRC Handbook
#: of Chemistry and Physics, viscosity of water): a viscosity in Pa s (0.001 for water) lands below, and
#: cut the d50c to a thirtieth, the mill then overloading with the feed blamed.
VISCOSITY_MIN_CP = 0.28


def check_d50c(owner: str, value) -> float:
    """``value`` as a float if it is a cut size a hydrocyclone makes [um], else TwinInputError naming ``owner``."""
    v = check_range(owner, "d50c_um", value, 0.0, D50C_MAX_UM)
    if v < D50C_MIN_UM:
        raise bad_value(owner, "d50c_um", value, f"at least {D50C_MIN_UM:g} um, the finest cut a hydrocyclone makes "
                        "(mm? um expected)")
    return v


@dataclass(frozen=True)
class CycloneSurvey:
    """One survey of a hydrocyclone cluster: the feed it classified (solids [t/h] and water [m3/h]
    to the whole cluster, the solids' density [t/m3]) and how it performed: corrected cut size
    d50c [um], Plitt sharpness m, water bypass R_f (the feed water to the underflow) and feed pressure
    [kPa, or psi as ``pressure_psi``]."""

    feed_solids_tph: float
    feed_water_m3_h: float
    solids_density_t_m3: float
    d50c_um: float
    sharpness: float
    water_bypass_frac: float
    pressure_kpa: float | None = None
    pressure_psi: float | None = None

    def __post_init__(self):
        o = "CycloneSurvey"
        refuse_bool_fields(o, self)
        for name, lo, hi in (("feed_solids_tph", 0.0, 1e6), ("feed_water_m3_h", 0.0, 1e6),
                             ("solids_density_t_m3", WATER_DENSITY_T_M3, 25.0), ("sharpness", 0.0, 20.0),
                             ("water_bypass_frac", 0.0, 1.0)):
            check_range(o, name, getattr(self, name), lo, hi)
        check_d50c(o, self.d50c_um)
        if (self.pressure_kpa is None) == (self.pressure_psi is None):
            raise bad_value(o, "pressure_kpa", self.pressure_kpa,
                            f"given, or 'pressure_psi' instead, not both (pressure_psi = {self.pressure_psi!r})")
        name = "pressure_kpa" if self.pressure_psi is None else "pressure_psi"
        check_range(o, name, getattr(self, name), 0.0, 1e4)
        _check_feed_vol_pct(o, "feed_water_m3_h", self.feed_water_m3_h,
                            f"a water flow that makes, with feed_solids_tph = {self.feed_solids_tph!r} at "
                            f"{self.solids_density_t_m3:g} t/m3,",
                            solids_volume_pct(self.feed_solids_frac, self.solids_density_t_m3))

    @property
    def kpa(self) -> float:
        return float(self.pressure_kpa if self.pressure_psi is None else self.pressure_psi * KPA_PER_PSI)

    @property
    def slurry_m3_h(self) -> float:
        return self.feed_solids_tph / self.solids_density_t_m3 + self.feed_water_m3_h / WATER_DENSITY_T_M3

    @property
    def feed_solids_frac(self) -> float:
        return self.feed_solids_tph / (self.feed_solids_tph + self.feed_water_m3_h * WATER_DENSITY_T_M3)


#: Plitt factors a cyclone given directly does not read (its pressure, from Plitt's equation, keeps ``pressure_factor``).
DIRECT_UNREAD_FACTORS = ("d50c_factor", "sharpness_factor", "split_factor")


@dataclass(frozen=True)
class Hydrocyclone:
    """A cluster of ``count`` hydrocyclones: geometry [cm], the sump's dilution and the model of its
    performance.

    Plitt (default): d50c, pressure, flow split and sharpness from Plitt's equations (module
    constants), each times its calibration factor (``d50c_factor``, ``pressure_factor``,
    ``sharpness_factor``, ``split_factor``: the roles of Moly-Cop Tools's a1-a4, whose values are
    in that tool's own units and do not transfer), water bypass R_f = S / (1 + S) and solids bypass
    ``solids_bypass_frac`` (default R_f, Plitt's assumption that fine solids follow the water).
    Direct: ``d50c_um``, ``sharpness`` and ``water_bypass_frac`` given (a surveyed cyclone), solids
    bypass as above; pressure still from Plitt's equation for the geometry.
    The sump dilutes the mill discharge to ``feed_solids_frac`` (solids mass fraction of the
    cyclone feed, 0.61 not 61) or, when that is None, to ``feed_solids_vol_pct`` % by volume.
    ``curve``: the corrected efficiency curve (:func:`corrected_partition`), ``"plitt"`` (``sharpness``
    Plitt's m; his equations predict it) or, for a cyclone given directly, ``"whiten"`` (``sharpness``
    Whiten's alpha, as JKSimMet reports it). ``surveyed_clay_frac``: the clay (kaolinite + illite) mass
    fraction of the solids its Plitt factors or survey were measured on, the slurry whose cut they state
    with the ``rheology`` effect (0: a clay-free slurry, as Plitt's published equations)."""

    diameter_cm: float = 38.0
    inlet_cm: float = 11.0
    vortex_finder_cm: float = 13.0
    apex_cm: float = 7.5
    free_vortex_height_cm: float = 120.0
    count: int = 2
    feed_solids_vol_pct: float = 30.0
    feed_solids_frac: float | None = None
    viscosity_cp: float = 1.0
    d50c_factor: float = 1.0
    pressure_factor: float = 1.0
    sharpness_factor: float = 1.0
    split_factor: float = 1.0
    d50c_um: float | None = None
    sharpness: float | None = None
    water_bypass_frac: float | None = None
    solids_bypass_frac: float | None = None
    curve: str = "plitt"
    surveyed_clay_frac: float = 0.0
    #: A table's keys beside the fields: a table built into the named dataclass (hydrocyclone_from).
    tables: ClassVar[dict] = {"survey": CycloneSurvey}

    def __post_init__(self):
        o = "Hydrocyclone"
        refuse_bool_fields(o, self)
        for name in ("diameter_cm", "inlet_cm", "vortex_finder_cm", "apex_cm", "free_vortex_height_cm"):
            check_range(o, name, getattr(self, name), 0.0, 1000.0)
        for name in ("inlet_cm", "vortex_finder_cm", "apex_cm"):  # openings in the cyclone's wall, roof and cone
            if not getattr(self, name) < self.diameter_cm:
                raise bad_value(o, name, getattr(self, name), f"below the cyclone's diameter_cm = {self.diameter_cm!r} "
                                "(an opening of the cyclone's body; the same unit, cm)")
        object.__setattr__(self, "count", check_int(o, "count", self.count, 1, 200))
        check_range(o, "feed_solids_vol_pct", self.feed_solids_vol_pct, FEED_SOLIDS_VOL_PCT_MIN,
                    FEED_SOLIDS_VOL_PCT_MAX, lo_open=False)
        if check_range(o, "viscosity_cp", self.viscosity_cp, 0.0, 1e4) < VISCOSITY_MIN_CP:
            raise bad_value(o, "viscosity_cp", self.viscosity_cp, f"at least {VISCOSITY_MIN_CP:g} cP, water's near "
                            "boiling (the liquid's viscosity in cP; Pa s? 1 cP is 0.001 Pa s)")
        for name in ("d50c_factor", "pressure_factor", "sharpness_factor", "split_factor"):
            check_range(o, name, getattr(self, name), 0.0, 1e3)
        # sharpness 0 makes the partition flat (E = R_f + (1 - R_f) / 2 at every size: nothing classified) and was
        # taken while a solids bypass of 0 (no short circuit: a screen, Whiten's curve with R_f = 0) was refused;
        # the water bypass stays above 0: an underflow without water is no slurry
        for name, lo, hi, lo_open in (("feed_solids_frac", 0.0, 1.0, True), ("sharpness", 0.0, 20.0, True),
                                      ("water_bypass_frac", 0.0, 1.0, True), ("solids_bypass_frac", 0.0, 1.0, False)):
            if getattr(self, name) is not None:
                check_range(o, name, getattr(self, name), lo, hi, lo_open=lo_open)
        if self.d50c_um is not None:
            check_d50c(o, self.d50c_um)
        check_range(o, "surveyed_clay_frac", self.surveyed_clay_frac, 0.0, 1.0, lo_open=False)
        if self.curve not in PARTITION_CURVES:
            raise bad_value(o, "curve", self.curve, "one of " + ", ".join(map(repr, PARTITION_CURVES)))
        if self.curve != "plitt" and self.d50c_um is None:  # Plitt's equations predict his own curve's m
            raise bad_value(o, "curve", self.curve, "'plitt' for a cyclone by Plitt's equations or a survey; another "
                            "curve is for a cyclone given directly (d50c_um, sharpness, water_bypass_frac)")
        direct = [n for n in ("d50c_um", "sharpness", "water_bypass_frac") if getattr(self, n) is not None]
        if direct and self.surveyed_clay_frac != 0.0:  # read by nothing: a cut given directly is fixed
            raise bad_value(o, "surveyed_clay_frac", self.surveyed_clay_frac, "0 for a cyclone given directly (its "
                            "d50c is fixed whatever the slurry); it is the slurry of Plitt factors or a survey")
        if direct and len(direct) < 3:
            missing = sorted({"d50c_um", "sharpness", "water_bypass_frac"} - set(direct))
            raise bad_value(o, missing[0], None, "given with " + ", ".join(direct)
                            + " (a cyclone given directly needs d50c_um, sharpness and water_bypass_frac)")
        for name in DIRECT_UNREAD_FACTORS if direct else ():  # read by nothing: a factor of 1.5 changed no number
            if getattr(self, name) != 1.0:
                raise bad_value(o, name, getattr(self, name), "1 for a cyclone given directly (d50c_um, sharpness, "
                                "water_bypass_frac): only Plitt's equations read it; remove it, or give the "
                                "cyclone's geometry and factors for Plitt's equations")

    @property
    def mode(self) -> str:
        return "direct" if self.d50c_um is not None else "plitt"

    def feed_volume_pct(self, solids_density_t_m3: float) -> float:
        """Solids % by volume of the cyclone feed."""
        if self.feed_solids_frac is None:
            return self.feed_solids_vol_pct
        if isinstance(solids_density_t_m3, (ca.SX, ca.MX)):  # a stream's own density; checked at the nominal one
            return solids_volume_pct(self.feed_solids_frac, solids_density_t_m3)
        return _check_feed_vol_pct("Hydrocyclone", "feed_solids_frac", self.feed_solids_frac,
                                   f"a solids mass fraction that makes, at the solids' {solids_density_t_m3:g} t/m3,",
                                   solids_volume_pct(self.feed_solids_frac, solids_density_t_m3))

    def plitt(self, slurry_flow_m3_h, solids_density_t_m3: float) -> dict:
        """Plitt's d50c [um], sharpness m, pressure [kPa], volumetric split S = Qu/Qo and water
        bypass R_f = S/(1+S) (each with its factor; the given values in the direct mode), for the
        total slurry flow [m3/h] shared by ``count`` cyclones. Floats or CasADi expressions."""
        if not isinstance(slurry_flow_m3_h, (ca.SX, ca.MX)):  # q**0.45 of a negative flow is complex, of 0 inf
            check_range("Hydrocyclone.plitt", "slurry_flow_m3_h", slurry_flow_m3_h, 0.0, math.inf)
        symbolic = isinstance(solids_density_t_m3, (ca.SX, ca.MX))  # a stream's own density (checked at nominal)
        if not symbolic:
            check_range("Hydrocyclone.plitt", "solids_density_t_m3", solids_density_t_m3, WATER_DENSITY_T_M3, 25.0)
        exp = ca.exp if symbolic else math.exp
        q = slurry_flow_m3_h * 1000.0 / 60.0 / self.count  # L/min per cyclone
        dc, di, do, du, h = (self.diameter_cm, self.inlet_cm, self.vortex_finder_cm,
                             self.apex_cm, self.free_vortex_height_cm)
        phi = self.feed_volume_pct(solids_density_t_m3)
        p_kpa = self.pressure_factor * PLITT_PRESSURE * q ** 1.78 * exp(0.0055 * phi) / (
            dc ** 0.37 * di ** 0.94 * h ** 0.28 * (du ** 2 + do ** 2) ** 0.87)
        if self.mode == "direct":
            rf = self.water_bypass_frac
            return {"d50c_um": self.d50c_um + 0 * q, "sharpness_m": self.sharpness + 0 * q, "pressure_kpa": p_kpa,
                    "volume_split": rf / (1.0 - rf) + 0 * q, "water_bypass_frac": rf + 0 * q}
        d50c = (self.d50c_factor * PLITT_D50C * dc ** 0.46 * di ** 0.6 * do ** 1.21 * self.viscosity_cp ** 0.5
                * exp(0.063 * phi)
                / (du ** 0.71 * h ** 0.38 * q ** 0.45 * (solids_density_t_m3 - WATER_DENSITY_T_M3) ** 0.5))
        rho_slurry = WATER_DENSITY_T_M3 + phi / 100.0 * (solids_density_t_m3 - WATER_DENSITY_T_M3)
        head_m = p_kpa / (G_M_S2 * rho_slurry)
        split = (self.split_factor * PLITT_SPLIT * (du / do) ** 3.31 * h ** 0.54 * (du ** 2 + do ** 2) ** 0.36
                 * exp(0.0054 * phi) / (head_m ** 0.24 * dc ** 1.11))
        m = self.sharpness_factor * PLITT_SHARPNESS * _exp(-1.58 * split / (1 + split)) * (dc ** 2 * h / q) ** 0.15
        return {"d50c_um": d50c, "sharpness_m": m, "pressure_kpa": p_kpa,
                "volume_split": split, "water_bypass_frac": split / (1.0 + split)}

    def solids_bypass(self, water_bypass):
        return water_bypass if self.solids_bypass_frac is None else self.solids_bypass_frac


#: Flintoff, Plitt & Turak (1987): one factor per Plitt equation, each the surveyed value over the
#: equation's, in this order (the split reads the pressure's head, the sharpness the split).
SURVEY_FACTORS = (("pressure_factor", "pressure_kpa"), ("split_factor", "volume_split"),
                  ("sharpness_factor", "sharpness_m"), ("d50c_factor", "d50c_um"))


def calibrate_plitt(cyclone: Hydrocyclone, survey: CycloneSurvey) -> Hydrocyclone:
    """``cyclone`` with the Plitt factors (:data:`SURVEY_FACTORS`) at which its equations give the
    survey's performance at the survey's feed (its geometry and count; its own sump dilution kept)."""
    rho, rf = survey.solids_density_t_m3, survey.water_bypass_frac
    target = {"pressure_kpa": survey.kpa, "volume_split": rf / (1.0 - rf), "sharpness_m": survey.sharpness,
              "d50c_um": survey.d50c_um}
    at = replace(cyclone, feed_solids_frac=survey.feed_solids_frac, **{f: 1.0 for f, _ in SURVEY_FACTORS})
    for factor, key in SURVEY_FACTORS:
        at = replace(at, **{factor: target[key] / float(at.plitt(survey.slurry_m3_h, rho)[key])})
    return replace(cyclone, **{f: getattr(at, f) for f, _ in SURVEY_FACTORS})


#: What a surveyed cyclone may not also give: its factors come from the survey.
_NOT_WITH_SURVEY = tuple(f for f, _ in SURVEY_FACTORS) + ("d50c_um", "sharpness", "water_bypass_frac")


def hydrocyclone_from(value) -> Hydrocyclone:
    """A Hydrocyclone, or one built from a table of its fields (errors name the field); a table
    with a ``survey`` (a CycloneSurvey's fields) gets Plitt's factors from it (:func:`calibrate_plitt`)
    and, unless it sets the sump's dilution, the survey's."""
    if isinstance(value, Hydrocyclone):
        return value
    where = "the 'cyclone' option of effect 'classification'"
    _refuse_unknown(value, list(Hydrocyclone.__dataclass_fields__) + list(Hydrocyclone.tables), where)
    table = dict(value)
    survey = table.pop("survey", None)
    if survey is None:
        return Hydrocyclone(**table)
    if not isinstance(survey, dict):
        raise ModelError(f"The 'survey' of {where} must be a table of "
                         f"{', '.join(CycloneSurvey.__dataclass_fields__)}. Got {survey!r}.")
    if "count" not in table:  # the survey's feed is the whole cluster's: a default count would misplace it
        raise ModelError(f"{where}: a cyclone with a 'survey' needs its 'count', the number of cyclones the "
                         "surveyed feed was shared by.")
    clash = [k for k in _NOT_WITH_SURVEY if k in table]
    if clash:
        raise ModelError(f"{where}: {clash[0]!r} and 'survey' are given together; a surveyed cyclone's Plitt factors "
                         "come from its survey (give one or the other).")
    _refuse_unknown(survey, CycloneSurvey.__dataclass_fields__, f"the 'survey' of {where}")
    survey = CycloneSurvey(**survey)
    if "feed_solids_frac" not in table and "feed_solids_vol_pct" not in table:
        table["feed_solids_frac"] = survey.feed_solids_frac
    return calibrate_plitt(Hydrocyclone(**table), survey)


def _refuse_unknown(table: dict, known, where: str) -> None:
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise ModelError(f"Unknown field {unknown[0]!r} of {where}.{close_matches(unknown[0], known)} Fields: "
                         f"{', '.join(known)}.")


def grate_factor(size_um: np.ndarray, d50_um: float, sharpness: float) -> np.ndarray:
    return 1.0 / (1.0 + (np.asarray(size_um) / d50_um) ** sharpness)


#: Stokes' law: the cut size of a settling classifier scales as (rho_s - rho_w)^-1/2 (as Plitt's d50c).
STOKES_DENSITY_EXPONENT = -0.5


def stokes_cut_ratio(solids_density_t_m3, reference_density_t_m3):
    """The cut size of particles of one density over that of particles of another in the same settling
    classifier (Stokes): ((rho_s - rho_w) / (rho_ref - rho_w))^-1/2. Floats or CasADi expressions."""
    return ((solids_density_t_m3 - WATER_DENSITY_T_M3)
            / (reference_density_t_m3 - WATER_DENSITY_T_M3)) ** STOKES_DENSITY_EXPONENT


def component_cut_ratios(spec, stream_density_t_m3) -> list | None:
    """Each component's cut over the cut stated at ``stream_density_t_m3`` (:func:`stokes_cut_ratio`);
    None when the components share the nominal density (one cut for all)."""
    if spec.volume_weights() is None:
        return None
    return [stokes_cut_ratio(r, stream_density_t_m3) for r in spec.component_density_t_m3]


def _stream_density_ratio(ctx, stream):
    """A stream's solids density over the nominal one (``stream``: its flow per component [t/h] per class)."""
    weights = ctx.spec.volume_weights()
    if weights is None:
        return 1.0
    packed = sum(w * ca.sum1(sc) for w, sc in zip(weights, stream))
    return ctx.density_ratio(sum(ca.sum1(sc) for sc in stream), packed, 1e-6 * ctx.spec.feed_nominal_tph)


def grate_density_factor(solids_density_t_m3: float) -> float:
    """The grate's cut size at an ore density over its cut for a quartz slurry (module docstring):
    ((rho_s - rho_w) / (rho_quartz - rho_w))^-1/2."""
    return stokes_cut_ratio(solids_density_t_m3, DISCHARGE_REFERENCE_DENSITY_T_M3)


class Classification(Effect):
    name = "classification"
    requires = ("transport",)
    provides = ("discharge_class_factor", "product_split", "flow_multiplier", "feed_to_classifier")
    outputs = ("cyclone_d50c_um", "circulating_load_frac", "cyclone_feed_tph", "cyclone_underflow_tph",
               "cyclone_pressure_kpa", "cyclone_sharpness", "cyclone_water_bypass_frac", "cyclone_feed_solids_frac",
               "overflow_solids_frac", "underflow_solids_frac", "overflow_water_m3_h", "sump_water_m3_h",
               "mill_water_m3_h", "underflow_solids_density_t_m3", "ore_underflow_tph")
    uses = ("cut_size_factor", "cut_size_factor_at")
    source = ("Austin et al. (1984) ch. 9 (grate), Stokes settling (its density term); Plitt (1976), "
              "Flintoff et al. (1987) (hydrocyclone)")
    summary = ("grate discharge factor, cut ~ (rho_s - 1)^-1/2, or hydrocyclone closed circuit with recycle "
               "to the feed")
    options = {
        "kind": Option("grate", "'grate' (internal classification at the discharge) or 'hydrocyclone' "
                       "(closed circuit, underflow to the mill feed)", choices=("grate", "hydrocyclone")),
        "circulating_load_nominal": Option(2.5, "underflow / fresh feed at nominal (hydrocyclone)", float,
                                           lo=0.0, hi=50.0),
        "circuit": Option("direct", "'direct' (fresh feed to the mill with the underflow) or 'reverse' (fresh feed "
                          "to the cyclone feed sump, the mill fed by the underflow alone: the ball mill of most "
                          "SAG-ball circuits) (hydrocyclone)", choices=CYCLONE_CIRCUITS),
        "fresh_feed_solids_frac": Option(None, "solids mass fraction of the fresh feed slurry (0.7, not 70) "
                                         "entering the sump of a reverse circuit; None: the feed's water is "
                                         "counted in the sump's water addition (hydrocyclone, reverse)",
                                         (float, type(None)), lo=0.0, hi=1.0),
        "cyclone": Option(None, "hydrocyclone geometry, feed dilution and model (hydrocyclone): a Hydrocyclone "
                          "or a table of its fields, which may hold a 'survey' table (feed_solids_tph, "
                          "feed_water_m3_h, solids_density_t_m3, d50c_um, sharpness, water_bypass_frac, "
                          "pressure_kpa or pressure_psi) that gives Plitt's factors; None: the mill's own "
                          "(Mill.cyclone), else Hydrocyclone()",
                          (Hydrocyclone, dict, type(None))),
    }

    #: Options only a hydrocyclone circuit reads (beside 'circuit' and 'fresh_feed_solids_frac',
    #: checked below): given with a grate they changed nothing, silently.
    GRATE_UNREAD = ("circulating_load_nominal", "cyclone")

    def __init__(self, **options):
        super().__init__(**options)
        unread = [k for k in self.GRATE_UNREAD if options.get(k) is not None]
        if self.settings["kind"] == "grate" and unread:
            raise ModelError(f"Effect 'classification': {', '.join(map(repr, unread))} "
                             f"{'is an option' if len(unread) == 1 else 'are options'} of kind = 'hydrocyclone', "
                             "which a grate (the default kind) does not read. Set 'kind' = 'hydrocyclone' or leave "
                             f"{'it' if len(unread) == 1 else 'them'} out.")
        reverse = self.settings["circuit"] == "reverse"
        if self.settings["kind"] == "grate" and (reverse or self.settings["fresh_feed_solids_frac"] is not None):
            raise ModelError("Effect 'classification': 'circuit' = 'reverse' and 'fresh_feed_solids_frac' are "
                             "options of kind = 'hydrocyclone' (a grate classifies inside the mill).")
        if not reverse and self.settings["fresh_feed_solids_frac"] is not None:
            raise ModelError("Effect 'classification': 'fresh_feed_solids_frac' is the slurry a reverse circuit's "
                             "fresh feed brings to the sump; a direct circuit's feed water is the mill's addition. "
                             "Set 'circuit' = 'reverse' or leave it out.")

    def apply(self, ctx: EffectContext) -> None:
        if self.settings["kind"] == "grate":
            self._grate(ctx)
        else:
            self._hydrocyclone(ctx, self.settings["circuit"] == "reverse")

    def _grate(self, ctx: EffectContext) -> None:
        spec = ctx.spec
        x = spec.grid.mid_um
        d50 = ctx.param("grate_d50_um", spec.mill.grate_d50_um, "um", "mill (quartz slurry)")
        k = ctx.param("grate_sharpness", spec.mill.grate_sharpness, "-", "mill")
        density = ctx.param("grate_density_factor", grate_density_factor(spec.solids_density_t_m3), "-",
                            "Stokes: ((rho_s - 1) / (rho_quartz - 1))^-1/2")
        slurry = ctx.get("cut_size_factor", 1.0)
        ratios = component_cut_ratios(spec, spec.solids_density_t_m3)  # each ore at its own density
        factors = [self._grate_factor(x, d50, k, slurry * density * r) for r in ratios or [1.0]]
        ctx.provide("discharge_class_factor", factors if ratios else factors[0])
        ctx.note(f"grate factor on the last mixer's discharge, d50 {d50:g} um (quartz slurry) x {density:.3f} "
                 "for the ore's density" + (" (each ore at its own)" if ratios else ""))

    @staticmethod
    def _grate_factor(x, d50, k, cut):
        """The grate's discharge factor per size class at cut size d50 x ``cut`` (the sink always leaves)."""
        if isinstance(cut, float):
            c = grate_factor(x, d50 * cut, k)
        else:  # a cut size that moves with the states (rheology)
            ratio = (x / d50) ** k  # SX when d50 or k is a symbol (a parametric model)
            c = 1.0 / (1.0 + (ratio if isinstance(ratio, ca.SX) else ca.DM(ratio)) * cut ** -k)
        c[-1] = 1.0
        return c

    def _hydrocyclone(self, ctx: EffectContext, reverse: bool) -> None:
        spec = ctx.spec
        cl = self.settings["circulating_load_nominal"]
        s_f = self.settings["fresh_feed_solids_frac"]
        cyc = circuit_cyclone(spec)
        rho = spec.solids_density_t_m3
        solids_nom = spec.feed_nominal_tph * (1.0 + cl)  # cyclone feed solids at nominal (D + F = F + U reverse)
        at_nominal = cyc.plitt(slurry_m3_h(cyc, solids_nom, rho), rho)
        for key, val in at_nominal.items():
            ctx.param(f"cyclone_{key}", float(val), "", f"{cyc.mode} cyclone at nominal feed")
        ctx.provide("flow_multiplier", cl if reverse else 1.0 + cl)  # the mill's through-flow over the feed
        ctx.provide("feed_to_classifier", reverse)
        xs = ca.DM(spec.grid.mid_um)
        cut = _cyclone_cut_factor(ctx, cyc)
        s_d = spec.mill.discharge_solids_frac
        feed_floor = 1e-6 * spec.feed_nominal_tph

        def split(discharge, fresh=None):
            """The cyclones' overflow and underflow per component of the mill discharge (with the
            fresh feed ``fresh`` in a reverse circuit)."""
            stream = discharge if fresh is None else [dc + fc for dc, fc in zip(discharge, fresh)]
            solids = sum(ca.sum1(dc) for dc in stream)
            rho_s = rho * _stream_density_ratio(ctx, stream)  # the stream's own density (Plitt's d50c reads it)
            state = cyc.plitt(slurry_m3_h(cyc, smooth_max(solids, 1e-3 * solids_nom, 1e-3 * solids_nom), rho_s), rho_s)
            d50 = state["d50c_um"] * cut
            rf = state["water_bypass_frac"]
            rs = cyc.solids_bypass(rf)
            def partition(d50_um):  # to the underflow, per size class
                return rs + (1.0 - rs) * corrected_partition(xs / d50_um, state["sharpness_m"], cyc.curve)

            ratios = component_cut_ratios(spec, rho_s)  # each ore at its own density
            if ratios is None:
                e = partition(d50)
                under = [e * dc for dc in stream]
            else:
                under = [partition(d50 * r) * dc for r, dc in zip(ratios, stream)]
            over = [dc - uc for dc, uc in zip(stream, under)]
            fresh_water = 0.0 if fresh is None or s_f is None else sum(ca.sum1(fc) for fc in fresh) * (1.0 - s_f) / s_f
            _water_balance(ctx, cyc, solids, sum(ca.sum1(dc) for dc in discharge), fresh_water,
                           sum(ca.sum1(u) for u in under), rf, rho_s, s_d, feed_floor)
            if spec.volume_weights() is not None:  # the underflow's own density (its roping is by volume)
                ctx.output("underflow_solids_density_t_m3", rho * _stream_density_ratio(ctx, under))
            ctx.output("cyclone_d50c_um", d50)
            ctx.output("cyclone_feed_tph", sum(stream))  # per size class, as the underflow below
            ctx.output("cyclone_underflow_tph", sum(under))
            ctx.output("cyclone_pressure_kpa", state["pressure_kpa"])
            ctx.output("cyclone_sharpness", state["sharpness_m"])
            ctx.output("cyclone_water_bypass_frac", rf)
            ctx.output("circulating_load_frac", sum(ca.sum1(u) for u in under) / smooth_max(
                ctx.feed_tph, feed_floor, feed_floor))
            if len(under) > 1:  # each ore's underflow [t/h], a column: a dense ore, cut finer, circulates more
                ctx.output("ore_underflow_tph", ca.vertcat(*[ca.sum1(u) for u in under]))
            return over, under

        ctx.provide("product_split", split)
        factors = plitt_factors_text(plitt_factors(cyc), calibrated_only=True)
        ctx.note(f"hydrocyclone ({cyc.mode}): d50c {float(at_nominal['d50c_um']):.0f} um, "
                 f"{'Whiten alpha' if cyc.curve == 'whiten' else 'm'} "
                 f"{float(at_nominal['sharpness_m']):.2f}, water bypass {float(at_nominal['water_bypass_frac']):.2f} "
                 "at nominal" + (f" (Plitt factors {factors})" if factors else "")
                 + ("; reverse circuit: fresh feed to the cyclones" if reverse else "")
                 + "; underflow to mixer 0; water balance")


def _cyclone_cut_factor(ctx: EffectContext, cyc: Hydrocyclone):
    """The slurry's factor on a cyclone's cut (module docstring): none for one given directly; against the
    slurry its calibration was measured on (``surveyed_clay_frac``) for Plitt's equations. A property of the
    cyclone, not of a run: a reference taken from a run's initial feed made a sweep over the feed blend
    cancel the clay's effect at each case's start (the same plant fed D gave 124 or 201 um)."""
    if cyc.mode == "direct":
        return 1.0
    at = ctx.get("cut_size_factor_at", None)
    return ctx.get("cut_size_factor", 1.0) / (at(cyc.surveyed_clay_frac) if at is not None else 1.0)


def circuit_cyclone(spec) -> Hydrocyclone | None:
    """The hydrocyclones of a model spec's circuit (its classification option, else its mill's
    own), or None when it has none (no classification effect, or a grate)."""
    if "classification" not in spec.effects:
        return None
    options = spec.effect_options.get("classification") or {}
    if options.get("kind", Classification.options["kind"].default) != "hydrocyclone":
        return None
    given = options.get("cyclone")
    return hydrocyclone_from(dict(spec.mill.cyclone or {}) if given is None else given)


def solids_volume_pct(solids_mass_frac, solids_density_t_m3: float):
    """Solids % by volume of a slurry of solids mass fraction ``solids_mass_frac`` in water."""
    c, rho = solids_mass_frac, solids_density_t_m3
    return 100.0 * (c / rho) / (c / rho + (1.0 - c) / WATER_DENSITY_T_M3)


#: The keys of a sized cyclone cluster (its geometry, count and sump dilution): a scene's cyclone table without
#: them runs Hydrocyclone's defaults in their place (:func:`sized_circuit_notes`).
SIZED_CYCLONE_KEYS = ("diameter_cm", "inlet_cm", "vortex_finder_cm", "apex_cm", "free_vortex_height_cm", "count",
                      "feed_solids_vol_pct")


def sized_circuit_notes(spec) -> list[str]:
    """What a model spec runs of a mill sized in closed circuit with hydrocyclones (``Mill.cyclone``)
    that is not the sized circuit: its grate discharge, or its own cyclones in the other circuit
    (``Mill.cyclone_circuit``); its numbers are then not those it was sized for."""
    mill = spec.mill
    if "classification" not in spec.effects or not mill.cyclone:
        return []
    options = spec.effect_options.get("classification") or {}
    if options.get("kind", Classification.options["kind"].default) != "hydrocyclone":
        return [f"mill {mill.name!r} was sized with a hydrocyclone circuit; this is its grate discharge (the "
                "calibration's effects); a scene with effect_options.classification.kind = \"hydrocyclone\" "
                "runs the sized circuit"]
    circuit = options.get("circuit", Classification.options["circuit"].default)
    given = options.get("cyclone")
    if isinstance(given, dict) and "d50c_um" not in given:  # Plitt's: a table sweeping one key ran 2 x 38 cm, unsaid
        sized = dict(mill.cyclone)
        defaulted = [k for k in SIZED_CYCLONE_KEYS if k not in given and k not in given.get("survey", {})
                     and sized.get(k) is not None]
        if defaulted:
            return [f"the scene's cyclone table replaces mill {mill.name!r}'s sized cyclones whole: the keys it leaves "
                    "out take Hydrocyclone's defaults, not the sized ones (" + ", ".join(
                        f"{k} {getattr(Hydrocyclone, k)!r} for {sized[k]:.4g}" for k in defaulted) + ")"]
    if given is None and circuit != mill.cyclone_circuit:
        return [f"mill {mill.name!r} and its cyclones were sized in a {mill.cyclone_circuit} circuit; this runs them "
                f"in a {circuit} one (effect_options.classification.circuit = \"{mill.cyclone_circuit}\" runs the "
                "sized circuit)"]
    return []


def plitt_factors(cyc: Hydrocyclone) -> dict:
    """A Plitt cyclone's four calibration factors by name (empty for one given directly)."""
    return {} if cyc.mode == "direct" else {f: getattr(cyc, f) for f, _ in SURVEY_FACTORS}


def plitt_factors_text(factors: dict, calibrated_only: bool = False) -> str:
    """``factors`` (:func:`plitt_factors`) as "pressure 0.46, split 2.05, ..."; with
    ``calibrated_only`` only those not 1 (the empty string when none is)."""
    return ", ".join(f"{f.removesuffix('_factor')} {v:.4g}" for f, v in factors.items()
                     if not (calibrated_only and v == 1.0))


def slurry_m3_h(cyc: Hydrocyclone, solids_tph, rho):
    """Cyclone feed slurry [m3/h] for a solids flow [t/h] diluted at the sump."""
    phi = cyc.feed_volume_pct(rho) / 100.0
    return solids_tph / rho / phi


def _water_balance(ctx, cyc, solids, discharge_solids, fresh_water, under_solids, rf, rho, s_d, floor):
    """Water [m3/h] and solids fractions of the circuit's streams: the mill discharge at the mill's
    solids fraction (and a reverse circuit's fresh feed with ``fresh_water`` [t/h]) enter the sump,
    which adds water to the cyclone feed's; the cyclone sends R_f of the feed water to the
    underflow; the mill's feed water is what the discharge holds less the underflow's."""
    phi = cyc.feed_volume_pct(rho) / 100.0
    feed_water = solids / rho * (1.0 - phi) / phi * WATER_DENSITY_T_M3
    discharge_water = discharge_solids * (1.0 - s_d) / s_d
    under_water, over_water = rf * feed_water, (1.0 - rf) * feed_water
    over_solids = solids - under_solids
    ctx.output("cyclone_feed_solids_frac", solids / smooth_max(solids + feed_water, floor, floor))
    ctx.output("overflow_solids_frac", over_solids / smooth_max(over_solids + over_water, floor, floor))
    ctx.output("underflow_solids_frac", under_solids / smooth_max(under_solids + under_water, floor, floor))
    ctx.output("overflow_water_m3_h", over_water / WATER_DENSITY_T_M3)
    ctx.output("sump_water_m3_h", (feed_water - discharge_water - fresh_water) / WATER_DENSITY_T_M3)
    ctx.output("mill_water_m3_h", (discharge_water - under_water) / WATER_DENSITY_T_M3)
