"""Size-by-size tables of a run's streams and size distributions over time, from the plant
model's states (as a simulator prints a circuit: one row per size class, one column group
per stream).

Streams, each a mass per size class (flows in t/h, the mill content in t):

- ``fresh_feed``: feed rate times the feed's size distribution (every ore is fed at the
  scene's feed size);
- ``mill_discharge``: what leaves the last mixer (through a grate, if classified);
- ``cyclone_feed``: with a hydrocyclone, the mill discharge, and the fresh feed in a reverse circuit
  (whose mill discharge was reported as the cyclone feed: 652.6 t/h against the mill's 402.6);
- ``cyclone_underflow``: the cyclone's coarse stream, returned to the mill feed;
- ``product``: the cyclone overflow, or the mill discharge without a cyclone;
- ``mill_content``: the mill's hold-up, summed over mixers and ores.

A batch grind has only the mill content. With a hydrocyclone the table also gives the
partition to underflow per class (the Tromp curve): underflow / cyclone feed, water bypass
included (Plitt's actual, not corrected, efficiency).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

#: Stream -> (unit suffix of its column, what it is).
STREAMS = {
    "fresh_feed": ("tph", "fresh feed"),
    "mill_discharge": ("tph", "mill discharge"),
    "cyclone_feed": ("tph", "cyclone feed (the mill discharge, and the fresh feed in a reverse circuit)"),
    "cyclone_underflow": ("tph", "cyclone underflow (returned to the mill)"),
    "product": ("tph", "product (cyclone overflow, or mill discharge)"),
    "mill_content": ("t", "mill content"),
}
#: The model outputs (per size class) of a hydrocyclone circuit: cyclone feed and underflow.
CYCLONE_OUTPUTS = {"cyclone_feed": "cyclone_feed_tph", "cyclone_underflow": "cyclone_underflow_tph"}
#: Number of size distributions kept over a run (evenly spaced samples, first and last included).
N_PSD_SNAPSHOTS = 6
#: How far from 1 a cumulative fraction passing is taken as the round-off of its sum and shown as 1: all of a
#: stream passes its top size (and a size with nothing above it), where streams.csv read 100.00000000000003 %
#: and 99.99999999999999 %. twin.sizes keeps the round-off (the P-values in the top class would move by it, at
#: 1e-15); more than this above 1 is a class mass below zero (twin.sizes.NEGATIVE_MASS_TOL), shown as it is.
PASSING_ROUNDOFF = 1e-12


@dataclass
class Samples:
    """The plant's state, inputs and disturbances at the samples of a run (rows)."""

    time_h: np.ndarray
    x: np.ndarray
    u: np.ndarray
    d: np.ndarray

    @classmethod
    def from_frame(cls, model, states, frame: pd.DataFrame, components) -> "Samples":
        """From an open-loop or batch frame (inputs and blend columns) and its states."""
        u = frame[["feed_tph", "speed_frac_critical"]].to_numpy(float)
        d = frame[[f"blend_{c}_frac" for c in components] + ["hardness_scale"]].to_numpy(float)
        return cls(frame["time_h"].to_numpy(float), np.asarray(states, float), u, d)


def stream_masses(model, x, u, d, batch: bool) -> dict[str, np.ndarray]:
    """Each stream's mass per size class (t/h, or t for the mill content) at one instant."""
    content = model.mass_array(x).sum(axis=(0, 1))
    if batch:
        return {"mill_content": content}
    product = np.asarray(model.product_psd_function()(x, u, d), float).ravel()
    out = {"fresh_feed": float(u[0]) * np.asarray(model.spec.feed_frac, float), "mill_discharge": product}
    if all(name in model.outputs for name in CYCLONE_OUTPUTS.values()):
        for stream, name in CYCLONE_OUTPUTS.items():
            out[stream] = np.asarray(model.outputs[name](x, u, d), float).ravel()
        reverse = model.spec.effect_options.get("classification", {}).get("circuit") == "reverse"
        out["mill_discharge"] = out["cyclone_feed"] - (out["fresh_feed"] if reverse else 0.0)
    return out | {"product": product, "mill_content": content}


def size_by_size(model, x, u, d, batch: bool) -> pd.DataFrame:
    """One row per size class (coarsest first): class bounds and geometric mean [um], then for every stream its
    mass (``<stream>_tph`` or ``_t``), % retained and cumulative % passing the class's upper
    size; with a hydrocyclone ``partition_to_underflow_frac``."""
    grid = model.spec.grid
    table = pd.DataFrame({"size_upper_um": grid.upper_um, "size_lower_um": grid.lower_um, "size_mid_um": grid.mid_um})
    table.index = pd.RangeIndex(1, grid.count + 1, name="size_class")
    masses = stream_masses(model, x, u, d, batch)
    for stream, mass in masses.items():
        total = mass.sum()
        table[f"{stream}_{STREAMS[stream][0]}"] = mass
        table[f"{stream}_retained_pct"] = 100.0 * mass / total if total > 0 else np.nan
        table[f"{stream}_passing_pct"] = 100.0 * _passing(grid, mass)
    if "cyclone_underflow" in masses:
        feed = masses["cyclone_feed"]
        table["partition_to_underflow_frac"] = np.divide(masses["cyclone_underflow"], feed,
                                                         out=np.full(feed.shape, np.nan), where=feed > 0)
    return table


def psd_snapshots(model, samples: Samples, stream: str, batch: bool) -> pd.DataFrame:
    """Cumulative fraction passing of one stream at ``N_PSD_SNAPSHOTS`` evenly spaced samples:
    rows = times [h], columns = class upper sizes [um] (``attrs['what']`` names the stream)."""
    grid = model.spec.grid
    idx = np.unique(np.linspace(0, len(samples.time_h) - 1, N_PSD_SNAPSHOTS).round().astype(int))
    rows = {float(samples.time_h[i]): _passing(grid, stream_masses(model, samples.x[i], samples.u[i],
                                                                   samples.d[i], batch)[stream]) for i in idx}
    psd = pd.DataFrame(rows, index=pd.Index(grid.upper_um, name="size_um")).T
    psd.index.name = "time_h"
    psd.attrs["what"] = stream.replace("_", " ")
    return psd


def _passing(grid, mass) -> np.ndarray:
    """Cumulative fraction passing of a stream's mass per class, 1 where it is 1 to within round-off
    (:data:`PASSING_ROUNDOFF`); NaN when it carries nothing (a stopped mill's product has no size
    distribution)."""
    if not np.sum(mass) > 0:
        return np.full(grid.count, np.nan)
    passing = grid.cumulative_passing(mass)
    return np.where(np.abs(passing - 1.0) <= PASSING_ROUNDOFF, 1.0, passing)


def run_size_data(model, samples: Samples, batch: bool) -> dict:
    """What a run keeps of its sizes: ``psd`` (product, or the mill content of a batch grind,
    over time), ``mill_psd`` (the mill content over time; None for a batch grind, where it is
    ``psd``), ``streams`` (:func:`size_by_size` at the first and the last sample, keyed
    "start" and "end")."""
    first = "mill_content" if batch else "product"
    return {"psd": psd_snapshots(model, samples, first, batch),
            "mill_psd": None if batch else psd_snapshots(model, samples, "mill_content", batch),
            "streams": {when: size_by_size(model, samples.x[i], samples.u[i], samples.d[i], batch)
                        for when, i in (("start", 0), ("end", len(samples.time_h) - 1))}}


def fit_rosin_rammler(size_um, passing_frac, lo: float = 0.02, hi: float = 0.98) -> tuple[float, float]:
    """Rosin-Rammler ``P = 1 - exp(-(x / x63)^n)`` fitted to cumulative passing by least squares
    of ``ln(-ln(1 - P))`` on ``ln x`` over the points with ``lo < P < hi`` (the linearised form,
    Rosin & Rammler 1933; the tails carry no information). Returns ``(x63_um, n)``; nan, nan
    with fewer than two such points."""
    x = np.asarray(size_um, float)
    p = np.asarray(passing_frac, float)
    keep = (p > lo) & (p < hi) & (x > 0)
    if keep.sum() < 2:
        return float("nan"), float("nan")
    n, c = np.polyfit(np.log(x[keep]), np.log(-np.log1p(-p[keep])), 1)
    return float(np.exp(-c / n)), float(n)
