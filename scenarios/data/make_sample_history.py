"""Write ``sample_history.csv``: one SYNTHETIC day of feed mineralogy at one-minute resolution.

Nothing here is measured. The feed moves between the reference ore types of
``twin/ore/data/ores.toml`` (Type B, a ramp to 60 % B / 40 % D, an A-rich stretch, a short C
streak, back to B); each minute's mineralogy and texture are the fraction-weighted mix of
the types plus slow ore variability and analyser noise. The ``feed_tph``,
``speed_frac_critical`` and ``p80_um`` columns are made-up operator moves and a made-up
product size, only so that a replay has "recorded" plant values to compare with.

    python scenarios/data/make_sample_history.py [--seed 20261122] [--out PATH]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from twin import reference_ores, write_atomically

#: The file's first line: a file that does not start with it is not this script's, and is not overwritten.
FIRST_LINE = "# SYNTHETIC data, not measured: one day of feed mineralogy at one-minute resolution."
MINUTES = 24 * 60
START = pd.Timestamp("2026-01-15T00:00:00")
#: (hour, blend) knots of the ore-type fractions; linear between knots.
KNOTS = [(0, {"B": 1.0}), (6, {"B": 1.0}), (8, {"B": 0.6, "D": 0.4}), (13, {"B": 0.6, "D": 0.4}),
         (14.5, {"A": 0.7, "B": 0.3}), (19, {"A": 0.7, "B": 0.3}), (20, {"B": 1.0}),
         (21, {"B": 1.0}), (21.3, {"B": 0.5, "C": 0.5}), (22, {"B": 0.5, "C": 0.5}),
         (22.3, {"B": 1.0}), (24, {"B": 1.0})]


def ore_fractions(t_h: np.ndarray, rng: np.random.Generator) -> pd.DataFrame:
    """Ore-type fractions per minute: the knots plus slow AR(1) variability, summing to 1."""
    types = sorted(reference_ores())
    knot_t = np.array([k[0] for k in KNOTS])
    frac = np.column_stack([np.interp(t_h, knot_t, [k[1].get(ty, 0.0) for k in KNOTS])
                            for ty in types])
    wiggle = np.zeros_like(frac)
    for i in range(1, len(t_h)):  # slow variability within the stockpile, ~1 h memory
        wiggle[i] = 0.983 * wiggle[i - 1] + 0.01 * rng.standard_normal(len(types))
    frac = np.clip(frac + wiggle * (frac > 0), 0.0, None)
    return pd.DataFrame(frac / frac.sum(axis=1, keepdims=True), columns=types)


def synthetic_day(seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    t_h = np.arange(MINUTES) / 60.0
    frac = ore_fractions(t_h, rng)
    refs = reference_ores()
    minerals = sorted({m for ore in refs.values() for m in ore.wt_pct})
    wt = sum(np.outer(frac[ty], [refs[ty].wt_pct.get(m, 0.0) for m in minerals]) for ty in frac)
    wt = np.clip(wt * (1 + 0.02 * rng.standard_normal(wt.shape)), 0.0, None)  # analyser noise
    wt = 100.0 * wt / wt.sum(axis=1, keepdims=True)
    stamps = pd.date_range(START, periods=MINUTES, freq="min")
    out = pd.DataFrame({"timestamp": stamps.strftime("%Y-%m-%dT%H:%M:%S")})
    for j, m in enumerate(minerals):
        out[f"{m}_wt_pct"] = np.round(wt[:, j], 3)
    for key in ("mean_grain_um", "uniformity", "association_entropy"):
        out[key] = np.round(sum(frac[ty] * getattr(refs[ty].texture, key) for ty in frac), 4)
    soft = frac.get("C", 0) + frac.get("D", 0)
    out["feed_tph"] = np.round(30.0 * (1 + 0.08 * soft - 0.06 * frac["A"])
                               + 0.4 * rng.standard_normal(MINUTES), 2)
    out["speed_frac_critical"] = np.round(np.where(t_h < 15, 0.72, 0.75), 3)
    out["p80_um"] = np.round(210 + 60 * soft - 25 * frac["A"] + 6 * rng.standard_normal(MINUTES), 1)
    return out


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=20261122)
    parser.add_argument("--out", type=Path, default=Path(__file__).with_name("sample_history.csv"))
    args = parser.parse_args(argv)
    if args.out.exists() and not _written_here(args.out):  # a plant's own history was replaced by this made-up day
        parser.error(f"refusing to overwrite {args.out}: it is not a sample history this script wrote (its first "
                     f"line is not {FIRST_LINE!r}); give a new --out path")
    day = synthetic_day(args.seed)
    header = (f"{FIRST_LINE}\n"
              f"# Produced by: python scenarios/data/make_sample_history.py --seed {args.seed}\n"
              f"# Ore types from twin/ore/data/ores.toml; feed_tph, speed_frac_critical and p80_um "
              f"are made up.\n")
    text = header + day.to_csv(index=False, lineterminator="\n")
    write_atomically(args.out, lambda tmp: tmp.write_bytes(text.encode("utf-8")))  # a stop leaves the file as it was
    return args.out


def _written_here(path: Path) -> bool:
    """Whether ``path`` is a file that starts as this script's output does."""
    try:
        with path.open(encoding="utf-8", errors="replace") as fh:
            return fh.readline().rstrip("\r\n") == FIRST_LINE
    except OSError:  # a folder, unreadable
        return False


if __name__ == "__main__":
    print(main())
