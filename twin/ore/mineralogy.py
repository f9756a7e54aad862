"""Modal mineralogy and texture of an ore, and the indices derived from them.

- Mineralogical hardness index ``H_min = sum_i w_i H_i`` (MISSION.md eq. 1), w_i weight
  fraction, H_i Vickers micro-hardness [GPa] from ``minerals.csv``.
- Textural index: grain-size strengthening after Brace (1961, J. Geophys. Res. 66, 3477,
  strength of rocks ~ d^-1/2) scaled by the mineral-association entropy (intergrown textures
  resist breakage and liberation; Lund et al. 2015, Minerals Engineering 82, 61-77).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..errors import TwinInputError, bad_value, check_range, close_matches
from .minerals import CLAY_MINERALS, MICA_MINERALS, SULFIDE_MINERALS, mineral_table

#: A modal analysis must sum to 100 wt% within this tolerance (QEMSCAN/XRD reconciliations
#: are reported to 0.1 wt% per phase; 0.5 wt% allows rounding over ~10 phases).
SUM_TOLERANCE_WT_PCT = 0.5

#: Column names of sample tables (and the surrogate's inputs): ``<mineral>_wt_pct`` and the texture.
WT_SUFFIX = "_wt_pct"
TEXTURE_COLUMNS = ("mean_grain_um", "uniformity", "association_entropy")

#: Reference grain size of the textural index [um]: the coarse, equigranular Type A texture.
TEXTURE_REFERENCE_GRAIN_UM = 200.0
#: Mean grain sizes an ore's texture may have [um]: from 1 um, the finest mean grain size automated
#: mineralogy (QEMSCAN, MLA: pixels of 1 um and more) measures, to the coarsest igneous textures
#: (pegmatites, ~1 cm); beyond, the value is a unit slip, and the textural index ~ d^-1/2 it enters would be
#: off by a factor of ~30: a grain given in mm (Table 1's 30-250 um are 0.03-0.25 mm) lies below 1.
MEAN_GRAIN_RANGE_UM = (1.0, 1e4)
#: How far a blend's mass fractions may sum from 1, per ore of the blend: the one tolerance of every blend (Blend,
#: Mineralogy.blend, Twin, scenes, the CLI's --blend, mpc; blend_sum_tolerance). A fraction typed to three decimals
#: is off by up to 5e-4, so n ores' sum by up to n x 5e-4 (thirds typed 0.333 sum to 0.999, within 1.5e-3); a slip
#: (0.6 + 0.3, or 0.6 + 0.397 of two ores) is further off and refused. Fractions within it are rescaled to sum to 1
#: (normalised_blend) before use: the components carry the whole feed (mass conserved), one answer wherever typed.
BLEND_SUM_TOLERANCE_PER_ORE = 5e-4


def blend_sum_tolerance(n_ores: int) -> float:
    """How far the fractions of a blend of ``n_ores`` ores may sum from 1 (:data:`BLEND_SUM_TOLERANCE_PER_ORE`)."""
    return BLEND_SUM_TOLERANCE_PER_ORE * max(int(n_ores), 1)


def blend_sum_ok(fractions) -> bool:
    """Whether ``fractions`` sum to 1 within :func:`blend_sum_tolerance` (its end included: a 0.5e-3 rounding
    of each of n ores sums to n x 5e-4 give or take the floats' rounding)."""
    values = [float(f) for f in fractions]
    return abs(math.fsum(values) - 1.0) <= blend_sum_tolerance(len(values)) * (1.0 + 1e-9)


def normalised_blend(fractions) -> list[float]:
    """``fractions`` (checked by the caller: >= 0, :func:`blend_sum_ok`) rescaled to sum to 1."""
    values = [float(f) for f in fractions]
    total = math.fsum(values)
    return [f / total for f in values]


def fractions_hint(total: float) -> str:
    """A hint for a modal analysis given as mass fractions (summing to 1) where wt% (summing to 100) is meant."""
    if abs(total - 1.0) <= SUM_TOLERANCE_WT_PCT / 100.0:
        return " (mass fractions summing to 1? give wt%: x 100)"
    return ""


@dataclass(frozen=True)
class Texture:
    """Texture of an ore: mean grain size [um], grain-size uniformity in (0, 1]
    (1 = equigranular), mineral-association entropy normalised to [0, 1]
    (0 = each mineral touches only itself, 1 = fully intergrown). The twin's breakage maps read the
    grain size and the entropy (:attr:`textural_index`); the uniformity is recorded and read only by
    the surrogate's regression (twin.surrogate), so it moves no twin number."""

    mean_grain_um: float
    uniformity: float = 0.6
    association_entropy: float = 0.5

    def __post_init__(self):
        # the checked floats are kept (text is refused by check_range; numpy scalars become floats)
        checked = {
            "mean_grain_um": check_range("Texture", "mean_grain_um", self.mean_grain_um, *MEAN_GRAIN_RANGE_UM,
                                         lo_open=False, hi_open=False),
            "uniformity": check_range("Texture", "uniformity", self.uniformity, 0.0, 1.0, hi_open=False),
            "association_entropy": check_range("Texture", "association_entropy", self.association_entropy, 0.0, 1.0,
                                               lo_open=False, hi_open=False)}
        for name, value in checked.items():
            object.__setattr__(self, name, value)

    @property
    def textural_index(self) -> float:
        """Dimensionless; 1 for the reference texture, > 1 for finer, more intergrown ones."""
        grain = (TEXTURE_REFERENCE_GRAIN_UM / self.mean_grain_um) ** 0.5
        return grain * (0.5 + 0.5 * self.association_entropy) / 0.75


class ReadOnlyWtPct(dict):
    """A Mineralogy's wt% by mineral: a dict (JSON, pickle, ``dict(...)`` copies) that refuses to be
    changed in place. An edit of a reference ore's dict changed that ore for the whole process (the
    cached reference types, and the DEM law's reference ore), past the sum-to-100 check."""

    def _refuse(self, *args, **kwargs):
        raise TwinInputError("A Mineralogy's wt_pct is read-only: make a new Mineralogy from an edited copy "
                             "(dict(ore.wt_pct)).")

    __setitem__ = __delitem__ = clear = pop = popitem = setdefault = update = __ior__ = _refuse

    def __reduce__(self):
        return ReadOnlyWtPct, (dict(self),)


@dataclass(frozen=True)
class Mineralogy:
    """Modal mineralogy in wt% by mineral name, validated on construction."""

    wt_pct: dict
    texture: Texture = field(default_factory=lambda: Texture(mean_grain_um=150.0))
    name: str = ""

    def __post_init__(self):
        known = mineral_table()
        if not isinstance(self.texture, Texture):  # a grain size given here failed later on .textural_index
            raise bad_value("Mineralogy", "texture", self.texture,
                            "a twin.ore.Texture (e.g. Texture(mean_grain_um=150))")
        clean = {}
        for mineral, value in dict(self.wt_pct).items():
            if mineral not in known:
                raise TwinInputError(
                    f"Unknown mineral {mineral!r} in Mineralogy."
                    f"{close_matches(str(mineral), known)} Known minerals: {', '.join(known)}.")
            if isinstance(value, bool):  # True was read as 1 wt%
                raise bad_value("Mineralogy", f"wt_pct[{mineral}]", value, "a number >= 0, not a bool")
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise bad_value("Mineralogy", f"wt_pct[{mineral}]", value, "a number >= 0") from None
            if not v >= 0.0 or math.isinf(v):
                raise bad_value("Mineralogy", f"wt_pct[{mineral}]", value, "a finite number >= 0")
            clean[mineral] = v
        total = sum(clean.values())
        if abs(total - 100.0) > SUM_TOLERANCE_WT_PCT:
            raise TwinInputError(
                f"The wt% of Mineralogy{f' {self.name!r}' if self.name else ''} must sum to 100 within "
                f"{SUM_TOLERANCE_WT_PCT} wt%. Got {total:.3f}{fractions_hint(total)}.")
        # renormalise the rounding residue so fractions sum to exactly 1; read-only, as the dataclass is
        object.__setattr__(self, "wt_pct", ReadOnlyWtPct({k: v * 100.0 / total for k, v in clean.items() if v > 0}))

    def fraction(self, mineral: str) -> float:
        """Mass fraction of ``mineral`` (0 if absent); a name not in the mineral table is refused (a
        misspelt "qartz" read as 0)."""
        if mineral not in self.wt_pct and mineral not in mineral_table():
            raise TwinInputError(f"Unknown mineral {mineral!r}.{close_matches(mineral, list(mineral_table()))}")
        return self.wt_pct.get(mineral, 0.0) / 100.0

    def group_fraction(self, minerals) -> float:
        return sum(self.fraction(m) for m in minerals)

    @property
    def clay_frac(self) -> float:
        return self.group_fraction(CLAY_MINERALS)

    @property
    def mica_frac(self) -> float:
        return self.group_fraction(MICA_MINERALS)

    @property
    def sulfide_frac(self) -> float:
        return self.group_fraction(SULFIDE_MINERALS)

    @property
    def hardness_index_gpa(self) -> float:
        """H_min = sum_i w_i H_i [GPa] (MISSION.md eq. 1)."""
        table = mineral_table()
        return sum(self.fraction(m) * table[m].vickers_gpa for m in self.wt_pct)

    @property
    def density_t_m3(self) -> float:
        """Solid density of the ore [t/m3]: harmonic mean of mineral densities by mass."""
        table = mineral_table()
        return 1.0 / sum(self.fraction(m) / table[m].density_t_m3 for m in self.wt_pct)

    @property
    def youngs_gpa(self) -> float:
        """Voigt-Reuss-Hill estimate of the aggregate Young's modulus [GPa] by volume fraction."""
        table = mineral_table()
        rho = self.density_t_m3
        vol = {m: self.fraction(m) * rho / table[m].density_t_m3 for m in self.wt_pct}
        voigt = sum(v * table[m].youngs_gpa for m, v in vol.items())
        reuss = 1.0 / sum(v / table[m].youngs_gpa for m, v in vol.items())
        return 0.5 * (voigt + reuss)

    @property
    def textural_index(self) -> float:
        return self.texture.textural_index

    def mix(self, other: "Mineralogy", frac_self: float) -> "Mineralogy":
        """Mass-weighted mixture (for blends): frac_self of this ore, the rest of ``other``."""
        f = check_range("Mineralogy.mix", "frac_self", frac_self, 0.0, 1.0, False, False)
        return Mineralogy.blend((self, other), (f, 1 - f))

    @staticmethod
    def blend(ores, fractions) -> "Mineralogy":
        """Mass-weighted mixture of ``ores`` at mass ``fractions`` (summing to 1): wt% linear, the mean
        grain size harmonic (grains per unit mass add), uniformity and association entropy linear (kept
        in their ranges against rounding). One ore is itself."""
        fr = [check_range("Mineralogy.blend", "fractions", f, 0.0, 1.0, lo_open=False, hi_open=False)
              for f in fractions]
        if len(fr) != len(ores):  # zip dropped the ores without a fraction
            raise bad_value("Mineralogy.blend", "fractions", list(fractions), f"one per ore ({len(ores)} ores)")
        if not blend_sum_ok(fr):  # (0.6, 0.397): the wt% were rescaled, the grain size not
            raise bad_value("Mineralogy.blend", "fractions", list(fractions), f"mass fractions summing to 1 within "
                            f"{blend_sum_tolerance(len(fr)):g} (sum {sum(fr):.6g})")
        fr = normalised_blend(fr)
        if len(ores) == 1:
            return ores[0]
        wt: dict = {}
        for ore, f in zip(ores, fr):
            for m, v in ore.wt_pct.items():
                wt[m] = wt.get(m, 0.0) + f * v
        grain = 1.0 / sum(f * o.texture.mean_grain_um ** -1 for o, f in zip(ores, fr))
        uni = sum(f * o.texture.uniformity for o, f in zip(ores, fr))
        ent = sum(f * o.texture.association_entropy for o, f in zip(ores, fr))
        name = "+".join(f"{o.name}{f:.2f}" for o, f in zip(ores, fr))
        return Mineralogy(wt, Texture(grain, min(uni, 1.0), min(max(ent, 0.0), 1.0)), name=name)

    def summary(self) -> dict:
        """Derived indices, unit-suffixed, for reports and the CLI."""
        return {
            "hardness_index_gpa": self.hardness_index_gpa,
            "textural_index": self.textural_index,
            "density_t_m3": self.density_t_m3,
            "youngs_gpa": self.youngs_gpa,
            "clay_frac": self.clay_frac,
            "mica_frac": self.mica_frac,
            "sulfide_frac": self.sulfide_frac,
            "mean_grain_um": self.texture.mean_grain_um,
        }
