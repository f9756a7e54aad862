"""Registry of effects: names, stage order, validation of a list of effect names."""

from __future__ import annotations

from ..errors import ModelError, close_matches
from .breakage import Breakage
from .classification import Classification
from .cushioning import Cushioning
from .holdup import Holdup
from .power import Power
from .rheology import Rheology
from .sensor_delay import SensorDelay
from .slowing_down import SlowingDown
from .speed import Speed
from .transport import Transport

#: Stage order: factors and hooks first, then the terms that use them, then outputs' effects.
EFFECTS = {cls.name: cls for cls in (
    Rheology, Classification, Holdup, Speed, Cushioning, SlowingDown, Breakage, Transport, Power, SensorDelay)}


def known_effects() -> list[str]:
    return list(EFFECTS)


def resolve(names, options: dict | None = None) -> list:
    """Validate effect names and options, return effect instances in stage order.
    Unknown name -> error with close matches; missing requirement or exclusion -> error naming it.
    Nothing is added or rewritten behind the caller's back."""
    options = dict(options or {})
    names = list(names)
    seen = set()
    for name in names:
        if name not in EFFECTS:
            raise ModelError(f"Unknown effect {name!r}.{close_matches(name, EFFECTS)} "
                             f"Known effects: {', '.join(EFFECTS)}.")
        if name in seen:
            raise ModelError(f"Effect {name!r} is listed twice.")
        seen.add(name)
    for name in names:
        cls = EFFECTS[name]
        for req in cls.requires:
            if req not in seen:
                raise ModelError(f"Effect {name!r} requires effect {req!r}; add it to the list.")
        for exc in cls.excludes:
            if exc in seen:
                raise ModelError(f"Effect {name!r} cannot be combined with {exc!r}.")
    for name in options:
        if name not in seen:
            raise ModelError(f"Options given for effect {name!r}, which is not in the list "
                             f"{names}.{close_matches(name, names)}")
    return [EFFECTS[n](**options.get(n, {})) for n in EFFECTS if n in seen]
