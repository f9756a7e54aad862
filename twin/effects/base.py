"""The one interface every effect implements, and the assembly it contributes to.

An effect is one physical mechanism. It declares what it requires and excludes, may add
states, and contributes to named slots of the :class:`Assembly`:

- ``rate_factors``: multipliers of every selection rate (scalar CasADi expressions);
- ``power_factors``: multipliers of the mill's net power;
- ``rhs``: terms added to state derivatives;
- hooks that later stages call (discharge law, class factor at the discharge, product split);
- ``outputs``: named expressions (units in the name).

The model is assembled by applying the listed effects in the registry's stage order; an effect
that is not listed contributes nothing, so its states, terms and outputs are absent.
Inside the model: mass t, time h, size um, power kW (module docstring of twin.model).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np


@dataclass
class Term:
    """A record of one contribution, for ``Model.describe()``."""

    effect: str
    what: str


@dataclass
class Assembly:
    """Symbols and slots shared by the effects while a model is built."""

    spec: object  # twin.model.ModelSpec
    u: ca.SX
    d: ca.SX
    mass: list  # mass[c][k] -> SX column (n,) of component c in mixer k [t]
    extra_states: dict = field(default_factory=dict)  # name -> (SX symbol, initial value array)
    rhs: dict = field(default_factory=dict)  # id -> SX added to the derivative of a symbol
    rate_factors: list = field(default_factory=list)
    power_factors: list = field(default_factory=list)
    outputs: dict = field(default_factory=dict)
    terms: list = field(default_factory=list)
    parameters: dict = field(default_factory=dict)  # name -> (value, unit, source)
    # hooks with defaults (no effect listed -> nothing happens)
    discharge_rate: object = None  # callable(k, H_k) -> SX [1/h], set by transport/holdup
    class_factor: np.ndarray | ca.SX | None = None  # discharge factor per class at the last mixer
    product_split: object = None  # callable(list of discharge vectors) -> (product, recycle)
    flow_multiplier: float = 1.0  # mill through-flow / fresh feed at nominal (recycle)
    cut_size_factor: object = 1.0  # multiplies the classification cut size (set by rheology)
    aggregates: dict = field(default_factory=dict)  # name -> (SX symbol z, SX expression of x)

    # ------------------------------------------------------------------ helpers
    @property
    def feed_tph(self):
        return self.u[0]

    @property
    def speed(self):
        return self.u[1]

    @property
    def n_components(self) -> int:
        return len(self.mass)

    @property
    def n_mixers(self) -> int:
        return len(self.mass[0])

    def blend(self, c: int):
        return self.d[c]

    @property
    def hardness_scale(self):
        return self.d[self.n_components]

    def aggregate(self, name: str, expr):
        """A scalar sum over many states (a hold-up, a soft mass) as an algebraic variable
        z = expr. Terms that use z keep the Jacobian sparse (the integrator solves the DAE);
        ``Model.f`` substitutes z back for a plain ODE."""
        if name not in self.aggregates:
            self.aggregates[name] = (ca.SX.sym(name), expr)
        return self.aggregates[name][0]

    def holdup(self, k: int | None = None):
        """Total hold-up [t], of one mixer or of the mill (algebraic aggregates)."""
        ks = range(self.n_mixers) if k is None else [k]
        return sum(self.aggregate(f"holdup_{kk}_t", sum(ca.sum1(self.mass[c][kk]) for c in range(self.n_components)))
                   for kk in ks)

    def holdup_fraction(self, name: str, frac_per_component):
        """Mass fraction of a mineral group in the whole hold-up (``frac_per_component`` its
        fraction in each ore), from the states; in an empty mill, that of the feed blend."""
        spec = self.spec
        group = self.aggregate(name, sum(frac_per_component[c] * ca.sum1(self.mass[c][k])
                                         for c in range(self.n_components) for k in range(self.n_mixers)))
        feed = sum(frac_per_component[c] * self.blend(c) for c in range(self.n_components))
        eps = 1e-6 * spec.holdup_nominal_t
        return (group + eps * feed) / (self.holdup() + eps)

    def class_mass(self, k: int | None = None):
        """Mass per size class summed over components [t] (of one mixer, or of the mill)."""
        ks = range(self.n_mixers) if k is None else [k]
        return sum(self.mass[c][kk] for c in range(self.n_components) for kk in ks)

    def add_rhs(self, sym: ca.SX, term: ca.SX) -> None:
        key = id(sym)
        self.rhs[key] = self.rhs[key] + term if key in self.rhs else term

    def add_state(self, name: str, size: int, initial) -> ca.SX:
        sym = ca.SX.sym(name, size)
        self.extra_states[name] = (sym, np.broadcast_to(np.asarray(initial, float), (size,)).copy())
        return sym

    def param(self, name: str, value: float, unit: str, source: str) -> float:
        self.parameters[name] = (value, unit, source)
        return value

    def note(self, effect: str, what: str) -> None:
        self.terms.append(Term(effect, what))

    def rate_factor(self):
        out = 1
        for f in self.rate_factors:
            out = out * f
        return out

    def power_factor(self):
        out = 1
        for f in self.power_factors:
            out = out * f
        return out


class Effect:
    """Base class: subclasses set the class attributes and implement :meth:`apply`."""

    name: str = ""
    requires: tuple = ()
    excludes: tuple = ()
    source: str = ""
    summary: str = ""
    #: options this effect accepts, name -> (default, description)
    options: dict = {}

    def __init__(self, **options):
        unknown = set(options) - set(self.options)
        if unknown:
            from ..errors import ModelError, close_matches
            name = sorted(unknown)[0]
            allowed = ", ".join(self.options) or "none"
            raise ModelError(f"Unknown option {name!r} of effect {self.name!r}."
                             f"{close_matches(name, self.options)} Allowed: {allowed}.")
        self.settings = {k: v[0] for k, v in self.options.items()} | options

    def apply(self, asm: Assembly) -> None:  # pragma: no cover - interface
        raise NotImplementedError


def smooth_max(a, b, width):
    """max(a, b) smoothed over ``width`` (same units): 0.5 (a + b + sqrt((a-b)^2 + width^2))."""
    return 0.5 * (a + b + ca.sqrt((a - b) ** 2 + width ** 2))
