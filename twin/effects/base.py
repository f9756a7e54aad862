"""The one interface every effect implements, and the context a model is built in.

An effect is one physical mechanism (after PyBaMM's submodels). It declares
- ``provides``: coupling variables it defines (each provided by exactly one listed effect);
- ``contributes``: factor variables it multiplies into (any number of contributors; the
  product, 1 when none contributes, is what a reader gets);
- ``outputs``: named results it adds to the model (units in the name);
- ``needs``: variables or outputs it reads, which a listed effect must provide;
- ``uses``: variables it reads when a listed effect provides them (else a stated default);
- ``requires`` / ``excludes``: other effects it cannot do without / cannot be combined with;
- ``options``: the options it accepts, each an :class:`Option` with a type and range.

The build order follows from the declarations (:func:`twin.effects.registry.build_order`), and
an effect can read and write only what it declared (:class:`EffectContext` refuses anything
else), so reordering the registry cannot build another model. An effect that is not listed
contributes nothing: its states, algebraic variables, terms and outputs are absent.
Inside the model: mass t, time h, size um, power kW (module docstring of twin.model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from ..errors import ModelError, close_matches

#: The variables the model itself provides to every effect (no effect declares them).
CORE_VARIABLES = ("mass_t", "feed_tph", "speed_frac_critical", "blend_frac", "hardness_scale")


@dataclass(frozen=True)
class Term:
    """A record of one contribution, for ``Model.describe()``."""

    effect: str
    what: str


@dataclass(frozen=True)
class Option:
    """One option of an effect: its default, what it means, and what values are allowed
    (``kind`` a type or tuple of types; ``choices`` a closed set; ``lo``/``hi`` a range, open
    unless ``lo_closed``/``hi_closed``)."""

    default: Any
    description: str
    kind: type | tuple = object
    choices: tuple | None = None
    lo: float | None = None
    hi: float | None = None
    lo_closed: bool = False
    hi_closed: bool = False

    def allowed(self) -> str:
        """What is allowed, in words, for error messages."""
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        kinds = self.kind if isinstance(self.kind, tuple) else (self.kind,)
        what = " or ".join("an integer" if k is int else "a number" if k is float else f"a {k.__name__}"
                           for k in kinds)
        if self.lo is not None or self.hi is not None:
            lo = "-inf" if self.lo is None else f"{self.lo:g}"
            hi = "inf" if self.hi is None else f"{self.hi:g}"
            what += f" in {'[' if self.lo_closed else '('}{lo}, {hi}{']' if self.hi_closed else ')'}"
        return what

    def check(self, effect: str, name: str, value):
        """``value`` if allowed, else ModelError naming the effect, option, value and what is allowed."""
        def bad():
            return ModelError(f"The {name!r} option of effect {effect!r} must be {self.allowed()}. Got {value!r}.")
        if self.choices is not None:
            if value not in self.choices:
                raise ModelError(f"The {name!r} option of effect {effect!r} must be {self.allowed()}. "
                                 f"Got {value!r}.{close_matches(str(value), [str(c) for c in self.choices])}")
            return value
        kinds = self.kind if isinstance(self.kind, tuple) else (self.kind,)
        numeric = any(k in (int, float) for k in kinds)
        if isinstance(value, bool) and bool not in kinds:
            raise bad()
        if float in kinds and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kinds):
            raise bad()
        if numeric:
            v = float(value)
            if not math.isfinite(v):
                raise bad()
            if self.lo is not None and (v < self.lo or (v == self.lo and not self.lo_closed)):
                raise bad()
            if self.hi is not None and (v > self.hi or (v == self.hi and not self.hi_closed)):
                raise bad()
        return value


class Effect:
    """Base class: subclasses set the class attributes and implement :meth:`apply`."""

    name: str = ""
    requires: tuple = ()
    excludes: tuple = ()
    provides: tuple = ()
    contributes: tuple = ()
    outputs: tuple = ()
    needs: tuple = ()
    uses: tuple = ()
    source: str = ""
    summary: str = ""
    #: options this effect accepts, name -> Option
    options: dict = {}

    def __init__(self, **options):
        unknown = set(options) - set(self.options)
        if unknown:
            name = sorted(unknown)[0]
            allowed = ", ".join(self.options) or "none"
            raise ModelError(f"Unknown option {name!r} of effect {self.name!r}."
                             f"{close_matches(name, self.options)} Allowed: {allowed}.")
        self.settings = {k: opt.default for k, opt in self.options.items()}
        self.settings |= {k: self.options[k].check(self.name, k, v) for k, v in options.items()}

    def apply(self, ctx: "EffectContext") -> None:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass
class Build:
    """Everything a model is assembled into: symbols, state derivatives, variables and their
    providers, aggregates (with the effects that use them), parameters and notes."""

    spec: object  # twin.model.ModelSpec
    u: ca.SX
    d: ca.SX
    mass: list  # mass[c][k] -> SX column (n,) of component c in mixer k [t]
    extra_states: dict = field(default_factory=dict)  # name -> (SX symbol, initial value array, effect)
    rhs: dict = field(default_factory=dict)  # id(symbol) -> list of (effect, SX term)
    variables: dict = field(default_factory=dict)  # name -> value
    provider: dict = field(default_factory=dict)  # name -> effect name
    factors: dict = field(default_factory=dict)  # name -> list of (effect, SX factor)
    outputs: dict = field(default_factory=dict)  # name -> SX
    aggregates: dict = field(default_factory=dict)  # name -> (SX symbol z, SX expression of x)
    aggregate_users: dict = field(default_factory=dict)  # name -> set of effect names
    terms: list = field(default_factory=list)
    parameters: dict = field(default_factory=dict)  # name -> (value, unit, source)

    def rhs_of(self, sym) -> ca.SX:
        """The derivative of a state block: its terms summed in build order."""
        terms = [term for _, term in self.rhs.get(id(sym), [])]
        if not terms:
            return ca.SX.zeros(sym.numel())
        out = terms[0]
        for term in terms[1:]:
            out = out + term
        return out


class EffectContext:
    """One effect's view of the build: it may read only what it declared it needs or uses, and
    write only what it declared it provides, contributes or outputs. Helpers build the sums
    over states that several effects need (hold-ups, mineral-group fractions)."""

    def __init__(self, build: Build, effect: Effect):
        self._b, self._e = build, effect
        self.spec = build.spec
        self.mass = build.mass

    # ------------------------------------------------------------------ variables
    def get(self, name: str, default=None):
        """The value of variable or output ``name``: declared in ``needs`` (always present) or
        ``uses`` (``default`` when no listed effect provides it)."""
        e, b = self._e, self._b
        if name not in e.needs and name not in e.uses:
            raise ModelError(f"Effect {e.name!r} reads variable {name!r} without declaring it in "
                             "'needs' or 'uses'.")
        if name in b.factors:
            return self.factor(name)
        if name in b.variables:
            return b.variables[name]
        if name in b.outputs:
            return b.outputs[name]
        if name in e.needs:  # the build order makes this unreachable; guard against a broken order
            raise ModelError(f"Effect {e.name!r} needs variable {name!r}, which is not built yet.")
        return default

    def factor(self, name: str):
        """Product of the contributions to factor variable ``name`` (1 if none)."""
        if name not in self._e.needs and name not in self._e.uses:
            raise ModelError(f"Effect {self._e.name!r} reads factor {name!r} without declaring it.")
        out = 1
        for _, f in self._b.factors.get(name, []):
            out = out * f
        return out

    def provide(self, name: str, value) -> None:
        if name not in self._e.provides:
            raise ModelError(f"Effect {self._e.name!r} provides variable {name!r} without declaring it "
                             "in 'provides'.")
        self._b.variables[name] = value
        self._b.provider[name] = self._e.name

    def contribute(self, name: str, factor) -> None:
        if name not in self._e.contributes:
            raise ModelError(f"Effect {self._e.name!r} contributes to {name!r} without declaring it in "
                             "'contributes'.")
        self._b.factors.setdefault(name, []).append((self._e.name, factor))

    def output(self, name: str, expr) -> None:
        if name not in self._e.outputs:
            raise ModelError(f"Effect {self._e.name!r} adds output {name!r} without declaring it in "
                             "'outputs'.")
        self._b.outputs[name] = expr
        self._b.provider[name] = self._e.name

    # ------------------------------------------------------------------ core symbols
    @property
    def feed_tph(self):
        return self._b.u[0]

    @property
    def speed(self):
        return self._b.u[1]

    @property
    def n_components(self) -> int:
        return len(self.mass)

    @property
    def n_mixers(self) -> int:
        return len(self.mass[0])

    def blend(self, c: int):
        return self._b.d[c]

    @property
    def hardness_scale(self):
        return self._b.d[self.n_components]

    # ------------------------------------------------------------------ sums over states
    def aggregate(self, name: str, expr):
        """A scalar sum over many states (a hold-up, a soft mass) as an algebraic variable
        z = expr. Terms that use z keep the Jacobian sparse (the integrator solves the DAE);
        ``Model.f`` substitutes z back for a plain ODE."""
        b = self._b
        if name not in b.aggregates:
            b.aggregates[name] = (ca.SX.sym(name), expr)
        b.aggregate_users.setdefault(name, set()).add(self._e.name)
        return b.aggregates[name][0]

    def holdup(self, k: int | None = None):
        """Total hold-up [t], of one mixer or of the mill (algebraic aggregates)."""
        ks = range(self.n_mixers) if k is None else [k]
        return sum(self.aggregate(f"holdup_{kk}_t", sum(ca.sum1(self.mass[c][kk]) for c in range(self.n_components)))
                   for kk in ks)

    def packed_holdup(self, k: int | None = None):
        """The hold-up's volume as tonnes at the nominal density [t] (Σ m_c ρ_nom / ρ_c, of one mixer or the
        mill): what fills the mill, whose nominal hold-up is a volume at the nominal blend's density. The hold-up
        itself when the components share that density."""
        weights = self.spec.volume_weights()
        if weights is None:
            return self.holdup(k)
        ks = range(self.n_mixers) if k is None else [k]
        return sum(self.aggregate(f"packed_holdup_{kk}_t", sum(weights[c] * ca.sum1(self.mass[c][kk])
                                                                for c in range(self.n_components)))
                   for kk in ks)

    def content_density_ratio(self, k: int | None = None):
        """The content's solids density over the nominal one (of one mixer or the mill; 1.0, a float, when the
        components share it): H / packed H, in an empty mill that of the feed blend."""
        if self.spec.volume_weights() is None:
            return 1.0
        return self.density_ratio(self.holdup(k), self.packed_holdup(k), 1e-6 * self.spec.holdup_nominal_t)

    def density_ratio(self, mass, packed, floor: float):
        """Solids density over the nominal one of ``mass`` [t or t/h] whose volume is ``packed`` (as tonnes at the
        nominal density, :meth:`packed_holdup`); near nothing (``floor``, same units) that of the feed blend."""
        feed = 1.0 / self.spec.blend_volume_ratio([self.blend(c) for c in range(self.n_components)])
        return (mass + floor * feed) / (packed + floor)

    def holdup_fraction(self, name: str, frac_per_component):
        """Mass fraction of a mineral group in the whole hold-up (``frac_per_component`` its
        fraction in each ore), from the states; in an empty mill, that of the feed blend."""
        group = self.aggregate(name, sum(frac_per_component[c] * ca.sum1(self.mass[c][k])
                                         for c in range(self.n_components) for k in range(self.n_mixers)))
        feed = sum(frac_per_component[c] * self.blend(c) for c in range(self.n_components))
        eps = 1e-6 * self.spec.holdup_nominal_t
        return (group + eps * feed) / (self.holdup() + eps)

    def class_mass(self, k: int | None = None):
        """Mass per size class summed over components [t] (of one mixer, or of the mill)."""
        ks = range(self.n_mixers) if k is None else [k]
        return sum(self.mass[c][kk] for c in range(self.n_components) for kk in ks)

    # ------------------------------------------------------------------ states, terms, records
    def add_rhs(self, sym: ca.SX, term: ca.SX) -> None:
        self._b.rhs.setdefault(id(sym), []).append((self._e.name, term))

    def add_state(self, name: str, size: int, initial) -> ca.SX:
        sym = ca.SX.sym(name, size)
        self._b.extra_states[name] = (sym, np.broadcast_to(np.asarray(initial, float), (size,)).copy(), self._e.name)
        return sym

    def param(self, name: str, value: float, unit: str, source: str) -> float:
        self._b.parameters[name] = (value, unit, source)
        return value

    def note(self, what: str) -> None:
        self._b.terms.append(Term(self._e.name, what))


def smooth_max(a, b, width):
    """max(a, b) smoothed over ``width`` (same units): 0.5 (a + b + sqrt((a-b)^2 + width^2))."""
    return 0.5 * (a + b + ca.sqrt((a - b) ** 2 + width ** 2))
