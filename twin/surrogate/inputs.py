"""The surrogate's inputs: mineralogies (ores, blends) as a feature table of mineral wt%,
texture and operating conditions."""

from __future__ import annotations

from ..errors import TwinInputError
from ..ore.mineralogy import TEXTURE_COLUMNS, WT_SUFFIX, Mineralogy, Texture
from ..ore.minerals import mineral_table
from ..ore.ores import Blend, load_ore

#: The operating conditions among the inputs (after mineral wt% and texture).
CONDITION_COLUMNS = ("feed_tph", "speed_frac_critical")


def mineral_names() -> list[str]:
    """All minerals of ``twin/ore/data/minerals.csv`` (feature columns ``<mineral>_wt_pct``)."""
    return list(mineral_table())


def blend_mineralogy(blend: Blend) -> Mineralogy:
    """Mass-weighted mineralogy of a blend (texture as in :meth:`Mineralogy.mix`: harmonic
    mean grain size, linear uniformity and entropy)."""
    fr = [float(f) for f in blend.fractions]
    if len(blend.ores) == 1:
        return blend.ores[0]
    wt: dict = {}
    for ore, f in zip(blend.ores, fr):
        for m, v in ore.wt_pct.items():
            wt[m] = wt.get(m, 0.0) + f * v
    grain = 1.0 / sum(f / o.texture.mean_grain_um for o, f in zip(blend.ores, fr))
    uni = sum(f * o.texture.uniformity for o, f in zip(blend.ores, fr))
    ent = sum(f * o.texture.association_entropy for o, f in zip(blend.ores, fr))
    name = "+".join(f"{o.name}{f:.2f}" for o, f in zip(blend.ores, fr))
    return Mineralogy(wt, Texture(grain, min(uni, 1.0), min(max(ent, 0.0), 1.0)), name=name)


def as_mineralogy(ore) -> Mineralogy:
    """A Mineralogy, a Blend, a reference type letter or an ore TOML path -> Mineralogy."""
    if isinstance(ore, Blend):
        return blend_mineralogy(ore)
    return load_ore(ore)


def feature_frame(mineralogies, feed_tph, speed_frac_critical):
    """Input table of the surrogate (a DataFrame): one row per (mineralogy, feed, speed); the
    three arguments broadcast against each other."""
    import numpy as np  # tables only: a single answer (predict.py) is plain Python
    import pandas as pd

    ores = [as_mineralogy(m) for m in (mineralogies if isinstance(mineralogies, (list, tuple)) else [mineralogies])]
    feed = np.atleast_1d(np.asarray(feed_tph, float))
    speed = np.atleast_1d(np.asarray(speed_frac_critical, float))
    n = max(len(ores), feed.size, speed.size)
    for name, size in (("mineralogies", len(ores)), ("feed_tph", feed.size), ("speed_frac_critical", speed.size)):
        if size not in (1, n):
            raise TwinInputError(f"The '{name}' of feature_frame must have 1 or {n} entries. Got {size}.")
    ores = ores * n if len(ores) == 1 else ores
    minerals = mineral_names()
    rows = {m + WT_SUFFIX: [o.wt_pct.get(m, 0.0) for o in ores] for m in minerals}
    for c in TEXTURE_COLUMNS:
        rows[c] = [float(getattr(o.texture, c)) for o in ores]
    rows["feed_tph"] = np.broadcast_to(feed, (n,)).copy()
    rows["speed_frac_critical"] = np.broadcast_to(speed, (n,)).copy()
    return pd.DataFrame(rows)


def input_columns(minerals=None) -> list[str]:
    """The surrogate's input columns, in order: mineral wt%, texture, conditions."""
    minerals = mineral_names() if minerals is None else minerals
    return [m + WT_SUFFIX for m in minerals] + list(TEXTURE_COLUMNS) + list(CONDITION_COLUMNS)
