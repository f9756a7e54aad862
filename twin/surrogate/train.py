"""Train, cross-validate and save the surrogate; ``python -m twin.surrogate --generate --train``."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pandas as pd

from ..atomic import json_text
from .design import (DEFAULT_N_MINERALOGIES, DEFAULT_POINTS, DEFAULT_SEED, generate_training_table,
                     load_training_table)
from .files import COMPILED_PATH, GENERATE_COMMAND, MODEL_PATH, TABLE_PATH, TRAIN_COMMAND, load, save, save_compiled
from .model import DEFAULT_PARAMS, Surrogate, cross_validate, held_out_split, split_xy


def train_and_save(table: pd.DataFrame, params: dict | None = None, out: str | Path | None = None,
                   n_splits: int = 5) -> tuple[Surrogate, dict]:
    """Cross-validate, hold out 20 % of mineralogies, fit on all rows and save."""
    params = dict(DEFAULT_PARAMS if params is None else params)
    cv = cross_validate(table, n_splits=n_splits, **params)
    tr, te = held_out_split(table)
    held = Surrogate(**params).fit(*split_xy(tr)[:2]).r2_per_kpi(*split_xy(te)[:2])
    t0 = time.perf_counter()
    X, Y, _ = split_xy(table)
    sur = Surrogate(**params).fit(X, Y)
    fit_s = time.perf_counter() - t0
    meta = {"command": TRAIN_COMMAND, "table_command": GENERATE_COMMAND, "mill": table.attrs.get("mill", "lab"),
            "design": {k: table.attrs.get(k) for k in ("seed", "n_mineralogies", "points_per_mineralogy",
                                                        "feed_range_tph", "speed_range")},
            "n_rows": len(table), "cv_r2": cv, "held_out_r2": held, "fit_seconds": round(fit_s, 3),
            "table_seconds": table.attrs.get("seconds"), "calibration": table.attrs.get("calibration"),
            "calibration_sha256": table.attrs.get("calibration_sha256"), "failed_steady_states": len(table.attrs.get("failed", []))}
    save(sur, out or MODEL_PATH, meta)
    sur.metadata_ = meta
    return sur, meta


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m twin.surrogate", description="Generate the training table and train the twin's PLS surrogate.")
    p.add_argument("--generate", action="store_true", help=f"run the twin over the design -> {TABLE_PATH.name}")
    p.add_argument("--train", action="store_true", help=f"fit and cross-validate -> {MODEL_PATH.name} "
                   f"and {COMPILED_PATH.name}")
    p.add_argument("--compile", action="store_true",
                   help=f"write {COMPILED_PATH.name} (numpy-only form) from the saved {MODEL_PATH.name}")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED)
    p.add_argument("--n-mineralogies", type=int, default=DEFAULT_N_MINERALOGIES)
    p.add_argument("--points", type=int, default=DEFAULT_POINTS, help="operating points per mineralogy")
    p.add_argument("--table", help=f"training table (default {TABLE_PATH})")
    p.add_argument("--out", help=f"surrogate file (default {MODEL_PATH})")
    p.add_argument("--calibration", default=None, help="the calibration the twin runs (default: dem)")
    args = p.parse_args(argv)
    if not (args.generate or args.train or args.compile):
        p.error("give --generate, --train and/or --compile")
    table_path = Path(args.table) if args.table else TABLE_PATH
    if args.generate or (args.train and not table_path.is_file()):
        table = generate_training_table(args.seed, args.n_mineralogies, args.points, progress=True,
                                        calibration=args.calibration)
        table.to_parquet(table_path, index=False)
        print(f"wrote {len(table)} steady states of {args.n_mineralogies} mineralogies to {table_path} "
              f"in {table.attrs['seconds']} s ({len(table.attrs['failed'])} failed)")
    if args.train:
        table = load_training_table(table_path)
        _, meta = train_and_save(table, out=args.out)
        print(json_text({k: meta[k] for k in ("n_rows", "cv_r2", "held_out_r2", "fit_seconds")}, indent=1))
    elif args.compile:
        joblib_path = Path(args.out) if args.out else MODEL_PATH
        sur = load(joblib_path)
        print(f"wrote {save_compiled(sur, joblib_path, sur.metadata_)}")
    return 0
