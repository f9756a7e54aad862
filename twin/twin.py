"""The Twin facade: ores + mill + effects -> a built model, with steady state and simulation.

    >>> from twin import Twin
    >>> t = Twin("B", mill="lab")
    >>> ss = t.steady(feed_tph=0.031, speed_frac_critical=0.70)
    >>> 150 < ss.p80_um < 300
    True
"""

from __future__ import annotations

import math
from pathlib import Path

from collections.abc import Callable, Sequence

import numpy as np

from .breakage import BreakageParams
from .breakage import ore_breakage as _ore_breakage
from .calibration import check_model, load_calibration
from .effects.classification import sized_circuit_notes
from .effects.registry import problems as effect_problems
from .errors import ModelError, TwinInputError, bad_value, check_int, check_range
from .mill import FEED_TPH_MAX, SPEED_FACTOR_ZERO_FRAC_CRITICAL, Mill, get_mill, power_kw
from .model import Model, ModelSpec
from .scaleup import scale_breakage
from .ore import (CLAY_MINERALS, CUSHIONING_MINERALS, Blend, Mineralogy, blend_sum_ok, blend_sum_tolerance, load_ore,
                  normalised_blend)
from .sizes import GatesGaudinSchuhmann, SizeGrid, TabulatedPSD, discretise, pxx_um
from .solve import simulate, steady_state, steady_state_at_load
from .validity import nominal_feed_note

#: The effects of the laboratory mill's calibration: a continuous grate-discharge mill with load
#: dynamics, speed-dependent rates, cushioning by clay and mica, clay slurry rheology, and power.
DEFAULT_EFFECTS = ("breakage", "transport", "holdup", "speed", "cushioning", "rheology", "power", "classification")
#: Feed size of the laboratory tests (MISSION.md: feed P80 3.2 mm) and the GGS modulus of a
#: crusher product (Gupta & Yan 2016, ch. 3: 0.7-1.0).
FEED_P80_UM = 3200.0
FEED_GGS_MODULUS = 0.8


class Twin:
    """A mill twin for a set of ore components.

    ``ores``: a reference type ('B'), a Blend, or a sequence of ores (types, TOML paths,
    Mineralogy); the nominal blend (defaults, and the density the nominal hold-up's volume is stated at) is the
    Blend's fractions, else equal shares. The mill fills by volume, each ore at its own density, and its grate and
    cyclones cut each ore at its own density (so a feed of one ore grinds alike whatever other ores the twin
    lists, and a dense ore in a blend is held back finer).
    ``calibration``: a shipped name (``"dem"``, the
    default, or ``"table"``), a calibration file's path or a :class:`twin.calibration.Calibration`;
    it maps each ore's mineralogy to its breakage parameters and gives the coefficients the
    effects read and the fitted mill values. ``breakage_map(ore, coefficients)`` replaces its
    mineralogy -> BreakageParams map.
    ``feed_psd`` overrides the feed size distribution (object with ``passing`` or class fractions).
    ``ore_breakage`` maps component names to :class:`twin.BreakageParams` given directly (e.g. an
    ore's published energy-specific parameters), which replace the map for those ores;
    ``solids_density_t_m3`` replaces the ores' mineral densities: a number, every ore at it; a dict by component
    name, those ores' (each ore still held and cut at its own density); ``mixer_volume_fracs`` gives the
    mixers' shares of the hold-up (e.g. Whiten's one large and two small, (0.7, 0.15, 0.15)) in
    place of ``n_mixers`` equal ones. The map's parameters describe the calibration's mill
    (``calibrated_mill``, the laboratory mill): on another mill they are scaled to it by
    :func:`twin.scaleup.scale_breakage` (Austin's diameter and ball-size rules); parameters given
    in ``ore_breakage`` are taken as this mill's own.

    A twin whose effects, size grid or (on the calibration's own mill) mixers differ from those
    the calibration was fitted with (:meth:`twin.calibration.Calibration.mismatch`) is built, not
    refused (benchmarks and studies do so on purpose), but says so: ``calibration_mismatch`` lists
    each difference and ``notes`` (which every steady state carries) has one note for each. This
    holds with a ``breakage_map`` or ``ore_breakage`` too: the calibration's coefficients (read by
    the effects) and its fitted mill values are used whatever maps the breakage. Scenes refuse
    such a twin unless ``calibration_mismatch_ok = true`` (scenarios.run.models).
    """

    def __init__(self, ores="B", mill: str | Mill = "lab", effects: Sequence[str] = DEFAULT_EFFECTS,
                 effect_options: dict | None = None, grid: SizeGrid | None = None, n_mixers: int = 3,
                 feed_p80_um: float = FEED_P80_UM, feed_modulus: float = FEED_GGS_MODULUS, feed_psd=None,
                 breakage_map: Callable | None = None, calibration=None,
                 ore_breakage: dict | None = None, solids_density_t_m3: float | dict | None = None,
                 mixer_volume_fracs: Sequence[float] | None = None, calibrated_mill: str | Mill = "lab"):
        # what the twin is made of, as given: a pickled twin is these, rebuilt (__reduce__)
        self._arguments = dict(ores=ores, mill=mill, effects=effects, effect_options=effect_options, grid=grid,
                               n_mixers=n_mixers, feed_p80_um=feed_p80_um, feed_modulus=feed_modulus,
                               feed_psd=feed_psd, breakage_map=breakage_map, calibration=calibration,
                               ore_breakage=ore_breakage, solids_density_t_m3=solids_density_t_m3,
                               mixer_volume_fracs=mixer_volume_fracs, calibrated_mill=calibrated_mill)
        if isinstance(effects, str):  # list("breakage") is its letters
            raise bad_value("Twin", "effects", effects, "a list of effect names, e.g. ['breakage', 'transport']")
        _check_effects(effects, effect_options)
        if not isinstance(mill, Mill):
            get_mill(mill)  # a misspelt name said before the calibration loads (a second on a fresh interpreter)
        self.blend = _as_blend(ores)
        self.calibration = load_calibration(calibration)
        from .calibration import predict_table  # scipy's optimiser with it: only when a twin is built

        check_model(self.calibration, predict_table)  # its fit's equations are these (once per file, process)
        self.coefficients = dict(self.calibration.coefficients)
        self.mill = get_mill(mill, self.calibration.record)
        self.grid = grid or SizeGrid()
        mixer_fracs = _mixer_fracs(n_mixers, mixer_volume_fracs)
        given = _given_breakage(ore_breakage, self.blend.names)
        if solids_density_t_m3 is None or isinstance(solids_density_t_m3, dict):  # each ore at its own
            own = _given_densities(solids_density_t_m3, self.blend)
            density = 1.0 / sum(f / r for f, r in zip(self.blend.fractions, own))  # the nominal blend's
        else:
            density = check_range("Twin", "solids_density_t_m3", solids_density_t_m3, 1.0, 25.0)
            own = ()
        holdup_nom = self.mill.nominal_holdup_t(density)
        power_nom = power_kw(self.mill, self.mill.speed_nominal_frac_critical)
        self.calibrated_mill = get_mill(calibrated_mill, self.calibration.record)
        # pickled as read, not as named: a worker does not read an ore's, a calibration's or a preset's file again
        self._arguments.update(ores=self.blend, calibration=self.calibration, mill=self.mill,
                               calibrated_mill=self.calibrated_mill)
        params = [given.get(o.name) or self.scaled_breakage(
            breakage_map(o, self.coefficients) if breakage_map else self.calibration.breakage(o), density)
            for o in self.blend.ores]
        breakage = [_ore_breakage(self.grid, p, power_nom, holdup_nom) for p in params]
        #: What differs from the calibration's effects, grid and mixers (Calibration.mismatch).
        self.calibration_mismatch = self.calibration.mismatch(effects, self.grid, self.mill, mixer_fracs)
        if self.calibrated_mill.name != self.calibration.mill:  # its breakage read as another mill's
            self.calibration_mismatch.append(
                f"calibrated_mill {self.calibrated_mill.name!r}: calibration {self.calibration.name!r} was fitted on "
                f"mill {self.calibration.mill!r}, whose breakage the twin would scale as if measured in "
                f"{self.calibrated_mill.name!r}")
        #: The notes of those differences, worded for a user of the Python API.
        self.mismatch_notes = [calibration_mismatch_note(p) for p in self.calibration_mismatch]
        #: What a steady state of this twin cannot show: the differences from its calibration, a
        #: calibration whose fit did not converge (Calibration.fit_notes), what the calibration's map
        #: leaves out of its ores (Calibration.ore_notes) and a mill run in another circuit than it
        #: was sized in (sized_circuit_notes).
        self.notes = self.mismatch_notes + self.calibration.fit_notes()
        if not breakage_map:
            self.notes += self.calibration.ore_notes([o for o in self.blend.ores if given.get(o.name) is None])
        feed = _feed_fractions(self.grid, feed_psd, _one_number("feed_p80_um", feed_p80_um, "um"),
                               _one_number("feed_modulus", feed_modulus, "-"))
        self.spec = ModelSpec(
            grid=self.grid, mill=self.mill, component_names=self.blend.names, breakage=breakage,
            feed_frac=feed, feed_nominal_tph=self.mill.feed_nominal_tph, holdup_nominal_t=holdup_nom,
            solids_density_t_m3=density, component_density_t_m3=tuple(own),
            soft_frac=[o.group_fraction(CUSHIONING_MINERALS) for o in self.blend.ores],
            clay_frac=[o.group_fraction(CLAY_MINERALS) for o in self.blend.ores],
            coefficients=self.coefficients, n_mixers=len(mixer_fracs), mixer_fracs=mixer_fracs, effects=list(effects),
            effect_options=dict(effect_options or {}))
        self.notes += sized_circuit_notes(self.spec)  # a mill sized in one circuit, run in another
        self.notes += [n for n in [nominal_feed_note(self.mill)] if n]  # another mill's nominal feed
        if self.mill.sized_calibration and self.mill.sized_calibration != self.calibration.name:
            self.notes.append(f"mill {self.mill.name!r} was sized under calibration {self.mill.sized_calibration!r}; "
                              f"this twin runs calibration {self.calibration.name!r}, whose breakage is another: the "
                              "P80 and throughput it was sized for do not hold under it")
        self.model = Model(self.spec)

    def __reduce__(self):
        """A twin pickles as the arguments it was made with (its ores, calibration and mills as read, not the
        files they were read from) and is rebuilt from them where it is loaded (a worker process of a pool): its
        model's CasADi expressions do not pickle. A ``breakage_map`` must then be a module-level function (a
        lambda does not pickle)."""
        return _rebuilt, (type(self), self._arguments)

    def scaled_breakage(self, params: BreakageParams, density_t_m3: float | None = None) -> BreakageParams:
        """``params`` of the calibrated mill scaled to this twin's mill
        (:func:`twin.scaleup.scale_breakage`; unchanged on the calibrated mill itself)."""
        density = self.spec.solids_density_t_m3 if density_t_m3 is None else density_t_m3
        return scale_breakage(params, self.calibrated_mill, self.mill, density)

    @property
    def nominal_blend(self) -> np.ndarray:
        return np.asarray(self.blend.fractions, float)

    def steady(self, feed_tph: float | None = None, speed_frac_critical: float | None = None,
               blend=None, hardness_scale: float = 1.0):
        """Steady state (:class:`twin.solve.steady.SteadyState`: ``p80_um``, ``outputs`` by name with units,
        ``load_status``, ``notes``) at the feed rate [t/h] and speed [fraction of critical] given (defaults: the
        mill's nominal), of ``blend`` (as :meth:`blend_fractions` takes it; default: the nominal blend, the
        twin's Blend or its ores at equal shares) at ``hardness_scale`` times its ores' hardness (divides
        every breakage rate)."""
        feed = self.mill.feed_nominal_tph if feed_tph is None else feed_tph
        return self._noted(steady_state(self.model, self._u(feed, speed_frac_critical), self._d(blend, hardness_scale)))

    def steady_at_constant_load(self, speed_frac_critical: float | None = None, blend=None,
                                load_frac: float = 1.0, hardness_scale: float = 1.0):
        """Steady state whose hold-up is ``load_frac`` of nominal: the feed rate is solved for
        (how the laboratory reports throughput 'at constant load')."""
        return self._noted(steady_state_at_load(self.model, self._u(self.mill.feed_nominal_tph, speed_frac_critical),
                                                self._d(blend, hardness_scale), load_frac))

    def _noted(self, ss):
        ss.notes.extend(n for n in self.notes if n not in ss.notes)
        return ss

    def simulate(self, duration_h: float, dt_h: float, feed_tph=None, speed_frac_critical=None,
                 blend=None, x0=None, hardness_scale=1.0, **kwargs):
        """Open-loop run with inputs given as constants or callables of time [h] (read at every
        sample and just before it, linear in between: :func:`twin.solve.simulate`); returns a
        :class:`twin.solve.simulate.Trajectory`. ``hardness_scale`` (a constant or a callable of
        time) scales the breakage rates' hardness as in :meth:`steady`. ``x0`` defaults to the mill
        filled to its nominal hold-up with unground feed (:meth:`Model.initial_state`), not a steady
        state: pass ``steady(...).x`` to start from one. Every value read is checked as :meth:`steady`
        checks its inputs; the error names the time."""
        def as_fn(v, default):
            v = default if v is None else v
            return v if callable(v) else (lambda t, v=v: v)

        feed_fn = as_fn(feed_tph, self.mill.feed_nominal_tph)
        speed_fn = as_fn(speed_frac_critical, self.mill.speed_nominal_frac_critical)
        blend_fn = as_fn(blend, self.nominal_blend)
        hardness_fn = as_fn(hardness_scale, 1.0)
        x0 = self.model.initial_state(self.nominal_blend) if x0 is None else x0
        return simulate(self.model, x0, duration_h, dt_h,
                        u_fn=_at_time(lambda t: self._u(feed_fn(t), speed_fn(t))),
                        d_fn=_at_time(lambda t: self._d(blend_fn(t), hardness_fn(t))), **kwargs)

    def _u(self, feed_tph, speed):
        speed = self.mill.speed_nominal_frac_critical if speed is None else speed
        feed_tph = _one_number("feed_tph", feed_tph, "t/h")
        speed = _one_number("speed_frac_critical", speed, "fraction of critical")
        if not 0.0 <= float(feed_tph) < FEED_TPH_MAX:
            raise bad_value("Twin", "feed_tph", feed_tph, f"a float in [0, {FEED_TPH_MAX:g})")
        if not 0.0 < float(speed) < 1.0:
            percent = " (a fraction of critical speed, not percent)" if 10.0 <= float(speed) <= 100.0 else ""
            raise bad_value("Twin", "speed_frac_critical", speed, f"a float in (0, 1){percent}")
        if float(speed) <= SPEED_FACTOR_ZERO_FRAC_CRITICAL and "speed" in self.model.effect_names:
            raise bad_value("Twin", "speed_frac_critical", speed,
                            f"a float in ({SPEED_FACTOR_ZERO_FRAC_CRITICAL:g}, 1) with the speed effect: Austin's "
                            "speed factor, and every breakage rate with it, is zero there and negative below")
        return np.array([feed_tph, speed], float)

    def _d(self, blend, hardness_scale):
        fr = self.blend_fractions(blend)
        # divides every breakage rate: 0, negative, NaN or inf made a solver error or a P80 of nothing
        hardness = _one_number("hardness_scale", hardness_scale, "multiple of the ore's hardness")
        return self.model.d_vector(fr, check_range("Twin", "hardness_scale", hardness, 0.0, math.inf))

    def blend_fractions(self, blend=None) -> np.ndarray:
        """``blend`` (a Blend, a dict {ore: fraction}, fractions in the twin's order, or None: the nominal blend)
        as fractions in the twin's component order, checked (non-negative, summing to 1, ores of this twin)."""
        if isinstance(blend, Blend):
            for ore in blend.ores:  # matched by name below: another ore of a component's name was the component
                own = dict(zip(self.blend.names, self.blend.ores)).get(ore.name)
                if own is not None and (dict(ore.wt_pct), ore.texture) != (dict(own.wt_pct), own.texture):
                    raise TwinInputError(f"Blend ore {ore.name!r} is not this twin's component {ore.name!r} (another "
                                         "mineralogy or texture of that name): build a Twin with it.")
            blend = dict(zip(blend.names, blend.fractions))
        if blend is None:
            fr = self.nominal_blend
        elif isinstance(blend, dict):  # {ore: fraction} or a Blend's, ores not named have none
            unknown = sorted(set(blend) - set(self.blend.names))
            if unknown:
                raise TwinInputError(f"Blend ores {unknown} are not components of this twin {self.blend.names}.")
            fr = np.array([_one_number(f"blend[{n!r}]", blend.get(n, 0.0), "fraction") for n in self.blend.names])
        elif isinstance(blend, (str, bytes)):
            raise bad_value("Twin", "blend", blend, f"a Blend, a dict {{ore: fraction}} or fractions in the order "
                            f"{self.blend.names} (text such as 'B=0.6,D=0.4': Blend.parse)")
        else:
            fr = np.asarray(blend, float)
        if fr.shape != (len(self.blend.names),):
            raise bad_value("Twin", "blend", blend, f"{len(self.blend.names)} fractions, of {self.blend.names}")
        if not np.all(np.isfinite(fr)) or not blend_sum_ok(fr) or np.any(fr < 0):
            raise bad_value("Twin", "blend", [float(v) for v in fr],
                            f"non-negative fractions summing to 1 within {blend_sum_tolerance(fr.size):g}")
        return np.asarray(normalised_blend(fr), float)


def _rebuilt(cls, arguments: dict):
    """A pickled twin (:meth:`Twin.__reduce__`) made again from its arguments."""
    return cls(**arguments)


def _one_number(name: str, value, unit: str) -> float:
    """``value`` as one float, or the user's error naming ``name``: a list, an array of more than one
    value or text is refused (text read as a number hid a column of strings; a one-element list
    gave a TypeError from deep inside)."""
    if isinstance(value, (str, bytes, bool)) or np.ndim(value) != 0:
        raise bad_value("Twin", name, value, f"one number [{unit}] (a callable must return one)")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise bad_value("Twin", name, value, f"one number [{unit}]") from None


def calibration_mismatch_note(problem: str) -> str:
    """The note of a twin that differs from its calibration (``problem``, one item of
    :meth:`twin.calibration.Calibration.mismatch`): what it means and what to do."""
    return (f"{problem}: the calibration's numbers were fitted with its own, so this twin runs them outside their "
            "fit; build the twin with the calibration's (grindtwin calibrate fits the twin's default effects, grid "
            "and mixers only); a scene that means it says calibration_mismatch_ok = true")


def _at_time(fn):
    """``fn(t)`` with the time [h] added to an input error's message."""
    def checked(t):
        try:
            return fn(t)
        except TwinInputError as exc:
            raise TwinInputError(f"{exc} (at t = {t:.6g} h)") from None
    return checked


#: How far mixer_volume_fracs may sum from 1 (rounded shares such as 0.7, 0.15, 0.15 or three
#: thirds written 0.33); what is within it is rescaled, what is not is a slip and refused.
MIXER_SHARES_SUM_TOL = 0.01


def mixer_shares_sum_ok(total: float) -> bool:
    """Whether mixer shares summing to ``total`` are shares of the hold-up (within the tolerance,
    its end included: three thirds written 0.33 sum to 0.99 give or take a rounding of the floats)."""
    return abs(total - 1.0) <= MIXER_SHARES_SUM_TOL * (1.0 + 1e-9)


def _mixer_fracs(n_mixers, fracs) -> tuple:
    """The mixers' shares of the hold-up: ``fracs`` normalised, or ``n_mixers`` equal shares."""
    if fracs is None:
        n_mixers = check_int("Twin", "n_mixers", n_mixers, 1, 20)  # True was 1
        return tuple([1.0 / n_mixers] * n_mixers)
    f = np.asarray(fracs, float)
    if f.ndim != 1 or not 1 <= f.size <= 20 or np.any(~np.isfinite(f)) or np.any(f <= 0):
        raise bad_value("Twin", "mixer_volume_fracs", fracs, "1 to 20 positive shares of the hold-up")
    if not mixer_shares_sum_ok(f.sum()):  # (1, 1, 1) was read as thirds without a word
        raise bad_value("Twin", "mixer_volume_fracs", fracs, f"shares of the hold-up summing to 1 within "
                        f"{MIXER_SHARES_SUM_TOL:g} (sum {f.sum():.4g})")
    return tuple(float(v) for v in f / f.sum())


def _given_breakage(given, names) -> dict:
    """Breakage parameters given per component name, checked against the components."""
    given = dict(given or {})
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise bad_value("Twin", "ore_breakage", unknown, f"names of this twin's components {list(names)}")
    bad = [k for k, v in given.items() if not isinstance(v, BreakageParams)]
    if bad:
        raise bad_value("Twin", "ore_breakage", {k: given[k] for k in bad}, "twin.BreakageParams per ore")
    return given


def _given_densities(given, blend) -> list[float]:
    """Each component's solids density [t/m3]: its minerals', or the one ``given`` by its name."""
    given = dict(given or {})
    unknown = sorted(set(given) - set(blend.names))
    if unknown:
        raise bad_value("Twin", "solids_density_t_m3", unknown, f"names of this twin's components {blend.names}")
    return [check_range("Twin", f"solids_density_t_m3[{o.name}]", given[o.name], 1.0, 25.0) if o.name in given
            else o.density_t_m3 for o in blend.ores]


#: The share of a feed distribution allowed above the size grid's top (lumped into the top
#: class): 1 %, within a sieve analysis's own error; more changes the feed the twin grinds.
FEED_ABOVE_TOP_MAX_FRAC = 0.01


def _feed_fractions(grid, feed_psd, feed_p80_um, feed_modulus) -> np.ndarray:
    """Feed mass fraction per class: a distribution object (``passing(x_um)``), an array of
    class fractions, or by default GGS with the given P80 and modulus."""
    if feed_psd is None or hasattr(feed_psd, "passing"):
        dist = GatesGaudinSchuhmann.from_p80(feed_p80_um, feed_modulus) if feed_psd is None else feed_psd
        above = 1.0 - float(dist.passing(grid.top_um))
        retained = 1.0 - dist.passing_frac[-1] if isinstance(dist, TabulatedPSD) else 0.0
        if retained > FEED_ABOVE_TOP_MAX_FRAC:  # of no known size: it was put just above the coarsest sieve
            raise TwinInputError(f"the feed_psd's coarsest sieve ({dist.sizes_um[-1]:g} um) passes "
                                 f"{dist.passing_frac[-1]:.1%}: the {retained:.1%} retained on it has no known size; "
                                 "add the sieve that all of the feed passes (100 %); allowed: at most "
                                 f"{FEED_ABOVE_TOP_MAX_FRAC:.0%} retained on the coarsest sieve.")
        if above > FEED_ABOVE_TOP_MAX_FRAC:  # discretise lumps it into the top class: another feed
            given = (f"feed_p80_um {feed_p80_um:g} with modulus {feed_modulus:g}" if feed_psd is None
                     else "the feed_psd")
            raise TwinInputError(f"{given} puts {above:.1%} of the feed above the size grid's top "
                                 f"({grid.top_um:g} um), which would be lumped into the top class (a finer feed "
                                 f"than given); allowed: at most {FEED_ABOVE_TOP_MAX_FRAC:.0%}. Raise the grid's "
                                 "top size (mill.size_classes.top_um in a scene) or give the feed's own analysis.")
        return _feed_on_grid(grid, discretise(grid, dist), feed_p80_um if feed_psd is None else None, sizes_given=True)
    frac = np.asarray(feed_psd, float)
    if frac.shape != (grid.count,) or not np.all(np.isfinite(frac)) or np.any(frac < 0) or abs(frac.sum() - 1.0) > 1e-9:
        raise bad_value("Twin", "feed_psd", feed_psd,
                        f"a size distribution or {grid.count} non-negative class fractions summing to 1")
    return _feed_on_grid(grid, frac, None)


#: A feed whose P80 is finer than this [um] is refused: the finest ball-mill feeds (regrind mills) have
#: P80s of 50-150 um, and below ~20 um a stirred mill grinds, not balls (Wills & Finch 2016, ch. 7); a
#: feed P80 in mm written for um (3.2) lands below.
FEED_P80_MIN_UM = 20.0


def _feed_on_grid(grid, frac: np.ndarray, feed_p80_um: float | None, sizes_given: bool = False) -> np.ndarray:
    """``frac`` if the feed's P80 lies on the grid and, for a feed given by sizes (a P80, a distribution;
    ``sizes_given``), is a ball mill's feed (at least :data:`FEED_P80_MIN_UM`), else the user's error: with
    80 % of the feed in the sink class (below the finest sieve) its P80, and every finer product's, is an
    extrapolation inside one class; a feed_p80_um of 3.2 (mm written for um) gave a product coarser than the
    feed, and on a finer grid a product P80 of 3.19 um. Class fractions carry no unit to slip."""
    given = f"feed_p80_um {feed_p80_um:g}" if feed_p80_um is not None else "the feed_psd"
    if frac[-1] >= 0.8:
        raise TwinInputError(f"{given} puts {frac[-1]:.1%} of the feed below the size grid's finest sieve "
                             f"({grid.upper_um[-1]:.4g} um): its P80 is not on the grid. Give the size in um, or a "
                             "grid reaching finer (more classes or a smaller top size; mill.size_classes in a scene).")
    p80 = pxx_um(grid, frac, 80.0)
    if sizes_given and p80 < FEED_P80_MIN_UM:
        raise TwinInputError(f"{given} has a P80 of {p80:.3g} um, finer than any ball mill's feed (allowed: at least "
                             f"{FEED_P80_MIN_UM:g} um): sizes in um, not mm ({p80:.3g} mm is {p80 * 1000:.4g} um)?")
    return frac


def _check_effects(effects, effect_options) -> None:
    """Effect names and options checked as the model will check them, but before the calibration
    loads: a ModelError (the class of every effect problem) that names the parameter."""
    found = effect_problems(effects, effect_options)
    if found:
        raise ModelError(f"The '{found[0].loc[0]}' parameter of Twin: {found[0].message}")


def _as_blend(ores) -> Blend:
    if isinstance(ores, Blend):
        return ores
    if isinstance(ores, dict) or not isinstance(ores, (str, Path, Mineralogy, Sequence)):
        raise bad_value("Twin", "ores", ores, "an ore (a reference type 'A'-'D', an ore TOML file, a Mineralogy), a "
                        "list of them or a Blend (a blend's fractions: Blend.parse('B=0.6,D=0.4'))")
    if isinstance(ores, (str, Path, Mineralogy)):
        return Blend.single(ores)
    items = [load_ore(o) for o in ores]
    if not items:
        raise TwinInputError("A Twin needs at least one ore.")
    names = [o.name for o in items]
    if len(set(names)) != len(names):
        raise TwinInputError(f"Ore names in a Twin must be unique. Got {names}.")
    return Blend(tuple(items), tuple([1.0 / len(items)] * len(items)))
