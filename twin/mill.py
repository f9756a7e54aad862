"""Mill geometry, charge and nominal operating point; presets for the laboratory and an
industrial mill.

Units: m, t, t/m3, t/h, fraction of critical speed.
"""

from __future__ import annotations

import json
import math
from numbers import Real
from dataclasses import dataclass, fields, replace
from functools import cache
from pathlib import Path

from .errors import TwinInputError, bad_value, check_range, close_matches
from .ore.minerals import mineral_table

G_M_S2 = 9.80665
#: The solids density [t/m3] the mills' ``discharge_factor`` is stated at: a quartz slurry
#: (twin/ore/data/minerals.csv; Mill.free_discharge_tph).
DISCHARGE_REFERENCE_DENSITY_T_M3 = mineral_table()["quartz"].density_t_m3
#: Densities a grinding ball may have [t/m3]: alumina ceramic (~3.6) to tungsten carbide (~15);
#: beyond, the value is in kg/m3 (7800 for steel's 7.8).
BALL_DENSITY_RANGE_T_M3 = (1.0, 25.0)
#: The smallest make-up ball size of a tumbling ball mill [mm]: regrind mills' balls are ~12 mm (1/2 in), finer
#: media (1-6 mm beads) belong to stirred mills; below, the value is in m (0.025 for 25 mm) or inches (1 for 25.4).
BALL_SIZE_MIN_MM = 10.0
#: The largest make-up ball [mm]: primary ball mills take up to 100-125 mm (4-5 in; Rowland's top-size formula);
#: 200 leaves room, more is not a ball mill's ball (um for mm).
BALL_SIZE_MAX_MM = 200.0
#: Feed rates a twin takes are below this [t/h]: twenty times the largest ball-mill circuits' (~5,000
#: t/h); a rate in kg/h of such a circuit lands above it.
FEED_TPH_MAX = 1e5
#: The speed [fraction of critical] at which Austin's speed factor (eq. 8.4) is zero; below it the
#: factor, and every breakage rate it multiplies, is negative: the slowest speed the twin describes.
SPEED_FACTOR_ZERO_FRAC_CRITICAL = 0.1
#: The largest ball diameter over the mill's diameter: the power and breakage models treat the balls as a bed
#: (Bond's power per tonne of balls, Austin's rates), and a laboratory mill holds some 8 balls across (Bond's
#: 305 mm test mill with balls up to 36.8 mm; Bond 1961): a fifth leaves room for that, a larger ball is a slip.
BALL_MILL_DIAMETER_RATIO_MAX = 0.2
#: The most net energy a ball mill spends per tonne of its feed [kWh/t]: Bond's law, 10 Wi (P80^-1/2 - F80^-1/2)
#: (Bond 1961, sizes in um), for the hardest ores (Wi ~50 kWh/t) ground to a P80 of 1 um, 10 x 50 x 1; a draw
#: in W for kW is 1000 times the mill's.
SPECIFIC_ENERGY_MAX_KWH_T = 500.0
#: The smallest grate cut size [um]: the calibrations fit the laboratory grate's within 10-3000 um
#: (twin/calibration/fitted.py); finer particles follow the water. Below, the cut is in mm (0.5 for 500 um).
GRATE_D50_MIN_UM = 10.0
#: Where a closed circuit's fresh feed enters: the mill (direct) or the cyclones' sump (reverse).
CYCLONE_CIRCUITS = ("direct", "reverse")
#: The net-power models a Mill may name (functions in :data:`POWER_MODELS`).
POWER_MODEL_NAMES = ("bond", "hogg_fuerstenau")


@dataclass(frozen=True)
class Mill:
    """A ball mill. ``power_factor`` scales Bond's power equation where it is extrapolated
    (a laboratory mill below the ~1 m diameters it was fitted to; Rowland & Kjos 1980); it is
    fitted by `grindtwin calibrate`, never typed in. ``grate_d50_um`` is the grate's cut size for a
    quartz slurry (a denser ore's is finer by Stokes, twin.effects.classification).
    ``powder_filling_nominal`` is Austin's U: the fraction of the ball bed's
    voids filled by powder at the nominal hold-up; ``stable_band`` the load (hold-up over
    nominal hold-up) within which the mill is called stable. ``discharge_factor`` is the
    mill's free discharge at nominal hold-up over its nominal feed, before a grate holds coarse
    particles back (a grate mill at nominal load passes less than it could; the V_Pmo of le
    Roux et al. 2013), for a quartz slurry: the discharge is a volume flow
    (:meth:`free_discharge_tph`); fitted for the lab mill by `grindtwin calibrate`.

    ``ball_size_mm`` is the make-up ball size (Austin's scale-up factors on S, twin.scaleup);
    ``discharge_solids_frac`` the solids mass fraction of the mill discharge (0.72, not 72), which
    the mill's feed water holds (the circuit's water balance, twin.effects.classification).
    ``power_model`` names the net-power model (:data:`POWER_MODELS`); ``net_power_kw``, when
    given, is the net power at the nominal speed (a measured or published draw), and the model
    then only shapes how power moves with speed. ``cyclone`` is the hydrocyclone cluster the mill
    is sized with (its twin.Hydrocyclone fields as (name, value) pairs; the classification effect's
    default when it runs a hydrocyclone circuit), empty when none; ``cyclone_circuit`` the circuit
    it was sized in (twin.sizing.CIRCUITS: fresh feed to the mill, ``"direct"``, or to the
    cyclones' sump, ``"reverse"``), which a twin running another says
    (twin.effects.classification.sized_circuit_notes). ``sized_calibration`` names the calibration a sized
    mill was sized under ('' for a mill not sized), which a twin under another says (its breakage, so the
    sizing's P80 and throughput, are another's)."""

    name: str
    diameter_m: float
    length_m: float
    ball_filling_frac: float = 0.35
    ball_density_t_m3: float = 7.8
    bed_porosity: float = 0.4
    powder_filling_nominal: float = 1.0
    speed_nominal_frac_critical: float = 0.70
    stable_band: tuple = (0.8, 1.2)
    grate_d50_um: float = 400.0
    grate_sharpness: float = 3.0
    discharge_exponent: float = 2.0
    discharge_factor: float = 1.0
    feed_nominal_tph: float = 0.031
    power_factor: float = 1.0
    ball_size_mm: float = 25.0
    discharge_solids_frac: float = 0.70
    power_model: str = "bond"
    net_power_kw: float | None = None
    cyclone: tuple = ()
    cyclone_circuit: str = "direct"
    sized_calibration: str = ""

    def __post_init__(self):
        o = f"Mill {self.name!r}"
        refuse_bool_fields(o, self)
        check_range(o, "diameter_m", self.diameter_m, 0.0, 20.0)
        check_range(o, "length_m", self.length_m, 0.0, 30.0)
        check_range(o, "ball_filling_frac", self.ball_filling_frac, 0.0, 0.5)
        # 7800 (kg/m3) drew a thousand times the power: 335 kW from the 0.5 m laboratory mill
        check_range(o, "ball_density_t_m3", self.ball_density_t_m3, *BALL_DENSITY_RANGE_T_M3)
        check_range(o, "bed_porosity", self.bed_porosity, 0.0, 1.0)
        check_range(o, "powder_filling_nominal", self.powder_filling_nominal, 0.0, 3.0)
        # at or below 0.1 Austin's speed factor, by which the rates are normalised at the nominal speed, is zero or
        # negative: 0.05 gave negative breakage rates (a percent slip, 70 for 0.70, is above 1)
        check_range(o, "speed_nominal_frac_critical", self.speed_nominal_frac_critical,
                    SPEED_FACTOR_ZERO_FRAC_CRITICAL, 1.0)
        try:
            lo, hi = (float(v) for v in self.stable_band)
        except (TypeError, ValueError):
            raise bad_value(o, "stable_band", self.stable_band, "a pair (lo, hi) with 0 < lo < 1 < hi") from None
        if not 0 < lo < 1 < hi:
            raise bad_value(o, "stable_band", self.stable_band, "a pair (lo, hi) with 0 < lo < 1 < hi")
        object.__setattr__(self, "stable_band", (lo, hi))  # a copy: the caller's list edited later skipped this check
        # 0.5 (mm) held every class back: a hold-up of 2e9 t in a 0.08 t mill and a P80 of 69 um
        check_range(o, "grate_d50_um", self.grate_d50_um, GRATE_D50_MIN_UM, 1e6, lo_open=False)
        check_range(o, "grate_sharpness", self.grate_sharpness, 0.0, 50.0)
        check_range(o, "discharge_exponent", self.discharge_exponent, 0.0, 10.0)
        check_range(o, "discharge_factor", self.discharge_factor, 0.0, 100.0)
        check_range(o, "feed_nominal_tph", self.feed_nominal_tph, 0.0, 1e5)
        check_range(o, "power_factor", self.power_factor, 0.0, 10.0)
        # 0.025 (m) scaled the calibrated breakage rates by Austin's ball-size rule a thousandfold
        check_range(o, "ball_size_mm", self.ball_size_mm, BALL_SIZE_MIN_MM, BALL_SIZE_MAX_MM, lo_open=False)
        ball_max_mm = BALL_MILL_DIAMETER_RATIO_MAX * 1000.0 * self.diameter_m
        if self.ball_size_mm > ball_max_mm:  # a 25 mm ball in a 0.02 m mill (cm for m) was a mill
            raise bad_value(o, "ball_size_mm", self.ball_size_mm, f"at most {BALL_MILL_DIAMETER_RATIO_MAX:g} of the "
                            f"mill's diameter ({ball_max_mm:.4g} mm of diameter_m {self.diameter_m:g}): a bed of balls")
        check_range(o, "discharge_solids_frac", self.discharge_solids_frac, 0.0, 1.0)
        if self.cyclone_circuit not in CYCLONE_CIRCUITS:
            raise bad_value(o, "cyclone_circuit", self.cyclone_circuit,
                            "one of " + ", ".join(map(repr, CYCLONE_CIRCUITS)))
        if self.power_model not in POWER_MODEL_NAMES:
            raise bad_value(o, "power_model", self.power_model, "one of " + ", ".join(map(repr, POWER_MODEL_NAMES)))
        if self.net_power_kw is not None:
            check_range(o, "net_power_kw", self.net_power_kw, 0.0, 1e5)
            # 500 (W) on the 0.5 m laboratory mill drew 500 kW, 16,000 kWh/t of its feed, without a word
            power_max = SPECIFIC_ENERGY_MAX_KWH_T * self.feed_nominal_tph
            if self.net_power_kw > power_max:
                raise bad_value(o, "net_power_kw", self.net_power_kw, f"at most {power_max:.4g} kW, "
                                f"{SPECIFIC_ENERGY_MAX_KWH_T:g} kWh/t of the nominal feed "
                                f"{self.feed_nominal_tph:g} t/h (the net draw in kW, not W)")

    @property
    def volume_m3(self) -> float:
        return math.pi * self.diameter_m ** 2 / 4.0 * self.length_m

    @property
    def ball_bulk_density_t_m3(self) -> float:
        return self.ball_density_t_m3 * (1.0 - self.bed_porosity)

    def critical_speed_rpm(self, ball_diameter_m: float = 0.0) -> float:
        """Critical speed [rpm]: the centrifugal force on a ball at the shell equals its weight,
        n_c = (60 / 2 pi) sqrt(2 g / (D - d)) (Wills & Finch 2016, eq. 7.3)."""
        check_range("Mill.critical_speed_rpm", "ball_diameter_m", ball_diameter_m, 0.0, self.diameter_m,
                    lo_open=False)  # 25 (mm for m) was a bare math domain error
        return 60.0 / (2 * math.pi) * math.sqrt(2 * G_M_S2 / (self.diameter_m - ball_diameter_m))

    def nominal_holdup_t(self, solids_density_t_m3: float) -> float:
        """Ore hold-up [t] at the nominal powder filling: U * bed voids * ball-bed volume *
        packed-powder density (packed at the bed porosity; Austin et al. 1984, ch. 8)."""
        bed_volume = self.ball_filling_frac * self.volume_m3
        return (self.powder_filling_nominal * self.bed_porosity * bed_volume
                * solids_density_t_m3 * (1.0 - self.bed_porosity))

    def max_holdup_t(self, solids_density_t_m3: float) -> float:
        """Ore hold-up [t] of the mill filled to its shell with powder packed at the bed
        porosity around its balls: (mill volume - the balls' solid volume) * packed-powder
        density. A steady state holding more is the model's extrapolation: the mill overflows."""
        free = self.volume_m3 * (1.0 - self.ball_filling_frac * (1.0 - self.bed_porosity))
        return free * solids_density_t_m3 * (1.0 - self.bed_porosity)

    def free_discharge_tph(self, solids_density_t_m3: float, flow_multiplier=1.0):
        """The mill's free discharge at nominal hold-up as a solids mass flow [t/h]. The nominal
        hold-up is a volume (Austin's powder filling U), and the discharge law is one of volumes:
        le Roux et al. (2013, eq. 9) give the mill's solids outflow as a volume flow set by the
        volumes of slurry and solids it holds. So at the same filling the same volume of solids
        leaves, and its mass scales with the solids density: ``discharge_factor`` x nominal feed
        x flow multiplier (a circuit's recycle) x rho_s / rho_quartz, the factor being stated for
        a quartz slurry. The residence time H_nom / Q then does not depend on the density."""
        return (self.feed_nominal_tph * flow_multiplier * self.discharge_factor
                * solids_density_t_m3 / DISCHARGE_REFERENCE_DENSITY_T_M3)

    def with_(self, **changes) -> "Mill":
        """This mill with ``changes`` (field names as the dataclass's, units in them)."""
        known = [f.name for f in fields(self)]
        for name in changes:
            if name not in known:  # a TypeError from dataclasses.replace named no field to use
                raise TwinInputError(f"Mill {self.name!r} has no field {name!r}.{close_matches(name, known)} "
                                     f"Fields: {', '.join(known)}.")
        return replace(self, **changes)


def refuse_bool_fields(owner: str, obj) -> None:
    """Refuse a bool in any field of the dataclass ``obj``: True passed every range check as 1.0 (a bool is an
    int in Python), e.g. a power factor or a 1 m diameter typed as a flag."""
    for f in fields(obj):
        value = getattr(obj, f.name)
        if isinstance(value, bool):
            raise bad_value(owner, f.name, value, "a number, not a bool")


#: The laboratory mill of MISSION.md: 0.5 m x 0.3 m, 70 % of critical, 25 mm balls (the ball size
#: Austin et al. 1984 ch. 4 report the typical shape parameters for; twin.calibration.breakage_map).
LAB = Mill("lab", diameter_m=0.5, length_m=0.3, feed_nominal_tph=0.031, ball_size_mm=25.0)
#: The shape of the industrial mill (length 1.5 diameters, 35 % balls, 70 % critical, 25 mm balls),
#: from which `grindtwin size-mill` sizes the ``industrial`` preset.
INDUSTRIAL_BASE = Mill("industrial", diameter_m=3.2, length_m=4.8, feed_nominal_tph=30.0, ball_size_mm=25.0)
#: The ``industrial`` preset: the base shape at the size `grindtwin size-mill --ore B --feed-tph 31
#: --target-p80-um 210 --write-preset twin/data/industrial_mill.json` found (twin.sizing), with its hydrocyclones.
INDUSTRIAL_PRESET_PATH = Path(__file__).resolve().parent / "data" / "industrial_mill.json"


#: The keys of a mill preset file (`grindtwin size-mill --write-preset` writes them; twin.sizing).
PRESET_KEYS = ("mill", "cyclone", "sizing", "command")


def read_preset(path) -> Mill:
    """The mill of a preset file `grindtwin size-mill --write-preset PATH` wrote: the industrial base
    mill (INDUSTRIAL_BASE, whose calibrated values it takes) at the sized dimensions, with the sized
    hydrocyclones and circuit; TwinInputError naming the file and what is wrong."""
    path = Path(path)
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise TwinInputError(f"No mill preset file {path} (`grindtwin size-mill ... --write-preset {path}` "
                             "writes one).") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise TwinInputError(f"The mill preset file {path} cannot be read as JSON: {exc}") from None
    missing = [k for k in PRESET_KEYS if k not in record] if isinstance(record, dict) else list(PRESET_KEYS)
    if missing or not all(isinstance(record[k], dict) for k in ("mill", "cyclone", "sizing")):
        raise TwinInputError(f"{path} is not a mill preset grindtwin wrote: it needs the tables "
                             f"{', '.join(PRESET_KEYS)} (`grindtwin size-mill --write-preset` writes them)"
                             + (f"; missing {', '.join(missing)}." if missing else "."))
    try:
        return INDUSTRIAL_BASE.with_(**record["mill"], cyclone=tuple(sorted(record["cyclone"].items())),
                                     cyclone_circuit=record["sizing"].get("circuit", "direct"),
                                     sized_calibration=str((record.get("calibration") or {}).get("name", "")))
    except TwinInputError as exc:
        raise TwinInputError(f"The mill preset file {path}: {exc}") from None


def is_preset_file(spec) -> bool:
    """Whether a mill ``spec`` names a preset file (a Path, or a string ending in .json) and not a preset."""
    return isinstance(spec, Path) or (isinstance(spec, str) and spec.lower().endswith(".json"))


@cache
def industrial_preset() -> Mill:
    """The sized industrial mill (INDUSTRIAL_PRESET_PATH); TwinError naming the command if absent."""
    from .errors import TwinError

    if not INDUSTRIAL_PRESET_PATH.is_file():
        raise TwinError(f"No industrial mill preset {INDUSTRIAL_PRESET_PATH}: run "
                        "`grindtwin size-mill --ore B --feed-tph 31 --target-p80-um 210 --write-preset twin/data/industrial_mill.json`.")
    return read_preset(INDUSTRIAL_PRESET_PATH)


MILLS = {"lab": LAB, "industrial": INDUSTRIAL_BASE}


def get_mill(spec, calibration: dict | None = None) -> Mill:
    """A preset name ('lab', 'industrial'), a preset file (:func:`read_preset`, an industrial mill) or a
    Mill. A preset takes the fitted mill values (``calibration['mills'][name]``, e.g. the lab mill's
    power factor and grate cut size)."""
    if isinstance(spec, Mill):
        return spec
    file = is_preset_file(spec)
    if file or spec in MILLS:
        name = "industrial" if file else spec  # a preset file is a sized industrial mill
        preset = read_preset(spec) if file else industrial_preset() if spec == "industrial" else MILLS[spec]
        return preset.with_(**(calibration or {}).get("mills", {}).get(name, {}))
    raise TwinInputError(f"The 'mill' must be one of {', '.join(MILLS)}, a preset file (.json) `grindtwin size-mill "
                         f"--write-preset` wrote, or a twin.Mill. Got {spec!r}.{close_matches(str(spec), MILLS)}")


#: Bond's ball-mill power constant in Rowland's metric form [kW per tonne of balls, D in m]: Bond's
#: 3.1 kW per short ton with D in ft (Bond 1961) times 3.281^0.3 x 1.1023.
ROWLAND_KW_PER_T = 4.879


def bond_power_kw(mill: Mill, speed_frac_critical):
    """Net power of an overflow ball mill [kW]: Bond's power per tonne of balls in Rowland's
    metric form, 4.879 D^0.3 (3.2 - 3 J) phi_c (1 - 0.1 / 2^(9 - 10 phi_c)) kW/t (D in m;
    Rowland 1982, in Mular & Jergensen (eds.), *Design and Installation of Comminution Circuits*,
    SME, 393-438; Bond 1961), times the mass of the ball bed J (pi/4) D^2 L rho_bulk [t], times the
    mill's ``power_factor``. The same as Gupta & Yan's (2016, eq. 9.28) 7.33 J phi_c (1 - 0.937 J)
    (...) rho_b L D^2.3 with rho_b the balls' own density (its 7.33 = 12.26 x 0.6 holds the bed's
    40 % voids); read with the bulk density, as this was, it gave 0.6x Bond's power. Rowland's
    ball-size term Ss = 1.102 (B - 12.5 D) / 50.8 kW/t for mills over 3.3 m is left out (a step at
    3.3 m; docs/sizing.md gives its size). Works on floats and CasADi expressions."""
    J = mill.ball_filling_frac
    phi = _speed("bond_power_kw", speed_frac_critical)
    per_tonne = (ROWLAND_KW_PER_T * mill.diameter_m ** 0.3 * (3.2 - 3.0 * J) * phi
                 * (1.0 - 0.1 / 2.0 ** (9.0 - 10.0 * phi)))
    return mill.power_factor * per_tonne * J * mill.volume_m3 * mill.ball_bulk_density_t_m3


#: Dynamic angle of repose of a ball charge at 70-80 % of critical speed [deg]: measured 30-40
#: deg in laboratory mills (Liddell & Moys 1988, J. S. Afr. Inst. Min. Metall. 88, 49-57).
DYNAMIC_ANGLE_DEG = 35.0


def hogg_fuerstenau_power_kw(mill: Mill, speed_frac_critical, dynamic_angle_deg: float = DYNAMIC_ANGLE_DEG):
    """Net power [kW] by the torque-arm model of Hogg & Fuerstenau (1972, Trans. SME-AIME 252,
    418-423): the charge, a circular segment of the mill's section filled to J, held at its
    dynamic angle alpha, draws P = M_c g r_c sin(alpha) omega, with M_c the ball-bed mass,
    r_c = 4 R sin^3(theta) / (3 (2 theta - sin 2 theta)) the distance of its centre of mass
    from the axis (theta the segment's half-angle, J = (2 theta - sin 2 theta) / 2 pi) and
    omega = phi_c sqrt(2 g / D). It scales exactly as D^2.5 L and has no centrifuging loss near
    critical speed. Works on floats and CasADi expressions (linear in the speed)."""
    import scipy.optimize

    _speed("hogg_fuerstenau_power_kw", speed_frac_critical)
    J = mill.ball_filling_frac
    theta = scipy.optimize.brentq(lambda t: (2 * t - math.sin(2 * t)) / (2 * math.pi) - J, 1e-6, math.pi)
    radius = mill.diameter_m / 2.0
    r_c = 4.0 * radius * math.sin(theta) ** 3 / (3.0 * (2 * theta - math.sin(2 * theta)))
    mass_t = J * mill.volume_m3 * mill.ball_bulk_density_t_m3
    omega = speed_frac_critical * math.sqrt(2.0 * G_M_S2 / mill.diameter_m)
    return mill.power_factor * mass_t * G_M_S2 * r_c * math.sin(math.radians(dynamic_angle_deg)) * omega


def _speed(owner: str, speed_frac_critical):
    """A speed given as a number checked as a fraction of critical in (0, 1] (70 typed for 0.70 drew
    -5.9e208 kW in Bond's equation); a CasADi expression as it is (the model's own inputs are checked)."""
    if isinstance(speed_frac_critical, Real):
        check_range(owner, "speed_frac_critical", speed_frac_critical, 0.0, 1.0, hi_open=False)
    return speed_frac_critical


def power_kw(mill: Mill, speed_frac_critical):
    """Net power [kW] of the mill at a speed: its ``power_model``; with ``net_power_kw`` given, that
    draw at the nominal speed, shaped with speed by the model (floats and CasADi expressions; each model
    checks a speed given as a number)."""
    model = POWER_MODELS[mill.power_model]
    if mill.net_power_kw is None:
        return model(mill, speed_frac_critical)
    return mill.net_power_kw * model(mill, speed_frac_critical) / model(mill, mill.speed_nominal_frac_critical)


#: Speed [fraction of critical] beyond which the ball charge centrifuges: the midpoint of the
#: logistic falloff of Austin, Klimpel & Luckie's speed factor (1984, eq. 8.4), which the twin's
#: breakage follows. Neither power model (Bond's equation, Hogg & Fuerstenau's torque arm) has a
#: centrifuging loss, so beyond it the twin's power and specific energy are a cascading charge's.
CENTRIFUGING_FRAC_CRITICAL = 0.94


def centrifuging_note(speed_frac_critical: float) -> str | None:
    """A note when a speed lies beyond :data:`CENTRIFUGING_FRAC_CRITICAL`, else None."""
    if not speed_frac_critical > CENTRIFUGING_FRAC_CRITICAL:
        return None
    return (f"speed {speed_frac_critical:.3g} of critical is beyond {CENTRIFUGING_FRAC_CRITICAL} where the charge "
            "centrifuges (Austin et al. 1984, eq. 8.4): breakage falls there, but the power model has no "
            "centrifuging loss, so power and specific energy are overestimated")


def load_status(load_frac: float, band) -> str:
    """'under', 'stable' or 'over' for a load (hold-up over nominal) and a stable band."""
    lo, hi = band
    return "under" if load_frac < lo else "over" if load_frac > hi else "stable"


#: Net-power models by name (a Mill's ``power_model``).
POWER_MODELS = dict(zip(POWER_MODEL_NAMES, (bond_power_kw, hogg_fuerstenau_power_kw)))
