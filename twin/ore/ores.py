"""Reference ore types A-D (``twin/ore/data/ores.toml``), ores from TOML files, and blends."""

from __future__ import annotations

import numbers
import tomllib
from dataclasses import dataclass
from functools import cache
from importlib import resources
from pathlib import Path

from ..errors import TwinInputError, close_matches
from .mineralogy import TEXTURE_COLUMNS, Mineralogy, Texture, blend_sum_ok, blend_sum_tolerance, normalised_blend


@cache
def reference_ores() -> dict[str, Mineralogy]:
    """The four reference ore types by letter."""
    text = resources.files("twin.ore").joinpath("data", "ores.toml").read_text(encoding="utf-8")
    return {k: _from_table(v, name=k) for k, v in tomllib.loads(text).items()}


#: The keys of an ore file (and of each ore in twin/ore/data/ores.toml).
ORE_FILE_KEYS = ("description", "mineralogy", "texture")


def _from_table(table: dict, name: str, where: str = "ores.toml") -> Mineralogy:
    for key in ("mineralogy", "texture"):
        if key not in table:
            raise TwinInputError(f"{where}: ore {name!r} needs a [{key}] table.")
    unknown = sorted(set(table) - set(ORE_FILE_KEYS))
    if unknown:  # a bond_wi_kwh_t or a [breakage] here was read by nothing, silently
        raise TwinInputError(f"{where}: ore {name!r}: unknown key{'s' * (len(unknown) > 1)} {', '.join(unknown)}; "
                             f"allowed: {', '.join(ORE_FILE_KEYS)} (breakage parameters given directly go in a "
                             "scene's [ores.NAME.breakage])")
    for key in ("mineralogy", "texture"):
        _check_numbers(table[key], key, name, where)
    texture = table["texture"]
    unknown = sorted(set(texture) - set(TEXTURE_COLUMNS))
    missing = [k for k in TEXTURE_COLUMNS if k not in texture]
    if unknown or missing:  # a missing one took Texture's default silently (0.5 entropy moves the textural index)
        what = ([f"unknown key{'s' * (len(unknown) > 1)} {', '.join(unknown)}"] if unknown else []) + (
            [f"missing {', '.join(missing)}"] if missing else [])
        raise TwinInputError(f"{where}: [texture] of ore {name!r}: {'; '.join(what)}. Allowed and required: "
                             f"{', '.join(TEXTURE_COLUMNS)} (as a scene's [ores.NAME.texture]).")
    try:
        return Mineralogy(dict(table["mineralogy"]), Texture(**texture), name=name)
    except TwinInputError as exc:  # the range checks of Texture and Mineralogy, with the file named
        raise TwinInputError(f"{where}: ore {name!r}: {exc}") from None


def _check_numbers(section, key: str, name: str, where: str) -> None:
    """A table of numbers: TOML's true read as 1 wt% and "40" as 40, and a text grain size
    failed later with a traceback."""
    if not isinstance(section, dict):
        raise TwinInputError(f"{where}: ore {name!r}: {key} must be a table ([{key}]). Got {section!r}.")
    bad = {k: v for k, v in section.items() if isinstance(v, bool) or not isinstance(v, (int, float))}
    if bad:
        k, v = next(iter(bad.items()))
        raise TwinInputError(f"{where}: [{key}] of ore {name!r}: {k} = {v!r} must be a number "
                             f"(a TOML integer or float, not {type(v).__name__}).")


def load_ore(spec: str | Path | Mineralogy) -> Mineralogy:
    """A reference type letter ('A'..'D'), a TOML file with [mineralogy] and [texture], or a Mineralogy."""
    if isinstance(spec, Mineralogy):
        return spec
    refs = reference_ores()
    if isinstance(spec, str) and spec in refs:
        return refs[spec]
    path = Path(spec)
    if path.suffix == ".toml" and path.is_file():
        try:
            with path.open("rb") as fh:
                table = tomllib.load(fh)
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise TwinInputError(f"The ore file {path} is not valid TOML: {exc}.") from None
        return _from_table(table, name=path.stem, where=str(path))
    if path.suffix == ".toml":
        raise TwinInputError(f"The ore file {path} was not found (an ore is a reference type "
                             f"{', '.join(refs)} or a TOML file with [mineralogy] and [texture] tables).")
    raise TwinInputError(
        f"The 'ore' must be a reference type ({', '.join(refs)}) or a TOML file with "
        f"[mineralogy] and [texture] tables. Got {str(spec)!r}.{close_matches(str(spec), refs)}")


@dataclass(frozen=True)
class Blend:
    """Feed blend: ore components and their mass fractions (sum 1)."""

    ores: tuple  # tuple[Mineralogy, ...]
    fractions: tuple  # tuple[float, ...]

    def __post_init__(self):
        if len(self.ores) != len(self.fractions) or not self.ores:
            raise TwinInputError("A Blend needs one fraction per ore and at least one ore.")
        # ores named as Twin takes them ('B', a TOML path) failed on .name; a text fraction on '<='
        object.__setattr__(self, "ores", tuple(load_ore(o) if isinstance(o, (str, Path)) else o for o in self.ores))
        for o in self.ores:  # (1, 2) failed on .name with a bare AttributeError
            if not isinstance(o, Mineralogy):
                raise TwinInputError(f"The 'ores' of Blend must be ore names, ore files or Mineralogy objects. "
                                     f"Got {o!r}.")
        fractions = []
        for ore, f in zip(self.ores, self.fractions):
            if isinstance(f, bool) or not isinstance(f, numbers.Real):
                raise TwinInputError(f"The fraction of ore {ore.name!r} in Blend must be a float in [0, 1]. "
                                     f"Got {f!r}.")
            fractions.append(float(f))
        object.__setattr__(self, "fractions", tuple(fractions))
        names = [ore.name for ore in self.ores]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:  # components are keyed by name (results, JSON): a second one would overwrite the first
            raise TwinInputError(f"A Blend names each ore once; {', '.join(map(repr, twice))} appears more than once "
                                 f"in {names} (two files with one stem are two ores of one name: rename one).")
        for ore, f in zip(self.ores, self.fractions):
            if not 0.0 <= f <= 1.0:
                raise TwinInputError(
                    f"The fraction of ore {ore.name!r} in Blend must be a float in [0, 1]. Got {f}.")
        total = sum(self.fractions)
        if not blend_sum_ok(self.fractions):
            raise TwinInputError(f"Blend fractions must sum to 1 within {blend_sum_tolerance(len(self.fractions)):g}"
                                 f". Got {total}.")
        object.__setattr__(self, "fractions", tuple(normalised_blend(self.fractions)))

    @classmethod
    def parse(cls, text: str) -> "Blend":
        """'B=0.6,D=0.4' -> Blend of reference ores (or ore TOML paths)."""
        ores, fracs = [], []
        for item in filter(None, (s.strip() for s in text.split(","))):
            if "=" not in item:
                raise TwinInputError(f"The 'blend' must look like 'B=0.6,D=0.4'. Got {text!r}.")
            key, value = item.split("=", 1)
            ores.append(load_ore(key.strip()))
            try:
                fracs.append(float(value))
            except ValueError:
                raise TwinInputError(f"The fraction of {key!r} in 'blend' must be a number. Got {value!r}.") from None
        return cls(tuple(ores), tuple(fracs))

    @classmethod
    def single(cls, ore) -> "Blend":
        return cls((load_ore(ore),), (1.0,))

    @property
    def names(self) -> list[str]:
        return [o.name for o in self.ores]

    @property
    def density_t_m3(self) -> float:
        """The blend's solids density [t/m3]: mass fractions over the components' densities, summed
        volumes (the harmonic mean)."""
        return 1.0 / sum(f / o.density_t_m3 for o, f in zip(self.ores, self.fractions))
