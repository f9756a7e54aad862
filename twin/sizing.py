"""Sizing a ball mill in closed circuit with hydrocyclones for an ore, a throughput and a target
product P80 (the job of Moly-Cop Tools's mill-sizing sheet, done here with the twin itself).

Rules, stated: the mill keeps the shape and charge of the base mill (length over diameter, ball
filling, ball size) and runs at the speed asked (a fraction of critical); its breakage rates come
from the laboratory calibration by the scale-up rules of :mod:`twin.scaleup` (Austin's diameter,
ball-size and speed factors) and its power from the base mill's power model; the circuit is the
mill with the default effects and a cluster of hydrocyclones (Plitt's equations,
twin.effects.classification) geometrically similar to the base design (inlet, vortex finder, apex
and free vortex height in proportion to the cyclone's diameter).

The design point, three conditions: the steady overflow P80 meets the target; the circulating
load is the design's (2.5, Wills & Finch 2016 ch. 9: 250 % typical of ball-mill circuits); the
cyclones run at the design feed pressure (:data:`DESIGN_CYCLONE_PRESSURE_KPA`). Three unknowns
meet them: the mill's diameter (which sets the circulating load), the cyclones' diameter (their
cut, which sets the product) and the sump's dilution, the cyclone feed's solids (the lever that
brings the cut to the design pressure: Plitt's d50c grows as exp(0.063 phi) with the feed's
solids phi by volume). They are solved by Newton's method for each count of cyclones, fewest
first (each count after the first from the last count's design point, else from its own first
guess; a count whose Newton failed is tried again from the first design found, so that a
solver's miss does not add cyclones); the answer is the fewest cyclones of a diameter made for
grinding circuits (:data:`CYCLONE_DIAMETER_RANGE_CM`) whose circuit has a stable load and needs no water taken out.
The result is written to ``twin/data/industrial_mill.json`` (with the command that made it) when
it is the ``industrial`` preset.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import warnings

import numpy as np
import scipy.sparse.linalg

from .effects.classification import CYCLONE_PRESSURE_RANGE_KPA, FEED_SOLIDS_VOL_PCT_MAX, Hydrocyclone, slurry_m3_h
from .atomic import is_grindtwin_checkout
from .errors import SolverError, TwinInputError, check_range
from .mill import CYCLONE_CIRCUITS, INDUSTRIAL_BASE, Mill, get_mill
from .twin import DEFAULT_EFFECTS, FEED_P80_UM, Twin
from .validity import water_shortfalls

#: Where a sized circuit's fresh feed enters (twin.mill.CYCLONE_CIRCUITS).
CIRCUITS = CYCLONE_CIRCUITS
#: Design circulating load (underflow over fresh feed) of a ball mill-cyclone circuit.
DESIGN_CIRCULATING_LOAD = 2.5
#: Design feed pressure of the cyclones [kPa]: 7.7 psi, that of the six-cyclone cluster of the
#: Moly-Cop Tools BallSim base case (scenarios/data/molycop_ballsim_published.toml).
DESIGN_CYCLONE_PRESSURE_KPA = 53.0
#: Mill diameters allowed [m]; cyclone diameters made for grinding circuits [cm] (4 to 33 in).
DIAMETER_RANGE_M = (0.8, 8.0)
#: A feed whose first-guess mill diameter (:func:`_first_guess`, from the base mill) is beyond this many times
#: the largest is refused before any sizing: from the industrial base the guess ran 1.51-1.59x the sized
#: diameter from 20 to 300 t/h of ore B at 210 um (the base's kW per t/h is not the design's), and targets
#: from 150 to 220 um or a speed of 0.9 move the design ~5 %; twice leaves room.
FIRST_GUESS_DIAMETER_MAX_FACTOR = 2.0
CYCLONE_DIAMETER_RANGE_CM = (10.16, 83.82)
#: Cyclone counts tried, fewest first.
MAX_CYCLONES = 16
#: Newton's method on the design point: its unknowns are ln(mill diameter), ln(cyclone diameter)
#: and the cyclone feed's solids % by volume / 10 (one scale); converged when every residual
#: (ln of each result over its design value) is below NEWTON_TOL; a step moves an unknown by at
#: most NEWTON_MAX_STEP (ln: 35 %); Jacobian by forward differences of NEWTON_FD_STEP.
NEWTON_TOL, NEWTON_MAX_STEP, NEWTON_FD_STEP, NEWTON_ITERATIONS = 1e-5, 0.3, 1e-3, 30
#: The first guess of the cyclone feed's solids [% by volume] (a dense coarse-cut feed).
FEED_SOLIDS_VOL_PCT_START = 40.0


@dataclass
class SizedMill:
    """A sized mill and its circuit at the design point."""

    mill: Mill
    cyclone: dict
    ore: str
    feed_tph: float
    target_p80_um: float
    p80_um: float
    circulating_load_frac: float
    power_kw: float
    specific_energy_kwh_t: float
    load_frac: float
    load_status: str
    tried: list = field(default_factory=list)  # per cyclone count: what the design point gave, or why none
    calibration: dict = field(default_factory=dict)  # the identity of the calibration it was sized with
    notes: list = field(default_factory=list)  # where the models do not describe the design point (twin.validity)
    circuit: dict = field(default_factory=dict)  # the cyclones' operating point and the water balance (CIRCUIT_KEYS)

    def record(self, command: str) -> dict:
        mill = {k: v for k, v in asdict(self.mill).items() if k in PRESET_FIELDS}
        return {"mill": mill, "cyclone": self.cyclone,
                "sizing": {"ore": self.ore, "feed_tph": self.feed_tph, "target_p80_um": self.target_p80_um,
                           "p80_um": self.p80_um, "circulating_load_frac": self.circulating_load_frac,
                           "power_kw": self.power_kw, "specific_energy_kwh_t": self.specific_energy_kwh_t,
                           "load_frac": self.load_frac, "load_status": self.load_status, **self.circuit,
                           "tried": self.tried},
                "calibration": self.calibration, "command": command}


#: The Mill fields a sized preset records (the rest are the base mill's).
PRESET_FIELDS = ("diameter_m", "length_m", "ball_filling_frac", "ball_size_mm", "speed_nominal_frac_critical",
                 "feed_nominal_tph", "power_model")
#: The circuit's outputs a sizing records beside the mill's.
CIRCUIT_KEYS = ("cyclone_pressure_kpa", "cyclone_d50c_um", "cyclone_water_bypass_frac", "cyclone_feed_solids_frac",
                "underflow_solids_frac", "overflow_solids_frac", "sump_water_m3_h", "mill_water_m3_h")


def circuit_twin(ore, mill: Mill, cyclone: dict, circuit: str = "direct", **kwargs) -> Twin:
    """The twin of a mill in closed circuit with its hydrocyclones (default effects), fresh feed to
    the mill (``"direct"``) or to the cyclones (``"reverse"``)."""
    options = {"classification": {"kind": "hydrocyclone", "cyclone": dict(cyclone), "circuit": circuit,
                                  "circulating_load_nominal": DESIGN_CIRCULATING_LOAD}}
    return Twin(ore, mill=mill, effects=list(DEFAULT_EFFECTS), effect_options=options, **kwargs)


def similar_cyclone(design: Hydrocyclone, diameter_cm: float, count: int, feed_solids_vol_pct: float) -> dict:
    """``count`` cyclones geometrically similar to ``design`` at ``diameter_cm``, fed at
    ``feed_solids_vol_pct`` solids by volume (a Hydrocyclone's fields)."""
    r = diameter_cm / design.diameter_cm
    return {**asdict(design), "diameter_cm": diameter_cm, "inlet_cm": design.inlet_cm * r,
            "vortex_finder_cm": design.vortex_finder_cm * r, "apex_cm": design.apex_cm * r,
            "free_vortex_height_cm": design.free_vortex_height_cm * r, "count": count,
            "feed_solids_vol_pct": feed_solids_vol_pct, "feed_solids_frac": None}


def _at(ore, base: Mill, diameter_m: float, cyclone: dict, feed_tph: float, speed: float, calibration, circuit):
    aspect = base.length_m / base.diameter_m
    mill = base.with_(diameter_m=diameter_m, length_m=aspect * diameter_m, feed_nominal_tph=feed_tph,
                      speed_nominal_frac_critical=speed, cyclone=tuple(sorted(cyclone.items())),
                      cyclone_circuit=circuit, sized_calibration=calibration.name)
    with warnings.catch_warnings():  # Newton on an overloading trial mill: the SolverError is the answer
        warnings.simplefilter("ignore", scipy.sparse.linalg.MatrixRankWarning)
        return mill, circuit_twin(ore, mill, cyclone, circuit, calibration=calibration).steady(
            feed_tph=feed_tph, speed_frac_critical=speed)


class _FeedOutOfRange(SolverError):
    """The cut would need a cyclone feed no slurry can be: more cyclones (smaller, cutting finer at
    the design pressure) would need a denser one still, once the cyclones are no larger than any
    made (``cyclone_cm``: their diameter at that trial); larger ones are no design anyway, and
    more of them may be."""

    def __init__(self, message: str, cyclone_cm: float):
        super().__init__(message)
        self.cyclone_cm = cyclone_cm


class _DesignPoint:
    """The design point's residuals for ``count`` cyclones of ``design``'s shape (module docstring)."""

    def __init__(self, ore, base, design, count, feed_tph, target_p80_um, speed, calibration, pressure_kpa,
                 circuit):
        self.args = ore, base, feed_tph, speed, calibration, circuit
        self.design, self.count, self.target, self.pressure_kpa = design, count, target_p80_um, pressure_kpa

    def cyclone(self, x) -> dict:
        return similar_cyclone(self.design, math.exp(x[1]), self.count, 10.0 * x[2])

    def __call__(self, x):
        ore, base, feed_tph, speed, calibration, circuit = self.args
        if not 0.0 < 10.0 * x[2] < FEED_SOLIDS_VOL_PCT_MAX:
            raise _FeedOutOfRange(f"the cut would need a cyclone feed of {10.0 * x[2]:.3g} % solids by volume "
                                  f"(a feed holds 0-{FEED_SOLIDS_VOL_PCT_MAX:g} %)", math.exp(x[1]))
        cyclone = self.cyclone(x)
        try:  # a trial outside what the models take (a 15-m cyclone, a 25-m mill) is a miss, not the user's input
            Hydrocyclone(**cyclone)
            base.with_(diameter_m=math.exp(x[0]), length_m=base.length_m / base.diameter_m * math.exp(x[0]))
        except TwinInputError as exc:
            raise SolverError(f"a trial of {math.exp(x[1]):.3g}-cm cyclones and a {math.exp(x[0]):.3g}-m mill, "
                              f"outside what the models take ({exc})") from None
        mill, ss = _at(ore, base, math.exp(x[0]), cyclone, feed_tph, speed, calibration, circuit)
        o = ss.outputs
        r = np.array([math.log(ss.p80_um / self.target),
                      math.log(o["circulating_load_frac"] / DESIGN_CIRCULATING_LOAD),
                      math.log(o["cyclone_pressure_kpa"] / self.pressure_kpa)])
        if not np.all(np.isfinite(r)):
            raise SolverError("a non-finite design residual")
        return r, mill, ss


def _newton(point: _DesignPoint, x):
    """Damped Newton's method from ``x`` (NEWTON_* constants); (x, mill, steady state), or
    SolverError naming why it stopped."""
    r, mill, ss = point(x)
    for _ in range(NEWTON_ITERATIONS):
        if np.max(np.abs(r)) < NEWTON_TOL:
            return x, mill, ss
        jac = np.empty((3, 3))
        for j in range(3):
            xj = x.copy()
            xj[j] += NEWTON_FD_STEP
            jac[:, j] = (point(xj)[0] - r) / NEWTON_FD_STEP
        try:
            step = np.linalg.solve(jac, -r)
        except np.linalg.LinAlgError:
            raise SolverError("the design point's Jacobian is singular") from None
        step *= min(1.0, NEWTON_MAX_STEP / np.max(np.abs(step)))
        for _ in range(6):  # halve a step into a circuit with no steady state (an overloaded trial mill)
            try:
                r_new, mill, ss = point(x + step)
                break
            except SolverError:
                step /= 2.0
        else:
            raise SolverError("every step from the last design point lands on a circuit with no steady state")
        x, r = x + step, r_new
    if np.max(np.abs(r)) < NEWTON_TOL:
        return x, mill, ss
    raise SolverError(f"Newton's method did not converge in {NEWTON_ITERATIONS} iterations (residuals {r.round(4)})")


def _refuse_feed_beyond_mills(base: Mill, feed_tph: float) -> None:
    """A feed whose first-guess mill (:func:`_first_guess`'s power scaling) is beyond
    :data:`FIRST_GUESS_DIAMETER_MAX_FACTOR` x the largest diameter made: 31,000 t/h (kg/h typed as t/h) ran
    every cyclone count and failed blaming the cyclones' pressure."""
    guess_m = base.diameter_m * (feed_tph / base.feed_nominal_tph) ** (1.0 / 3.5)
    if guess_m > FIRST_GUESS_DIAMETER_MAX_FACTOR * DIAMETER_RANGE_M[1]:
        raise TwinInputError(f"The 'feed_tph' parameter of size_mill is {feed_tph:g} t/h: by Bond's power scaling "
                             f"from the {base.name!r} mill ({base.diameter_m:.3g} m at {base.feed_nominal_tph:g} t/h) "
                             f"one mill would be about {guess_m:.3g} m across, and ball mills are made up to "
                             f"{DIAMETER_RANGE_M[1]:g} m: give the feed of one mill (in t/h, not kg/h).")


def _first_guess(design: Hydrocyclone, base: Mill, count: int, feed_tph: float, rho: float,
                 pressure_kpa: float) -> np.ndarray:
    """Mill diameter by power proportional to feed at constant shape (P ~ D^3.5: Bond's D^2.5 L);
    cyclone diameter from Plitt's pressure at the design's load and the starting dilution, at
    which pressure scales as diameter^-3.33 for similar cyclones (Plitt's exponents summed)."""
    d_mill = float(np.clip(base.diameter_m * (feed_tph / base.feed_nominal_tph) ** (1.0 / 3.5), *DIAMETER_RANGE_M))
    cyc = Hydrocyclone(**similar_cyclone(design, design.diameter_cm, count, FEED_SOLIDS_VOL_PCT_START))
    p_kpa = float(cyc.plitt(slurry_m3_h(cyc, feed_tph * (1.0 + DESIGN_CIRCULATING_LOAD), rho), rho)["pressure_kpa"])
    d_cyc = design.diameter_cm * (p_kpa / pressure_kpa) ** (1.0 / 3.33)
    return np.array([math.log(d_mill), math.log(d_cyc), FEED_SOLIDS_VOL_PCT_START / 10.0])


def _fewer(trial, unsolved: list, tried: list, found: tuple, first: np.ndarray) -> tuple:
    """The design with the fewest cyclones: ``found`` (point, count, x, mill, steady state, from
    its first guess ``first``), or that of a count in ``unsolved`` (fewer cyclones, whose Newton
    failed from its own start) that Newton reaches from ``found``'s design point. Its ``tried``
    entry then says so."""
    _, count, x, _, _ = found
    for c in unsolved:
        point_c, first_c = trial(c)
        try:
            x_c, mill_c, ss_c = _newton(point_c, _from_last(first_c, x, first))
        except SolverError:
            continue
        why = _unrunnable(mill_c, math.exp(x_c[1]), ss_c)
        entry = next(t for t in tried if t["count"] == c)
        entry.update(_tried(c, x_c, mill_c, f"{why or 'design'} (from the {count}-cyclone design point; from its "
                                            f"own first guess, {entry['outcome']})"))
        if why is None:
            return point_c, c, x_c, mill_c, ss_c
    return found


def _tried(count: int, x: np.ndarray, mill: Mill, outcome: str) -> dict:
    """What a sizing records of a count whose Newton converged (``tried``)."""
    return {"count": count, "diameter_m": mill.diameter_m, "cyclone_diameter_cm": math.exp(x[1]),
            "feed_solids_vol_pct": float(10.0 * x[2]), "outcome": outcome}


def _newton_from(point: _DesignPoint, starts: list):
    """:func:`_newton` from each start in turn until one converges; the last one's SolverError
    if none does."""
    for k, start in enumerate(starts):
        try:
            return _newton(point, start)
        except SolverError:
            if k == len(starts) - 1:
                raise


def _from_last(first: np.ndarray, x_last: np.ndarray, first_last: np.ndarray) -> np.ndarray:
    """A count's start from the last count's design point: its mill and its feed's dilution (the
    grind sets the mill, which the count barely moves), its cyclones scaled as the two counts'
    first guesses are (Plitt's pressure at the design's flow)."""
    return np.array([x_last[0], x_last[1] + first[1] - first_last[1], x_last[2]])


def load_design_cyclone(path) -> Hydrocyclone:
    """The cyclone whose shape and Plitt model a sizing scales: a TOML file holding one cyclone
    table, as a scene's ``effect_options.classification.cyclone`` (geometry, Plitt factors or a
    ``survey``); its count and dilution are the sizing's to choose. TwinInputError naming the file."""
    import tomllib

    from .errors import TwinError
    from .effects.classification import hydrocyclone_from

    path = Path(path)
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise TwinInputError(f"The cyclone file {path} was not found.") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise TwinInputError(f"The cyclone file {path} is not a readable TOML file: {exc}.") from None
    try:
        cyclone = hydrocyclone_from(table)
    except TwinError as exc:
        raise TwinInputError(f"The cyclone file {path}: {exc}") from None
    if cyclone.mode == "direct":
        raise TwinInputError(f"The cyclone file {path} gives d50c_um, sharpness and water_bypass_frac, which stay "
                             "fixed whatever the cyclone: a sizing needs Plitt's equations (give its factors or "
                             "its 'survey' instead).")
    return cyclone


#: The open intervals size_mill takes its numbers in (`grindtwin size-mill`'s parser checks them here too).
SIZE_MILL_RANGES = {"feed_tph": (0.0, 1e5), "target_p80_um": (1.0, 1e4), "speed_frac_critical": (0.3, 0.95),
                    "cyclone_pressure_kpa": CYCLONE_PRESSURE_RANGE_KPA}


def check_size_mill_input(name: str, value) -> float:
    """``value`` of size_mill's parameter ``name`` as a float, or TwinInputError naming it and its
    range (:data:`SIZE_MILL_RANGES`; a target no finer than the feed is refused too)."""
    v = check_range("size_mill", name, value, *SIZE_MILL_RANGES[name])
    if name == "target_p80_um" and not v < FEED_P80_UM:  # the Newton failure said nothing of why
        raise TwinInputError(f"The 'target_p80_um' parameter of size_mill must be finer than the feed the sizing "
                             f"grinds (P80 {FEED_P80_UM:g} um): no mill coarsens its feed. Got {v:g}.")
    return v


def size_mill(ore="B", feed_tph: float = 31.0, target_p80_um: float = 210.0, speed_frac_critical: float = 0.70,
              base: str | Mill = INDUSTRIAL_BASE, cyclone: Hydrocyclone | None = None,
              calibration=None, cyclone_pressure_kpa: float = DESIGN_CYCLONE_PRESSURE_KPA,
              circuit: str = "direct") -> SizedMill:
    """Size the mill and its cyclones (module docstring) with ``calibration`` (default: the
    default calibration), the cyclones of ``cyclone``'s shape at ``cyclone_pressure_kpa``, in a
    ``circuit`` of :data:`CIRCUITS`; TwinInputError for bad inputs, SolverError naming why each
    cyclone count failed if none gives a design point."""
    from .calibration import load_calibration
    from .twin import _as_blend

    # the checked floats are used (text is refused by check_range; numpy scalars become floats)
    feed_tph, target_p80_um, speed_frac_critical, cyclone_pressure_kpa = (
        check_size_mill_input(name, value) for name, value in (
            ("feed_tph", feed_tph), ("target_p80_um", target_p80_um), ("speed_frac_critical", speed_frac_critical),
            ("cyclone_pressure_kpa", cyclone_pressure_kpa)))
    calibration = load_calibration(calibration)
    if circuit not in CIRCUITS:
        raise TwinInputError(f"The 'circuit' parameter of size_mill must be one of {', '.join(map(repr, CIRCUITS))} "
                             f"(fresh feed to the mill, or to the cyclones). Got {circuit!r}.")
    base = get_mill(base)
    _refuse_feed_beyond_mills(base, feed_tph)
    design = cyclone or Hydrocyclone()
    if design.mode == "direct":  # a fixed cut cannot be sized to the target
        raise TwinInputError("The 'cyclone' parameter of size_mill must be a cyclone modelled by Plitt's equations "
                             "(its factors, or a survey), not one given by a fixed d50c_um, sharpness and bypass.")
    rho = _as_blend(ore).density_t_m3

    def trial(count):  # the design point's residuals and Newton's first guess for ``count`` cyclones
        return (_DesignPoint(ore, base, design, count, feed_tph, target_p80_um, speed_frac_critical, calibration,
                             cyclone_pressure_kpa, circuit),
                _first_guess(design, base, count, feed_tph, rho, cyclone_pressure_kpa))

    tried, last = [], None  # last: the design point of the last count that had one, and its first guess
    unsolved = []  # counts whose Newton failed (not a feed no slurry can be): the solver's, not the circuit's
    for count in range(1, MAX_CYCLONES + 1):
        point, first = trial(count)
        try:
            x, mill, ss = _newton_from(point, [first] if last is None else [_from_last(first, *last), first])
        except SolverError as exc:
            tried.append({"count": count, "outcome": f"no design point: {exc}"})
            if isinstance(exc, _FeedOutOfRange) and exc.cyclone_cm <= CYCLONE_DIAMETER_RANGE_CM[1]:
                break
            if not isinstance(exc, _FeedOutOfRange):
                unsolved.append(count)
            continue
        last = (x, first)
        d_cyc = math.exp(x[1])
        why = _unrunnable(mill, d_cyc, ss)
        tried.append(_tried(count, x, mill, why or "design"))
        if why is None:
            point, count, x, mill, ss = _fewer(trial, unsolved, tried, (point, count, x, mill, ss), first)
            o = ss.outputs
            if cyclone is not None and count != cyclone.count:  # the user's table had its own count
                ss.notes.append(f"{count} cyclone{'s' * (count > 1)}, not the cyclone table's {cyclone.count}: a "
                                "sizing chooses the count; the table gives the shape and the Plitt model")
            return SizedMill(mill, point.cyclone(x), getattr(ore, "name", str(ore)), feed_tph, target_p80_um,
                             ss.p80_um, o["circulating_load_frac"], o["power_kw"], o["specific_energy_kwh_t"],
                             o["load_frac"], ss.load_status, tried, calibration.identity(), ss.notes,
                             {k: float(o[k]) for k in CIRCUIT_KEYS}
                             | {"design_cyclone_pressure_kpa": cyclone_pressure_kpa, "circuit": circuit})
        if d_cyc < CYCLONE_DIAMETER_RANGE_CM[0] or ss.outputs["sump_water_m3_h"] < 0.0:
            break  # more cyclones are smaller and, at the design pressure, cut finer: they need a denser feed
        if not DIAMETER_RANGE_M[0] <= mill.diameter_m <= DIAMETER_RANGE_M[1]:
            break  # the grind sets the mill: other counts of cyclones, or another pressure, barely move it
    mill_out = any(not DIAMETER_RANGE_M[0] <= t.get("diameter_m", DIAMETER_RANGE_M[0]) <= DIAMETER_RANGE_M[1]
                   for t in tried)
    raise SolverError(f"No circuit gives P80 {target_p80_um:g} um at {feed_tph:g} t/h with circulating load "
                      f"{DESIGN_CIRCULATING_LOAD:g} and the cyclones at {cyclone_pressure_kpa:g} kPa: "
                      + _misses_text(tried)
                      + (" (the grind sets the mill's diameter, which neither the cyclones nor their pressure move: "
                         "another feed rate per mill or another target may)" if mill_out else
                         " (another design pressure may: size-mill --cyclone-pressure-kpa)."))


def _unrunnable(mill: Mill, d_cyc: float, ss) -> str | None:
    """Why a design point is not a circuit to build (every reason, joined), or None."""
    lo, hi = CYCLONE_DIAMETER_RANGE_CM
    o, why = ss.outputs, []
    if not lo <= d_cyc <= hi:
        why.append(f"cyclones of {d_cyc:.3g} cm, outside the {lo:g}-{hi:g} cm made")
    if not DIAMETER_RANGE_M[0] <= mill.diameter_m <= DIAMETER_RANGE_M[1]:
        why.append(f"a {mill.diameter_m:.3g}-m mill, outside {DIAMETER_RANGE_M[0]:g}-{DIAMETER_RANGE_M[1]:g} m")
    if ss.load_status != "stable":
        why.append(f"the mill's load {ss.load_status} its stable band (load {o['load_frac']:.3g} of nominal)")
    short = water_shortfalls(o)
    if short:
        why.append("water taken out (" + ", ".join(f"{k} {v:.3g}" for k, v in short.items()) + ")")
    return " and ".join(why) or None


def _misses_text(tried: list) -> str:
    """Why each cyclone count gave no circuit, counts with one reason joined (``1-3, 5``)."""
    reasons: dict[str, list[int]] = {}
    for t in tried:
        reasons.setdefault(t["outcome"], []).append(t["count"])
    return "; ".join(f"with {_counts(counts)} cyclone{'s' * (counts != [1])}, {why}" for why, counts in reasons.items())


def _counts(counts: list[int]) -> str:
    """``[1, 2, 3, 5]`` -> ``"1-3, 5"``."""
    runs, start = [], counts[0]
    for a, b in zip(counts, counts[1:] + [None]):
        if b != a + 1:
            runs.append(f"{start}" if start == a else f"{start}-{a}")
            start = b
    return ", ".join(runs)


#: The packages of the grindtwin distribution (pyproject.toml), folders beside this one.
DISTRIBUTION_PACKAGES = ("twin", "dem", "mpc", "scenarios")


def check_preset_path(path) -> Path:
    """``path`` if a preset may be written there: a new file in an existing folder, or a preset
    file grindtwin wrote; never inside grindtwin's own packages, but for the shipped ``industrial``
    preset in a checkout of the repository; TwinInputError otherwise (called before any sizing work)."""
    from .errors import TwinInputError
    from .mill import INDUSTRIAL_PRESET_PATH, PRESET_KEYS

    if not str(path).strip():  # Path("") is the current folder
        raise TwinInputError(f"The preset output path is empty ({str(path)!r}); give a file path.")
    path = Path(path)
    if path.is_dir():
        raise TwinInputError(f"The preset output {path} is a folder; give a file path.")
    root, resolved = Path(__file__).resolve().parents[1], path.resolve()
    for name in DISTRIBUTION_PACKAGES:
        if resolved.is_relative_to(root / name):
            shipped = resolved == INDUSTRIAL_PRESET_PATH.resolve()
            if not (shipped and is_grindtwin_checkout(root)):
                raise TwinInputError(
                    f"Refusing to write the preset {path} inside grindtwin's package {root / name}: give a path "
                    "outside it" + (" (the shipped industrial preset is rewritten only in a checkout of the "
                                    "grindtwin repository, not in an installed package)." if shipped else "."))
    if path.exists():
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            record = None
        if not (isinstance(record, dict) and all(k in record for k in PRESET_KEYS)):
            raise TwinInputError(f"Refusing to overwrite {path}: it is not a mill preset grindtwin wrote.")
    if not path.parent.is_dir():
        raise TwinInputError(f"The folder of the preset output {path} "
                             + ("is a file." if path.parent.exists() else "does not exist."))
    return path


def write_preset(sized: SizedMill, command: str, path) -> Path:
    """Write the sized mill as a preset file at ``path`` (the shipped ``industrial`` preset is
    INDUSTRIAL_PRESET_PATH, written only when named), atomically."""
    from .calibration.files import write_json_atomically
    from .mill import industrial_preset

    path = check_preset_path(path)
    write_json_atomically(path, sized.record(command))
    industrial_preset.cache_clear()
    return path


