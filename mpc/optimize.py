"""Steady-state set-point optimiser: feed rate and speed that hold a target P80 with a stable load.

On the twin's steady state (``Twin.steady``): for a blend, the P80 rises with feed rate
and falls with speed (over the usable range), so

- ``"feed"``: speed held (default: the mill's nominal), the feed rate that gives the target is
  the root of ``P80(feed) - target`` (Brent's method, ``scipy.optimize.brentq``);
- ``"speed"``: feed held (default: the mill's nominal), the speed root of ``P80(speed) - target``;
- ``"both"``: on the curve P80 = target (feed solved for each speed), the speed that minimises
  specific energy [kWh/t] (``objective="min_energy"``) or maximises throughput
  (``objective="max_throughput"``), by a grid over the speed bounds refined with a bounded
  scalar search (``scipy.optimize.minimize_scalar``), subject to the load in its stable band.

Every answer says whether it is feasible (a root inside the bounds and the load in the band);
an unreachable target is reported in ``message``, never replaced by the nearest point silently.
An answer of ``"both"`` that sits on a constraint (a speed bound, an end of the load band, or
where no feed within the feed bounds holds the target) names it in the table's ``active`` column
and in ``message``: the objective would improve beyond it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable
from numbers import Real
from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.optimize

from mpc.errors import MpcInputError
from twin import pxx_um

MODES = ("both", "feed", "speed")
OBJECTIVES = ("min_energy", "max_throughput")


@dataclass(frozen=True)
class Setpoints:
    """The chosen set points and the table of alternatives."""

    feasible: bool
    feed_tph: float
    speed_frac_critical: float
    p80_um: float
    specific_energy_kwh_t: float
    load_frac: float
    power_kw: float
    mode: str
    objective: str
    message: str
    table: pd.DataFrame
    active: str = ""  # the constraints the answer sits on ("" when none; module docstring)


#: The default feed search range, as multiples of the mill's nominal feed rate (the range of
#: ``grindtwin optimize``): fixed t/h bounds fit one mill size only (5-60 t/h held no root for the
#: 0.031 t/h laboratory mill).
FEED_RANGE_NOMINAL = (0.2, 2.0)
#: A root's feed (or speed) is found to this share of its search interval: an absolute 1e-4 t/h
#: was 0.3 % of the laboratory mill's feed and left its P80 0.15 um off the target.
ROOT_XTOL_REL = 1e-8
#: An answer holds the target when its P80 is within this share of it (0.5 um at 210 um was 2.5 %
#: at 20 um); the roots above meet it by orders of magnitude.
P80_TOL_REL = 1e-3


def default_feed_bounds(twin) -> tuple:
    """The feed search range [t/h] of :data:`FEED_RANGE_NOMINAL` for ``twin``'s mill."""
    return tuple(f * twin.mill.feed_nominal_tph for f in FEED_RANGE_NOMINAL)


def _row(twin, blend, feed, speed, target, option, objective, hardness_scale, band):
    ss = twin.steady(feed_tph=feed, speed_frac_critical=speed, blend=blend,
                     hardness_scale=hardness_scale)
    load = ss.outputs["load_frac"]
    held = abs(ss.p80_um - target) <= P80_TOL_REL * target
    ok = held and band[0] <= load <= band[1]
    note = "" if ok else ("load outside the stable band" if held else "target not reached")
    return {"option": option, "objective": objective, "feasible": ok, "feed_tph": feed,
            "speed_frac_critical": speed, "p80_um": ss.p80_um, "target_p80_um": target,
            "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"], "load_frac": load,
            "power_kw": ss.outputs["power_kw"], "throughput_tph": ss.outputs["throughput_tph"],
            "note": note, "active": ""}


def _root_in(g, bounds, xtol) -> float:
    """Brent's root of g inside ``bounds``; nan if g does not change sign there."""
    lo, hi = bounds
    if g(lo) * g(hi) > 0:
        return math.nan
    return float(scipy.optimize.brentq(g, lo, hi, xtol=xtol))


#: Halvings of the feed bracket's upper end towards its lower end while the mill has no steady
#: state there (it overloads: its hold-up grows without bound); 6 halvings reach 1/64 of the span.
OVERLOAD_HALVINGS = 6


#: Points of the feed scan that :func:`feed_for_target` brackets roots on when P80 does not cross the target
#: between the ends of its bounds: a hydrocyclone circuit's P80 rises with the feed, peaks near the circuit's
#: design and falls past it (README, Limitations), so a target coarser than both ends is met twice between
#: them; a step of 0.13 of the nominal feed over FEED_RANGE_NOMINAL, refined around the peak.
FEED_SCAN_POINTS = 15


def feed_for_target(twin, blend, target_p80_um: float, speed_frac_critical: float,
                    feed_bounds_tph=None, hardness_scale: float = 1.0) -> float:
    """Feed rate [t/h] with steady P80 = target at the given speed; nan if outside the bounds
    (default :func:`default_feed_bounds`). Where the mill overloads at the upper bound (no steady
    state, twin.SolverError), the bracket ends at the highest feed, halving towards the lower
    bound, that it holds. Brent's root between the bracket's ends; where P80 does not cross the target
    between them, the roots of a scan of ``FEED_SCAN_POINTS`` feeds (:func:`_scanned_roots`: a cyclone
    circuit's P80 peaks between finer ends), of several the one of least specific energy."""
    from twin import SolverError

    @functools.cache  # each feed solved once: the bracket's end for the overload test and the root, the scan
    def state(f):
        return twin.steady(feed_tph=f, speed_frac_critical=speed_frac_critical, blend=blend,
                           hardness_scale=hardness_scale)

    def gap(f):
        return state(float(f)).p80_um - target_p80_um

    lo, hi = default_feed_bounds(twin) if feed_bounds_tph is None else feed_bounds_tph
    xtol = ROOT_XTOL_REL * (hi - lo)
    for _ in range(OVERLOAD_HALVINGS):
        try:
            gap(hi)
            break
        except SolverError:
            hi = 0.5 * (lo + hi)
    else:
        return math.nan
    root = _root_in(gap, (lo, hi), xtol=xtol)
    if math.isfinite(root):
        return root
    roots = _scanned_roots(gap, list(np.linspace(lo, hi, FEED_SCAN_POINTS)), xtol)
    return min(roots, key=lambda f: state(f).outputs["specific_energy_kwh_t"]) if roots else math.nan


#: How far above the target [fraction] a blend's steady P80 at :func:`feed_holding_every_blend`'s feed may lie:
#: the blend that set the feed sits at its root (found to ROOT_XTOL_REL of the feed range).
HOLDING_P80_TOL_REL = 1e-6


def feed_holding_every_blend(twin, blends, target_p80_um: float, speed_frac_critical: float,
                             feed_bounds_tph=None) -> float:
    """The one feed rate [t/h] at which every blend of ``blends`` grinds at or finer than the target at steady
    state, at the given speed: the least of their :func:`feed_for_target`, checked: a grate mill's product
    coarsens as the feed rises, but a cyclone circuit's can get finer (README, Limitations), and then a blend
    whose target feed is higher lies coarser at the least. What an operator without a controller holds to keep
    a schedule's every ore in specification, grinding the others finer than they need. nan if a blend is coarser
    than the target at the least one, or :func:`feed_for_target` finds no feed for it (its P80 coarser than the
    target over the whole bounds, or finer). The target, speed and bounds are checked as
    :func:`optimal_setpoints` checks them."""
    fn = "feed_holding_every_blend"
    # a list: an iterator was read up by the feeds, and the check below then passed on no blend
    blends = list(blends) if isinstance(blends, Iterable) and not isinstance(blends, (str, bytes, dict)) else []
    if not blends:
        raise MpcInputError(f"The 'blends' parameter of {fn} must be a list of one or more blends (each a dict by "
                            "ore, a Blend or fractions in the twin's component order).")
    target_p80_um = _target(twin, target_p80_um, fn)
    speed_frac_critical = _number("speed_frac_critical", speed_frac_critical, fn)
    if feed_bounds_tph is not None:
        feed_bounds_tph = _bounds("feed_bounds_tph", feed_bounds_tph, 0.0, math.inf, "t/h", fn)
    feeds = [feed_for_target(twin, b, target_p80_um, speed_frac_critical, feed_bounds_tph) for b in blends]
    if not all(math.isfinite(f) for f in feeds):
        return math.nan
    safe = min(feeds)
    limit = target_p80_um * (1.0 + HOLDING_P80_TOL_REL)
    held = all(twin.steady(feed_tph=safe, speed_frac_critical=speed_frac_critical, blend=b).p80_um <= limit
               for b in blends)
    return safe if held else math.nan


#: Points of the speed scan that brackets the roots of P80(speed) = target: P80 is not monotonic
#: in speed (breakage rates peak near 0.75-0.8 of critical, Austin et al. 1984 sec. 10.2, and the
#: twin's speed factor follows), so a target can be met at two speeds, or at none inside the
#: bounds although both ends are coarser than it; a step of 0.025 of critical over 0.55-0.90.
SPEED_SCAN_POINTS = 15


def speed_for_target(twin, blend, target_p80_um: float, feed_tph: float,
                     speed_bounds=(0.55, 0.90), hardness_scale: float = 1.0) -> float:
    """Speed [fraction of critical] with steady P80 = target at the given feed; of several such
    speeds the one of least specific energy; nan if none. Roots are bracketed on a scan of
    ``SPEED_SCAN_POINTS`` speeds (and either side of a minimum below the target between them,
    :func:`_dips_below`), then refined by Brent's method."""
    @functools.cache
    def state(s):
        return twin.steady(feed_tph=feed_tph, speed_frac_critical=s, blend=blend, hardness_scale=hardness_scale)

    def gap(s):
        return state(float(s)).p80_um - target_p80_um

    roots = _scanned_roots(gap, list(np.linspace(speed_bounds[0], speed_bounds[1], SPEED_SCAN_POINTS)), 1e-7)
    if not roots:
        return math.nan
    return min(roots, key=lambda s: state(s).outputs["specific_energy_kwh_t"])


def _scanned_roots(gap, grid, xtol) -> list[float]:
    """The roots of ``gap`` bracketed on the scan ``grid`` and on either side of an extreme that crosses zero
    between scan points of one sign (:func:`_dips_below`: a minimum below zero, or of -gap, a maximum above it),
    each refined by Brent's method."""
    grid = sorted(grid + _dips_below(gap, grid) + _dips_below(lambda x: -gap(x), grid))
    roots = [_root_in(gap, (float(a), float(b)), xtol=xtol) for a, b in zip(grid[:-1], grid[1:])]
    return [r for r in roots if math.isfinite(r)]


def _dips_below(gap, grid) -> list[float]:
    """The minima of ``gap`` below zero between scan points where it is positive at the points: a
    target just finer than the least P80 is met at two speeds (or feeds) closer than the scan's step, with no
    sign change at the points to bracket them. Each interior scan point lower than both neighbours
    is refined by a bounded Brent minimisation between them."""
    values = [gap(s) for s in grid]
    out = []
    for i in range(1, len(grid) - 1):
        if 0 < values[i] <= min(values[i - 1], values[i + 1]):
            res = scipy.optimize.minimize_scalar(gap, bounds=(grid[i - 1], grid[i + 1]), method="bounded",
                                                 options={"xatol": 1e-7})
            if res.fun < 0:
                out.append(float(res.x))
    return out


#: Speeds scanned along the curve P80 = target by ``"both"`` before its bounded search.
BOTH_SPEED_SCAN_POINTS = 9


class _LeftFeedBounds(Exception):
    """No feed within the bounds holds the target at a speed the band search tried."""


#: How far inside the load band [load fraction] the points found on its ends are put, so that a root found to
#: Brent's tolerance counts as inside (a millionth of the load: far below what the twin resolves).
BAND_EDGE_INSIDE = 1e-6


def _band_crossings(pts, band, on_curve) -> list:
    """Points of the curve P80 = target inside the load band that the scan stepped over: the load on the
    curve is continuous in speed, so between two scanned neighbours
    - on either side of an end of the band, the point where the load meets that end (just inside it): an
      optimum on the band's edge lies there, and the scanned neighbour inside the band missed it;
    - one below the band and the other above it, also the point where the load is mid-band;
    - both below it (or both above), a load that peaks into the band (or dips into it) between them: the
      extreme and the window's two ends, where the load meets the band (a window narrower than the scan's
      step: the scan alone called the target infeasible).
    Brent's method for each (a bounded scalar search for the extreme)."""
    mid = 0.5 * (band[0] + band[1])
    out = []

    def load_at(s):
        load = on_curve(float(s))[2]
        if math.isnan(load):
            raise _LeftFeedBounds
        return load

    for (s0, f0, _, l0), (s1, f1, _, l1) in zip(pts, pts[1:]):
        if math.isnan(f0) or math.isnan(f1):
            continue
        try:
            for edge in (band[0] + BAND_EDGE_INSIDE, band[1] - BAND_EDGE_INSIDE):
                if (l0 - edge) * (l1 - edge) < 0:
                    out.append(scipy.optimize.brentq(lambda s: load_at(s) - edge, s0, s1, xtol=1e-9))
            if (l0 - band[0]) * (l1 - band[0]) < 0 and (l0 - band[1]) * (l1 - band[1]) < 0:
                out.append(scipy.optimize.brentq(lambda s: load_at(s) - mid, s0, s1, xtol=1e-6))
            elif max(l0, l1) < band[0] or min(l0, l1) > band[1]:
                sign, edge = (1.0, band[0] + BAND_EDGE_INSIDE) if l0 < band[0] else (-1.0, band[1] - BAND_EDGE_INSIDE)
                peak = scipy.optimize.minimize_scalar(lambda s: -sign * load_at(s), bounds=(s0, s1),
                                                      method="bounded", options={"xatol": 1e-6}).x
                if sign * (load_at(peak) - edge) >= 0:
                    out += [peak] + [scipy.optimize.brentq(lambda s: load_at(s) - edge, a, b, xtol=1e-9)
                                     for a, b in ((s0, peak), (peak, s1))]
        except _LeftFeedBounds:  # the target left the feed bounds between them: nothing to find
            continue
    return [(float(s), *on_curve(float(s))) for s in out]


#: Speeds [fraction of critical] this close to a speed bound, or to a speed that breaks a
#: constraint, put the answer of ``"both"`` on that constraint: a few times the bounded search's
#: ``xatol`` (1e-4), within which it stops short of an edge it approaches.
SPEED_EDGE = 5e-4


def _number(name: str, value, fn: str = "optimal_setpoints") -> float:
    """``value`` as one finite float, or an error naming the parameter of ``fn``."""
    if isinstance(value, (str, bytes, bool)) or np.ndim(value) != 0 or not np.isfinite(value):
        raise MpcInputError(f"The '{name}' parameter of {fn} must be one finite number. Got {value!r}.")
    return float(value)


def _bounds(name: str, value, lo: float, hi: float, unit: str, fn: str = "optimal_setpoints") -> tuple[float, float]:
    """``value`` as (low, high) with lo <= low < high < hi, or an error naming the parameter of ``fn``."""
    pair = tuple(value) if isinstance(value, (tuple, list, np.ndarray)) else ()
    if len(pair) != 2 or not all(isinstance(v, Real) and not isinstance(v, bool) for v in pair) \
            or not lo <= pair[0] < pair[1] < hi:
        raise MpcInputError(f"The '{name}' parameter of {fn} must be (low, high) [{unit}] with "
                            f"{lo:g} <= low < high < {hi:g}. Got {value!r}.")
    return float(pair[0]), float(pair[1])


def _target(twin, value, fn: str) -> float:
    """``value`` as a P80 target [um] the twin can grind to (coarser than its finest size class, finer than its
    feed), or an error naming the parameter of ``fn``."""
    target = _number("target_p80_um", value, fn)
    finest = float(twin.spec.grid.upper_um[-1])
    if not target > finest:  # 0.21 (mm for um) searched for 10 s, then answered 'infeasible'
        raise MpcInputError(f"The 'target_p80_um' parameter of {fn} must be coarser than the twin's finest size "
                            f"class ({finest:.3g} um; a P80 below it lies in the grid's sink): sizes in um, not mm? "
                            f"Got {target!r}.")
    feed_p80 = pxx_um(twin.spec.grid, twin.spec.feed_frac)
    if not target < feed_p80:  # the whole search ran, then said 'unreachable within the bounds'
        raise MpcInputError(f"The 'target_p80_um' parameter of {fn} must be finer than the twin's feed (P80 "
                            f"{feed_p80:.4g} um): no mill coarsens its feed. Got {target:g}.")
    return target


def optimal_setpoints(twin, blend, target_p80_um: float, mode: str = "both",
                      objective: str = "min_energy", feed_bounds_tph=None,
                      speed_bounds=(0.55, 0.90), feed_tph: float | None = None,
                      speed_frac_critical: float | None = None, hardness_scale: float = 1.0,
                      load_band=None) -> Setpoints:
    """Set points for ``blend`` (a dict by ore, a Blend, or fractions in the twin's component order) that hold
    ``target_p80_um``; ``mode`` in ``("both", "feed", "speed")`` picks the answer, the table
    always lists every option: feed only (speed held at ``speed_frac_critical``, default
    nominal), speed only (feed held at ``feed_tph``, default nominal), both for least specific
    energy and both for most throughput. ``feed_bounds_tph`` defaults to
    :func:`default_feed_bounds`; the table's ``active`` column names the constraints an answer
    of ``"both"`` sits on."""
    if mode not in MODES:
        raise MpcInputError(f"The 'mode' parameter of optimal_setpoints must be one of {MODES}. "
                            f"Got {mode!r}.")
    if objective not in OBJECTIVES:
        raise MpcInputError(f"The 'objective' parameter of optimal_setpoints must be one of "
                            f"{OBJECTIVES}. Got {objective!r}.")
    target_p80_um = _target(twin, target_p80_um, "optimal_setpoints")
    speed_bounds = _bounds("speed_bounds", speed_bounds, 0.0, 1.0, "fractions of critical speed")
    if feed_bounds_tph is not None:
        feed_bounds_tph = _bounds("feed_bounds_tph", feed_bounds_tph, 0.0, math.inf, "t/h")
    if load_band is not None:  # a band in percent answered 'infeasible': at most the mill filled to its shell
        shell = twin.mill.max_holdup_t(twin.spec.solids_density_t_m3) / twin.spec.holdup_nominal_t
        load_band = _bounds("load_band", load_band, 0.0, shell, "hold-up / nominal, e.g. (0.8, 1.2)")
    feed_tph = None if feed_tph is None else _number("feed_tph", feed_tph)
    speed_frac_critical = None if speed_frac_critical is None else _number("speed_frac_critical", speed_frac_critical)
    blend = list(twin.blend_fractions(blend))  # a dict by ore, a Blend or fractions, as the twin takes them
    mill = twin.mill
    speed0 = mill.speed_nominal_frac_critical if speed_frac_critical is None else speed_frac_critical
    feed0 = mill.feed_nominal_tph if feed_tph is None else feed_tph
    feed_bounds_tph = tuple(default_feed_bounds(twin) if feed_bounds_tph is None else feed_bounds_tph)
    band = tuple(load_band or mill.stable_band)
    rows = []

    def add(option, obj, feed, speed, why="target unreachable within the bounds"):
        if math.isnan(feed) or math.isnan(speed):
            rows.append({"option": option, "objective": obj, "feasible": False, "feed_tph": feed,
                         "speed_frac_critical": speed, "p80_um": math.nan,
                         "target_p80_um": target_p80_um, "specific_energy_kwh_t": math.nan,
                         "load_frac": math.nan, "power_kw": math.nan, "throughput_tph": math.nan,
                         "note": why, "active": ""})
        else:
            rows.append(_row(twin, blend, feed, speed, target_p80_um, option, obj,
                             hardness_scale, band))

    add("feed", "hold target", feed_for_target(twin, blend, target_p80_um, speed0,
                                               feed_bounds_tph, hardness_scale), speed0)
    add("speed", "hold target", feed0, speed_for_target(twin, blend, target_p80_um, feed0,
                                                        speed_bounds, hardness_scale))

    @functools.cache
    def on_curve(speed):
        f = feed_for_target(twin, blend, target_p80_um, speed, feed_bounds_tph, hardness_scale)
        if math.isnan(f):
            return math.nan, math.nan, math.nan
        ss = twin.steady(feed_tph=f, speed_frac_critical=speed, blend=blend,
                         hardness_scale=hardness_scale)
        return f, ss.outputs["specific_energy_kwh_t"], ss.outputs["load_frac"]

    def broken(speed) -> str:
        """The constraint the point of the curve P80 = target at ``speed`` breaks ("" if none)."""
        f, _, load = on_curve(float(speed))
        if math.isnan(f):
            return (f"the feed bounds {feed_bounds_tph[0]:.4g}-{feed_bounds_tph[1]:.4g} t/h (no feed "
                    "within them holds the target)")
        if load > band[1]:
            return f"the load band's upper end {band[1]:g}"
        if load < band[0]:
            return f"the load band's lower end {band[0]:g}"
        return ""

    def active_at(speed) -> str:
        """The constraints an optimum at ``speed`` sits on: a speed bound it is at, or what a
        speed just beside it breaks (the objective improves past the edge of the feasible set)."""
        found = [f"the speed's {end} bound {b:g}" for end, b in zip(("lower", "upper"), speed_bounds)
                 if abs(speed - b) <= SPEED_EDGE]
        for side in (speed - SPEED_EDGE, speed + SPEED_EDGE):
            if speed_bounds[0] <= side <= speed_bounds[1] and broken(side):
                found.append(broken(side))
        return "; ".join(dict.fromkeys(found))

    grid = np.linspace(speed_bounds[0], speed_bounds[1], BOTH_SPEED_SCAN_POINTS)
    pts = [(s, *on_curve(float(s))) for s in grid]
    pts = sorted(pts + _band_crossings(pts, band, on_curve), key=lambda p: p[0])
    grid = np.array([p[0] for p in pts])
    for obj in OBJECTIVES:
        def score(p):
            s, f, se, load = p
            if math.isnan(f) or not band[0] <= load <= band[1]:
                return math.inf
            return se if obj == "min_energy" else -f
        best = min(pts, key=score)
        if not math.isfinite(score(best)):
            # say which constraint leaves no candidate: the target itself, or the load band
            held = [p for p in pts if not math.isnan(p[1])]
            add("both", obj, math.nan, math.nan,
                "load outside the stable band at every scanned speed that holds the target" if held
                else "target unreachable within the bounds")
            continue
        i = int(np.argmin([score(p) for p in pts]))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        with np.errstate(invalid="ignore"):  # Brent's parabola through infinite scores (outside the band)
            r = scipy.optimize.minimize_scalar(lambda s: score((s, *on_curve(float(s)))), bounds=(lo, hi),
                                               method="bounded", options={"xatol": 1e-4})
        s_best = float(r.x) if math.isfinite(r.fun) and r.fun <= score(best) else float(best[0])
        add("both", obj, on_curve(s_best)[0], s_best)
        if rows[-1]["feasible"]:
            rows[-1]["active"] = active_at(s_best)
    table = pd.DataFrame(rows)
    pick = table[(table.option == mode)
                 & ((table.objective == objective) if mode == "both" else True)].iloc[0]
    # what was searched, said with the answer or its absence
    scope = (f"feed bounds {feed_bounds_tph[0]:.4g}-{feed_bounds_tph[1]:.4g} t/h, speed bounds "
             f"{speed_bounds[0]:g}-{speed_bounds[1]:g}, load band {band[0]:g}-{band[1]:g}, the target held "
             f"to {P80_TOL_REL:.1%} of it")
    if pick.feasible:
        msg = (f"P80 {pick.p80_um:.4g} um (target {target_p80_um:g}) with feed {pick.feed_tph:.4g} t/h, speed "
               f"{pick.speed_frac_critical:.3f} of critical, {pick.specific_energy_kwh_t:.2f} "
               f"kWh/t, load {pick.load_frac:.2f}")
        if pick.active:
            aim = "least specific energy" if objective == "min_energy" else "most throughput"
            msg += f"; on a constraint: {pick.active} (the {aim} without it lies beyond)"
        msg += f" ({scope})"
    else:
        msg = f"Target P80 {target_p80_um:g} um is infeasible in mode {mode!r} ({pick.note}; {scope})."
    return Setpoints(bool(pick.feasible), float(pick.feed_tph), float(pick.speed_frac_critical),
                     float(pick.p80_um), float(pick.specific_energy_kwh_t), float(pick.load_frac),
                     float(pick.power_kw), mode, objective, msg, table, str(pick.active))
