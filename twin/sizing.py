"""Sizing a ball mill in closed circuit with hydrocyclones for an ore, a throughput and a target
product P80 (the job of Moly-Cop Tools's mill-sizing sheet, done here with the twin itself).

Rules, stated: the mill keeps the shape and charge of the base mill (length over diameter, ball
filling, ball size, speed as a fraction of critical); its breakage rates come from the laboratory
calibration by the scale-up rules of :mod:`twin.scaleup` and its power from the base mill's power
model; the circuit is the mill with the default effects and a cluster of hydrocyclones of the
base design (Plitt's equations, twin.effects.classification) at the mill's nominal circulating
load. For each count of cyclones the diameter is solved so that the steady overflow P80 meets the
target; the count whose circulating load is nearest the design's (2.5, Wills & Finch 2016 ch. 9:
250 % typical of ball-mill circuits) is the answer, provided the mill's load is in its stable
band there. The result is written to ``twin/data/industrial_mill.json`` (with the command that
made it) when it is the ``industrial`` preset.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import warnings

import scipy.optimize
import scipy.sparse.linalg

from .effects.classification import Hydrocyclone
from .errors import SolverError, TwinInputError, check_range
from .mill import INDUSTRIAL_BASE, Mill, get_mill
from .twin import DEFAULT_EFFECTS, FEED_P80_UM, Twin

#: Design circulating load (underflow over fresh feed) of a ball mill-cyclone circuit.
DESIGN_CIRCULATING_LOAD = 2.5
#: Mill diameters searched [m] and cyclone counts tried.
DIAMETER_RANGE_M = (0.8, 8.0)
MAX_CYCLONES = 16


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
    tried: list = field(default_factory=list)  # (cyclones, diameter_m or None, circulating load)
    calibration: dict = field(default_factory=dict)  # the identity of the calibration it was sized with
    notes: list = field(default_factory=list)  # where the models do not describe the design point (twin.validity)

    def record(self, command: str) -> dict:
        mill = {k: v for k, v in asdict(self.mill).items() if k in PRESET_FIELDS}
        return {"mill": mill, "cyclone": self.cyclone,
                "sizing": {"ore": self.ore, "feed_tph": self.feed_tph, "target_p80_um": self.target_p80_um,
                           "p80_um": self.p80_um, "circulating_load_frac": self.circulating_load_frac,
                           "power_kw": self.power_kw, "specific_energy_kwh_t": self.specific_energy_kwh_t,
                           "load_frac": self.load_frac, "load_status": self.load_status, "tried": self.tried},
                "calibration": self.calibration, "command": command}


#: The Mill fields a sized preset records (the rest are the base mill's).
PRESET_FIELDS = ("diameter_m", "length_m", "ball_filling_frac", "ball_size_mm", "speed_nominal_frac_critical",
                 "feed_nominal_tph", "power_model")


def circuit_twin(ore, mill: Mill, cyclone: dict, **kwargs) -> Twin:
    """The twin of a mill in closed circuit with its hydrocyclones (default effects)."""
    options = {"classification": {"kind": "hydrocyclone", "cyclone": dict(cyclone),
                                  "circulating_load_nominal": DESIGN_CIRCULATING_LOAD}}
    return Twin(ore, mill=mill, effects=list(DEFAULT_EFFECTS), effect_options=options, **kwargs)


def _at(ore, base: Mill, diameter_m: float, cyclone: dict, feed_tph: float, speed: float, calibration):
    aspect = base.length_m / base.diameter_m
    mill = base.with_(diameter_m=diameter_m, length_m=aspect * diameter_m, feed_nominal_tph=feed_tph,
                      speed_nominal_frac_critical=speed, cyclone=tuple(sorted(cyclone.items())))
    return mill, circuit_twin(ore, mill, cyclone, calibration=calibration).steady(
        feed_tph=feed_tph, speed_frac_critical=speed)


def size_mill(ore="B", feed_tph: float = 31.0, target_p80_um: float = 210.0, speed_frac_critical: float = 0.70,
              base: str | Mill = INDUSTRIAL_BASE, cyclone: Hydrocyclone | None = None,
              calibration=None) -> SizedMill:
    """Size the mill (module docstring) with ``calibration`` (default: the default calibration);
    TwinInputError for bad inputs, SolverError if no cyclone count and diameter in range meet
    the target with a stable load."""
    from .calibration import load_calibration

    calibration = load_calibration(calibration)
    check_range("size_mill", "feed_tph", feed_tph, 0.0, 1e5)
    check_range("size_mill", "target_p80_um", target_p80_um, 1.0, 1e4)
    if not target_p80_um < FEED_P80_UM:  # the Newton failure said nothing of why
        raise TwinInputError(f"The 'target_p80_um' parameter of size_mill must be finer than the feed the sizing "
                             f"grinds (P80 {FEED_P80_UM:g} um): no mill coarsens its feed. Got {target_p80_um:g}.")
    check_range("size_mill", "speed_frac_critical", speed_frac_critical, 0.3, 0.95)
    base = get_mill(base)
    design = asdict(cyclone or Hydrocyclone())
    tried, found, missed = [], [], {}
    for count in range(1, MAX_CYCLONES + 1):
        cyc = {**design, "count": count}

        def gap(log_d):
            try:
                with warnings.catch_warnings():  # Newton on an overloading trial mill: failure is the answer
                    warnings.simplefilter("ignore", scipy.sparse.linalg.MatrixRankWarning)
                    ss = _at(ore, base, math.exp(log_d), cyc, feed_tph, speed_frac_critical, calibration)[1]
                return math.log(ss.p80_um / target_p80_um)
            except SolverError:  # no steady state (the circuit overloads): the mill is too small
                return 1.0
        lo, hi = (math.log(d) for d in DIAMETER_RANGE_M)
        if gap(lo) < 0:
            tried.append((count, None, None))
            missed.setdefault("finer", []).append(count)
            continue
        if gap(hi) > 0:
            tried.append((count, None, None))
            missed.setdefault("coarser", []).append(count)
            continue
        d = math.exp(scipy.optimize.brentq(gap, lo, hi, xtol=1e-4))
        mill, ss = _at(ore, base, d, cyc, feed_tph, speed_frac_critical, calibration)
        cl = ss.outputs["circulating_load_frac"]
        tried.append((count, d, cl))
        found.append((abs(cl - DESIGN_CIRCULATING_LOAD), count, mill, ss, cyc))
        if cl <= DESIGN_CIRCULATING_LOAD:
            break
    stable = [f for f in found if f[3].load_status == "stable"]
    if not stable:
        raise SolverError(f"No mill from {DIAMETER_RANGE_M[0]} to {DIAMETER_RANGE_M[1]} m with 1-{count} "
                          f"cyclones of the base design gives P80 {target_p80_um:g} um at {feed_tph:g} t/h with a "
                          f"stable load: {_misses_text(missed, found, target_p80_um)}.")
    _, count, mill, ss, cyc = min(stable, key=lambda f: f[0])
    o = ss.outputs
    return SizedMill(mill, cyc, getattr(ore, "name", str(ore)), feed_tph, target_p80_um, ss.p80_um, o["circulating_load_frac"],
                     o["power_kw"], o["specific_energy_kwh_t"], o["load_frac"], ss.load_status, tried,
                     calibration.identity(), ss.notes)


def _misses_text(missed: dict, found: list, target_p80_um: float) -> str:
    """Why each cyclone count gave no answer, for :func:`size_mill`'s error: the diameter range's
    smallest mill already grinds finer than the target, its largest still coarser (or overloads),
    or the diameter found leaves the load outside its stable band."""
    lo, hi = DIAMETER_RANGE_M
    parts = []
    if missed.get("finer"):
        parts.append(f"with {_counts(missed['finer'])} cyclones even the {lo:g}-m mill grinds finer than "
                     f"{target_p80_um:g} um")
    if missed.get("coarser"):
        parts.append(f"with {_counts(missed['coarser'])} cyclones even the {hi:g}-m mill grinds coarser than "
                     f"{target_p80_um:g} um or overloads")
    parts += [f"with {count} cyclones the {mill.diameter_m:.2f}-m mill that meets it runs its load {ss.load_status} "
              f"its stable band (load {ss.outputs['load_frac']:.3g} of nominal)" for _, count, mill, ss, _ in found]
    return "; ".join(parts)


def _counts(counts: list[int]) -> str:
    """``[1, 2, 3, 5]`` -> ``"1-3, 5"``."""
    runs, start = [], counts[0]
    for a, b in zip(counts, counts[1:] + [None]):
        if b != a + 1:
            runs.append(f"{start}" if start == a else f"{start}-{a}")
            start = b
    return ", ".join(runs)


#: The keys of a preset file grindtwin wrote (:meth:`SizedMill.record`).
PRESET_KEYS = ("mill", "cyclone", "sizing", "command")


def check_preset_path(path) -> Path:
    """``path`` if a preset may be written there: a new file in an existing folder, or a preset
    file grindtwin wrote; TwinInputError otherwise (called before any sizing work)."""
    from .errors import TwinInputError

    path = Path(path)
    if path.is_dir():
        raise TwinInputError(f"The preset output {path} is a folder; give a file path.")
    if path.exists():
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            record = None
        if not (isinstance(record, dict) and all(k in record for k in PRESET_KEYS)):
            raise TwinInputError(f"Refusing to overwrite {path}: it is not a mill preset grindtwin wrote.")
    if not path.parent.is_dir():
        raise TwinInputError(f"The folder of the preset output {path} does not exist.")
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


