"""Physical ranges shared by scene keys and history columns, with the hint for the usual unit
mistake: mill speed as a fraction of critical (0.72, not 72 %), feed rate in t/h (not kg/h),
the latter judged against the mill's nominal feed rate, and a product P80 in um (not mm)."""

from __future__ import annotations

import math

from twin import (MILLS, POWER_MODELS, SPECIFIC_ENERGY_RANGE_KWH_T, TwinInputError, get_mill, is_preset_file,
                  power_kw)

#: A feed rate above this multiple of the mill's nominal feed rate is refused: an order of
#: magnitude above nominal is no operating point of that mill (its hold-up would be many
#: times its volume), while a feed in kg/h typed as t/h is 1000x.
FEED_MAX_NOMINAL_MULTIPLE = 10.0
#: A recorded feed whose median over its rows above 0 is below this fraction of the mill's nominal
#: feed is refused: plants run their mills near nominal (a start-up or a stop are some rows, not the
#: median), while a feed in kg/s (1/3.6 of t/h) or kt/d (1/24) lands below.
FEED_MIN_NOMINAL_FRAC = 0.3
#: A sample whose product rate, or the fresh feed over the interval before it, is below this fraction of the
#: mill's nominal feed is one of a feed stop (a mill discharges at its nominal rate over its residence time,
#: ~0.1 h; after a stop's few residence times only the draining charge's trickle leaves); a controller's
#: lowest feed must stay above it, so that the run's KPIs never take its own moves for a stop.
NO_PRODUCT_FRAC = 0.05
#: Speeds in this range are named as "percent of critical" in the hint: ball mills run at
#: 40-100 % of critical (0.65-0.80 typically), so 72 reads as 72 %, but 1.2 as a fraction.
PERCENT_RANGE = (40.0, 100.0)
#: Speeds in this range are named as rpm in the hint: ball mills turn at 10-25 rpm (42.3 / sqrt(D)
#: rpm is critical, D in m; Wills & Finch 2016, eq. 7.3), no mill at 5-40 % of critical.
RPM_RANGE = (5.0, 40.0)


#: A recorded product P80 [um] below this is refused: finer than any ball mill's (or stirred mill's,
#: ~5-10 um) product, while a P80 in mm (0.2-0.5 for a ball-mill circuit) lands there.
P80_MIN_UM = 1.0


#: A given net power beside the scene's own mill dimensions may differ from Bond's power for them by
#: at most this factor either way: Bond's equation predicts a mill's power within some 10-20 % (Morrell
#: 2004), so a factor of 2 is a size or a power in other units (a diameter in feet: 2 % of Bond's).
NET_POWER_BOND_FACTOR_MAX = 2.0


#: Scene [mill] keys that change the mill's power draw.
POWER_KEYS = ("diameter_m", "length_m", "ball_filling_frac", "net_power_kw")


def preset_mill(preset):
    """The twin.Mill of a scene's ``preset`` (a preset's name, or its preset file resolved against the
    scene's folder), None when it is neither or the file cannot be read (the scene's checks say why)."""
    if not (isinstance(preset, str) and preset in MILLS or is_preset_file(preset)):
        return None
    try:
        return get_mill(preset)
    except TwinInputError:
        return None


def nominal_feed_tph(preset, mill_keys: dict | None = None) -> float | None:
    """The nominal feed rate [t/h] of a scene's mill (None for an unknown preset): the preset's,
    scaled by the power the scene's mill draws at nominal speed over the preset's (throughput ~
    power at a given specific energy, Bond's law). ``mill_keys``: the scene's [mill] table; its
    dimensions, ball filling and net power (:data:`POWER_KEYS`) enter. A value the mill refuses
    (the schema names it in the same check) leaves the preset's nominal feed."""
    base = preset_mill(preset)
    if base is None:
        return None
    mill = power_mill(base, mill_keys)
    speed = base.speed_nominal_frac_critical
    return float(base.feed_nominal_tph) * float(power_kw(mill, speed)) / float(power_kw(base, speed))


def power_mill(base, mill_keys: dict | None):
    """The preset's twin.Mill ``base`` with a scene's [mill] keys that change its power (:data:`POWER_KEYS`); a value
    the mill refuses (the schema names it in the same check) leaves the preset's."""
    given = {k: float(v) for k, v in (mill_keys if isinstance(mill_keys, dict) else {}).items()
             if k in POWER_KEYS and isinstance(v, (int, float)) and not isinstance(v, bool)}
    try:
        return base.with_(**given)
    except TwinInputError:
        return base


def power_limit_problem(preset, mill_keys: dict | None, limit_kw: float, speed_min: float, speed_max: float,
                        power_models=()) -> str | None:
    """Why a controller's ``power_max_kw`` is no limit of the scene's mill run between ``speed_min`` and
    ``speed_max``, or None. Its ball charge draws the power whatever the feed (Bond 1961), so a limit below
    1/:data:`NET_POWER_BOND_FACTOR_MAX` of its net power at the lowest speed can never be met (a limit in MW held the
    NMPC at its lowest speed and feed, P80 off target), and one above that factor times its power at the highest
    speed never binds (a limit in W ran as none). ``power_models``: models the scene names besides the mill's own
    (``mill.power_model``, a power effect's ``model``); the least and the most of them bound the limit."""
    base = preset_mill(preset)
    if base is None or not (0 < speed_min < speed_max < 1):
        return None
    mill = power_mill(base, mill_keys)
    keys = mill_keys if isinstance(mill_keys, dict) else {}
    named = {m for m in (keys.get("power_model"), *power_models) if isinstance(m, str) and m in POWER_MODELS}
    mills = [mill] + [mill.with_(power_model=m) for m in named - {mill.power_model}]
    low = min(float(power_kw(m, speed_min)) for m in mills)
    high = max(float(power_kw(m, speed_max)) for m in mills)
    f = NET_POWER_BOND_FACTOR_MAX
    if low / f <= limit_kw <= f * high:
        return None
    side, unit = ((f"below 1/{f:g} of the {low:.4g} kW the mill draws at speed_min {speed_min:g}: no speed within the "
                   "bounds meets it", "MW") if limit_kw < low / f else
                  (f"above {f:g} x the {high:.4g} kW the mill draws at speed_max {speed_max:g}: it never binds", "W"))
    return (f"{limit_kw:g} kW is {side} (the ball charge draws the power whatever the feed, Bond 1961; allowed "
            f"{low / f:.4g}-{f * high:.4g} kW; {unit}? kW expected)")


def scene_nominal_feed_tph(scene) -> float | None:
    """The nominal feed rate [t/h] of a loaded scene's mill (:func:`nominal_feed_tph`), else its feed rate."""
    return nominal_feed_tph(scene.mill_spec(), scene.mill.model_dump()) or scene.feed.feed_tph


def speed_problem(value: float) -> str | None:
    """Why ``value`` is not a speed as a fraction of critical in (0, 1), or None."""
    if math.isfinite(value) and 0.0 < value < 1.0:
        return None
    hint = ""
    if PERCENT_RANGE[0] <= value <= PERCENT_RANGE[1]:
        hint = f": fraction of critical expected, not percent ({value:g} % is {value / 100:g})"
    elif RPM_RANGE[0] <= value < RPM_RANGE[1]:
        hint = (f": fraction of critical expected, not rpm ({value:g} rpm is {value:g} / (42.3 / sqrt(D)) of "
                "critical, D the mill's inside diameter in m)")
    return f"speed {value:g} is outside (0, 1){hint}"


def feed_problem(value: float, nominal_tph: float | None) -> str | None:
    """Why ``value`` [t/h] is not a plausible feed rate of a mill with ``nominal_tph``, or None."""
    if not math.isfinite(value) or value < 0:
        return f"feed {value:g} t/h is not a finite rate >= 0"
    if nominal_tph is None or value <= FEED_MAX_NOMINAL_MULTIPLE * nominal_tph:
        return None
    limit = FEED_MAX_NOMINAL_MULTIPLE * nominal_tph
    hint = " (kg/h? t/h expected)" if value / 1000.0 <= limit else ""
    return (f"feed {value:g} t/h is more than {FEED_MAX_NOMINAL_MULTIPLE:g} x the mill's nominal "
            f"{nominal_tph:g} t/h{hint}")


def controller_feed_min_problem(value: float, nominal_tph: float | None) -> str | None:
    """Why ``value`` [t/h] cannot be a controller's lowest feed on a mill with ``nominal_tph``, or None: below
    :data:`NO_PRODUCT_FRAC` of the nominal, the KPIs would read the controller's own feed cut as a feed stop
    and leave its samples out of the P80 IAE."""
    if nominal_tph is None or not value < NO_PRODUCT_FRAC * nominal_tph:
        return None
    return (f"must be at least {NO_PRODUCT_FRAC * nominal_tph:.4g} t/h, {NO_PRODUCT_FRAC:.0%} of the mill's nominal "
            f"{nominal_tph:.4g} t/h: a lower feed is a feed stop, whose samples the P80 KPIs leave out, so the "
            "controller's own cut would not count against it")


def feed_level_problem(median_tph: float, nominal_tph: float | None) -> str | None:
    """Why a recorded feed whose median over its rows above 0 is ``median_tph`` is not the feed of a
    mill with ``nominal_tph`` (:data:`FEED_MIN_NOMINAL_FRAC`), or None."""
    if nominal_tph is None or not median_tph < FEED_MIN_NOMINAL_FRAC * nominal_tph:
        return None
    return (f"median {median_tph:.4g} t/h over the rows above 0 is below {FEED_MIN_NOMINAL_FRAC:.0%} of the mill's "
            f"nominal {nominal_tph:.4g} t/h (kg/s? x 3.6 is t/h; kt/d? x 41.7 is t/h); if the plant ran so, give the "
            "scene its own mill (feed.feed_tph is the mill's nominal feed)")


def product_p80_problem(value: float, feed_p80_um: float | None) -> str | None:
    """Why ``value`` [um] is not a plausible product P80 of a mill fed at ``feed_p80_um`` (None:
    unknown), or None: above 0, at least :data:`P80_MIN_UM`, and finer than the feed (grinding only
    makes it finer; a historian's fill value such as 9999 is coarser)."""
    if not math.isfinite(value) or value <= 0:
        return f"P80 {value:g} um is not > 0"
    if value < P80_MIN_UM:
        return (f"P80 {value:g} um is below {P80_MIN_UM:g} um, finer than any mill's product (mm? "
                f"{value:g} mm is {value * 1000:g} um)")
    if feed_p80_um is not None and value >= feed_p80_um:
        return (f"P80 {value:g} um is not finer than the scene's feed P80 {feed_p80_um:g} um (a mill's "
                "product is; a recorder's fill value for a missing sample? leave the cell empty)")
    return None


def own_dimensions(mill_keys, preset_mill) -> bool:
    """Whether a scene's [mill] (its keys, or a dict of them) gives a diameter or length other than its
    preset's: a loaded scene carries the preset's own, filled in (scenarios.scene.loader)."""
    get = mill_keys.get if isinstance(mill_keys, dict) else lambda k: getattr(mill_keys, k)
    return any(get(k) is not None and get(k) != getattr(preset_mill, k) for k in ("diameter_m", "length_m"))


def net_power_problem(preset, mill_keys: dict | None, feed_tph: float | None, speed: float | None = None) -> str | None:
    """Why a scene's ``mill.net_power_kw`` is implausible, or None: the specific energy it means at the
    scene's feed outside :data:`twin.SPECIFIC_ENERGY_RANGE_KWH_T` (a power in MW or W lands outside), or,
    beside the scene's own dimensions,
    more than :data:`NET_POWER_BOND_FACTOR_MAX` from Bond's power for them at the scene's ``speed`` (where the
    power was measured; the preset's own when None: Bond's at 0.70 was quoted for a mill run at 0.74)."""
    keys = mill_keys if isinstance(mill_keys, dict) else {}
    net = keys.get("net_power_kw")
    if not isinstance(net, (int, float)) or isinstance(net, bool) or not net > 0:
        return None
    if isinstance(feed_tph, (int, float)) and feed_tph > 0:
        se = net / feed_tph
        lo, hi = SPECIFIC_ENERGY_RANGE_KWH_T
        if not lo <= se <= hi:
            unit = "MW? kW expected" if se < lo else "W? kW expected"
            return (f"{net:g} kW at the feed's {feed_tph:g} t/h is {se:.3g} kWh/t, outside the {lo:g}-{hi:g} kWh/t "
                    f"ball mills draw ({unit})")
    base = preset_mill(preset)
    dims = {k: float(v) for k, v in keys.items() if k in ("diameter_m", "length_m", "ball_filling_frac")
            and isinstance(v, (int, float)) and not isinstance(v, bool)}
    if base is None or not own_dimensions(dims, base):  # the preset's own: a stand-in with a case's power
        return None
    try:
        at = speed if isinstance(speed, (int, float)) and 0 < speed < 1 else base.speed_nominal_frac_critical
        bond = float(power_kw(base.with_(**dims, power_factor=1.0), at))
    except TwinInputError:
        return None
    if not 1 / NET_POWER_BOND_FACTOR_MAX <= net / bond <= NET_POWER_BOND_FACTOR_MAX:
        return (f"{net:g} kW is {net / bond:.3g} x Bond's {bond:.4g} kW for the mill's own dimensions "
                f"({', '.join(f'{k} {v:g}' for k, v in dims.items())}) at {at:g} of critical; allowed: within a factor "
                f"{NET_POWER_BOND_FACTOR_MAX:g} (a size in feet, or a power in other units?)")
    return None
