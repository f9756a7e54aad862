"""Shared helpers of the dem benchmarks (markdown tables without extra dependencies)."""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

OUT = os.path.join(os.path.dirname(__file__), "results")


def md_table(df, floatfmt: str = ".4g") -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(str(c) for c in cols) + " |", "|" + "---|" * len(cols)]
    for _, row in df.iterrows():
        cells = []
        for c in cols:
            v = row[c]
            cells.append(format(v, floatfmt) if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_table(df, name: str, title: str, notes: str = "") -> None:
    os.makedirs(OUT, exist_ok=True)
    df.to_csv(os.path.join(OUT, name + ".csv"), index=False)
    with open(os.path.join(OUT, name + ".md"), "w") as fh:
        fh.write(f"# {title}\n\n")
        if notes:
            fh.write(notes.strip() + "\n\n")
        fh.write(md_table(df))
