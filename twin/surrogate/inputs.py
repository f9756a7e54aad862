"""The surrogate's inputs: mineralogies (ores, blends) as a feature table of mineral wt%,
texture and operating conditions."""

from __future__ import annotations

from ..errors import TwinInputError
from ..ore.mineralogy import TEXTURE_COLUMNS, WT_SUFFIX, Mineralogy
from ..ore.minerals import mineral_table
from ..ore.ores import Blend, load_ore

#: The operating conditions among the inputs (after mineral wt% and texture).
CONDITION_COLUMNS = ("feed_tph", "speed_frac_critical")


def mineral_names() -> list[str]:
    """All minerals of ``twin/ore/data/minerals.csv`` (feature columns ``<mineral>_wt_pct``)."""
    return list(mineral_table())


def blend_mineralogy(blend: Blend) -> Mineralogy:
    """Mass-weighted mineralogy of a blend (:meth:`Mineralogy.blend`)."""
    return Mineralogy.blend(blend.ores, blend.fractions)


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
