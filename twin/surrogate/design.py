"""The surrogate's training design: seeded mineralogies (library draws, mixtures, reference
blends) times a Latin hypercube of operating points, each run through the twin's steady state.
See docs/surrogate.md for the design and its reasons."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import qmc

from ..errors import SolverError, TwinError, bad_value
from ..ore import Blend, generate_library, reference_ores, to_mineralogies
from ..calibration import load_calibration
from .files import GENERATE_COMMAND, TABLE_PATH
from .inputs import blend_mineralogy, feature_frame
from .model import TARGETS

#: Operating ranges of the training design (laboratory mill): feed [t/h] (log-uniform),
#: speed [fraction of critical] (uniform). Nominal: 0.031 t/h, 0.70.
FEED_RANGE_TPH = (0.015, 0.050)
SPEED_RANGE = (0.60, 0.85)
DEFAULT_SEED = 2026
DEFAULT_N_MINERALOGIES = 320
DEFAULT_POINTS = 8


def design_mineralogies(seed: int = DEFAULT_SEED, n_mineralogies: int = DEFAULT_N_MINERALOGIES):
    """The seeded mineralogy design (module docstring): list of (Mineralogy, kind)."""
    if int(n_mineralogies) != n_mineralogies or n_mineralogies < 8:
        raise bad_value("design_mineralogies", "n_mineralogies", n_mineralogies, "an integer >= 8")
    rng = np.random.default_rng(seed)
    n_lib = n_mineralogies // 2
    n_mix = n_mineralogies // 4
    n_ref = n_mineralogies - n_lib - n_mix
    types = ["A", "B", "C", "D"]

    def counts(n):
        base = {t: n // 4 for t in types}
        for t in types[: n % 4]:
            base[t] += 1
        return base

    out = []
    lib = generate_library(seed=int(rng.integers(2**31)), counts=counts(n_lib))
    for ore, t in zip(to_mineralogies(lib), lib["generating_type"]):
        out.append((ore, f"library:{t}"))
    lib2 = generate_library(seed=int(rng.integers(2**31)), counts=counts(2 * n_mix))
    ores2 = to_mineralogies(lib2)
    t2 = lib2["generating_type"].to_numpy()
    for _ in range(n_mix):
        i = int(rng.integers(len(ores2)))
        j = int(rng.choice(np.flatnonzero(t2 != t2[i])))
        f = float(rng.uniform(0.1, 0.9))
        out.append((ores2[i].mix(ores2[j], f), f"library-mix:{t2[i]}{t2[j]}"))
    out = _independent_textures(out, rng)
    refs = reference_ores()
    for t in types[: min(4, n_ref)]:
        out.append((refs[t], f"reference:{t}"))
    for _ in range(n_ref - min(4, n_ref)):
        k = int(rng.integers(2, 4))
        pick = rng.choice(types, size=k, replace=False)
        fr = rng.dirichlet(np.ones(k))
        blend = Blend(tuple(refs[t] for t in pick), tuple(fr / fr.sum()))
        out.append((blend_mineralogy(blend), "reference-mix:" + "".join(pick)))
    return out


def _independent_textures(design: list, rng: np.random.Generator) -> list:
    """The design's mineralogies each with a texture drawn independently of it, over the ranges the draws span
    (grain size log-uniform, uniformity and association entropy uniform): the library ties texture to ore
    type, so a regression read mineralogy as texture (B's mineralogy at 25 or 250 um moved the surrogate's P80
    by 8 %, in opposite directions by uniformity, under a calibration that reads no texture)."""
    from dataclasses import replace

    from ..ore import Texture

    textures = [ore.texture for ore, _ in design]
    grain = [math.log(t.mean_grain_um) for t in textures]
    spans = {k: (min(getattr(t, k) for t in textures), max(getattr(t, k) for t in textures))
             for k in ("uniformity", "association_entropy")}
    out = []
    for ore, kind in design:
        texture = Texture(mean_grain_um=math.exp(rng.uniform(min(grain), max(grain))),
                          **{k: float(rng.uniform(*span)) for k, span in spans.items()})
        out.append((replace(ore, texture=texture), kind))
    return out


def design_conditions(n_points: int, rng: np.random.Generator) -> np.ndarray:
    """(n_points, 2) Latin hypercube: feed [t/h] log-uniform, speed uniform."""
    lhs = qmc.LatinHypercube(d=2, rng=rng).random(n_points)
    lo = np.array([math.log(FEED_RANGE_TPH[0]), SPEED_RANGE[0]])
    hi = np.array([math.log(FEED_RANGE_TPH[1]), SPEED_RANGE[1]])
    pts = qmc.scale(lhs, lo, hi)
    pts[:, 0] = np.exp(pts[:, 0])
    return pts


def twin_kpis(twin, feed_tph: float, speed_frac_critical: float) -> dict:
    """The surrogate's targets from one twin steady state."""
    ss = twin.steady(feed_tph=feed_tph, speed_frac_critical=speed_frac_critical)
    return {"p80_um": ss.p80_um, "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"],
            "load_frac": ss.outputs["load_frac"]}


def generate_training_table(seed: int = DEFAULT_SEED, n_mineralogies: int = DEFAULT_N_MINERALOGIES,
                            points_per_mineralogy: int = DEFAULT_POINTS, mill: str = "lab",
                            progress: bool = False, calibration=None) -> pd.DataFrame:
    """Run the twin over the seeded design; one row per steady state with the input columns
    of :func:`feature_frame`, ``mineralogy_id``, ``design_kind``, the targets and
    ``twin_seconds`` (build share + steady state), run with ``calibration`` (the default's
    unless named). Failed steady states are counted in ``attrs['failed']`` (with their inputs),
    never silently dropped."""
    from ..twin import Twin  # the twin imports the calibration; built here only

    cal = load_calibration(calibration)
    t_start = time.perf_counter()
    design = design_mineralogies(seed, n_mineralogies)
    rng = np.random.default_rng([seed, 1])
    frames, failed = [], []
    for k, (ore, kind) in enumerate(design):
        pts = design_conditions(points_per_mineralogy, rng)
        t0 = time.perf_counter()
        twin = Twin(ore, mill=mill, calibration=cal)
        rows = []
        for feed, speed in pts:
            try:
                rows.append(twin_kpis(twin, feed, speed))
            except SolverError as exc:
                failed.append({"mineralogy_id": k, "feed_tph": feed, "speed_frac_critical": speed, "error": str(exc)})
                rows.append(None)
        dt = time.perf_counter() - t0
        ok = [i for i, r in enumerate(rows) if r is not None]
        fr = feature_frame(ore, pts[ok, 0], pts[ok, 1])
        fr.insert(0, "design_kind", kind)
        fr.insert(0, "mineralogy_id", k)
        for t in TARGETS:
            fr[t] = [rows[i][t] for i in ok]
        fr["twin_seconds"] = dt / len(pts)
        frames.append(fr)
        if progress and (k + 1) % 20 == 0:
            print(f"  {k + 1}/{len(design)} mineralogies, {time.perf_counter() - t_start:.0f} s", file=sys.stderr)
    table = pd.concat(frames, ignore_index=True)
    table.attrs = {"command": GENERATE_COMMAND, "seed": seed, "n_mineralogies": n_mineralogies,
                   "points_per_mineralogy": points_per_mineralogy, "mill": mill,
                   "feed_range_tph": list(FEED_RANGE_TPH), "speed_range": list(SPEED_RANGE),
                   "calibration": {"name": cal.name, "sha256": cal.sha256}, "calibration_sha256": cal.sha256,
                   "failed": failed, "seconds": round(time.perf_counter() - t_start, 1),
                   "numpy": np.__version__, "pandas": pd.__version__}
    return table


def load_training_table(path: str | Path | None = None) -> pd.DataFrame:
    """The cached training table (``twin/surrogate/data/surrogate_training.parquet`` by default)."""
    path = Path(path) if path else TABLE_PATH
    if not path.is_file():
        raise TwinError(f"No surrogate training table {path}: run `{GENERATE_COMMAND}`.")
    return pd.read_parquet(path)
