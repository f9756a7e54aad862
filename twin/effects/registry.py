"""Registry of effects: names, validation of a list of effect names and options, and the build
order that follows from what each effect provides and needs."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import ModelError, close_matches
from .base import CORE_VARIABLES, Effect
from .breakage import Breakage
from .charge_lag import ChargeLag
from .classification import Classification
from .cushioning import Cushioning
from .feed_inventory import FeedInventory
from .holdup import Holdup
from .power import Power
from .rheology import Rheology
from .sensor_delay import SensorDelay
from .slowing_down import SlowingDown
from .speed import Speed
from .transport import Transport

#: Every effect by name (alphabetical: the order carries no meaning; the build order comes from
#: the declarations, ties broken by name).
EFFECTS: dict[str, type[Effect]] = {cls.name: cls for cls in sorted(
    (Breakage, ChargeLag, Classification, Cushioning, FeedInventory, Holdup, Power, Rheology, SensorDelay, SlowingDown, Speed, Transport),
    key=lambda c: c.name)}


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a list of effects: where (``("effects", i)`` or
    ``("effect_options", effect, option)``) and what."""

    loc: tuple
    message: str


def known_effects() -> list[str]:
    return list(EFFECTS)


def _writes(cls) -> tuple:
    return tuple(cls.provides) + tuple(cls.outputs)


def problems(names, options: dict | None = None, registry: dict | None = None) -> list[Problem]:
    """Everything wrong with effect ``names`` and their ``options``, in one pass (empty: fine).
    Unknown or repeated names, missing requirements, exclusions, variables needed that no listed
    effect provides, variables provided twice, and options of unlisted effects, unknown options
    and option values outside their declared types and ranges."""
    registry = EFFECTS if registry is None else registry
    if isinstance(names, str):  # list("breakage") was read as the effects 'b', 'r', ...
        return [Problem(("effects",), f"The effects must be a list of effect names, not one string. Got {names!r}; "
                                      f"write [{names!r}].")]
    names, options = list(names), dict(options or {})
    out, seen = [], []
    for i, name in enumerate(names):
        if not isinstance(name, str) or name not in registry:
            out.append(Problem(("effects", i), f"Unknown effect {name!r}.{close_matches(str(name), registry)} "
                                               f"Known effects: {', '.join(registry)}."))
        elif name in seen:
            out.append(Problem(("effects", i), f"Effect {name!r} is listed twice."))
        else:
            seen.append(name)
    for name in seen:
        i, cls = names.index(name), registry[name]
        out += [Problem(("effects", i), f"Effect {name!r} requires effect {req!r}; add it to the list.")
                for req in cls.requires if req not in seen]
        out += [Problem(("effects", i), f"Effect {name!r} cannot be combined with {exc!r}.")
                for exc in cls.excludes if exc in seen]
    out += _variable_problems(names, seen, registry)
    for name, table in options.items():
        if name not in seen:
            out.append(Problem(("effect_options", name), f"Options given for effect {name!r}, which is not in "
                                                         f"the list {seen}.{close_matches(str(name), seen)} Add it to the "
                                                         "effects or remove these options."))
            continue
        declared = registry[name].options
        if table is not None and not isinstance(table, dict):  # was an AttributeError on .items()
            out.append(Problem(("effect_options", name), f"The options of effect {name!r} must be a table of option "
                                                         f"names and values (a dict). Got {table!r}; allowed options: "
                                                         f"{', '.join(declared) or 'none'}."))
            continue
        for key, value in (table or {}).items():
            if key not in declared:
                out.append(Problem(("effect_options", name, key),
                                   f"Unknown option {key!r} of effect {name!r}.{close_matches(key, declared)} "
                                   f"Allowed: {', '.join(declared) or 'none'}."))
                continue
            try:
                declared[key].check(name, key, value)
            except ModelError as exc:
                out.append(Problem(("effect_options", name, key), str(exc)))
    return out


def _variable_problems(names, listed, registry) -> list[Problem]:
    """Variables provided twice, or needed and provided by no listed effect."""
    out, writer = [], {}
    for name in listed:
        for var in _writes(registry[name]):
            if var in writer or var in CORE_VARIABLES:
                first = writer.get(var, "the model itself")
                out.append(Problem(("effects", names.index(name)),
                                   f"Variable {var!r} is provided by both {first!r} and effect {name!r}."))
            writer.setdefault(var, name)
    for name in listed:
        for var in registry[name].needs:
            if var in writer or var in CORE_VARIABLES or any(var in registry[o].contributes for o in listed):
                continue
            could = [n for n, c in registry.items() if var in _writes(c) or var in c.contributes]
            hint = f" It is provided by {', '.join(repr(c) for c in could)}: add one." if could else ""
            out.append(Problem(("effects", names.index(name)),
                               f"Effect {name!r} needs variable {var!r}, which no listed effect provides.{hint}"))
    return out


def build_order(listed, registry: dict | None = None) -> list[str]:
    """The listed effects in an order where every effect comes after all that provide or
    contribute what it needs or uses (a stable topological sort, ties broken by name). A cycle
    is a ModelError naming its effects."""
    registry = EFFECTS if registry is None else registry
    listed = sorted(listed)
    sources = {name: {o for o in listed if o != name and any(
        v in _writes(registry[o]) or v in registry[o].contributes
        for v in tuple(registry[name].needs) + tuple(registry[name].uses))} for name in listed}
    order: list[str] = []
    while len(order) < len(listed):
        ready = [n for n in listed if n not in order and sources[n] <= set(order)]
        if not ready:
            stuck = [n for n in listed if n not in order]
            raise ModelError(f"Effects {stuck} need each other's variables in a cycle; no build order exists.")
        order.append(ready[0])
    return order


def resolve(names, options: dict | None = None) -> list[Effect]:
    """Validate effect names and options, return effect instances in build order. Every problem
    is a ModelError (the first; :func:`problems` lists them all). Nothing is added or rewritten
    behind the caller's back."""
    found = problems(names, options)
    if found:
        raise ModelError(found[0].message)
    options = dict(options or {})
    return [EFFECTS[n](**options.get(n, {})) for n in build_order(names)]
