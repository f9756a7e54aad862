"""Labels that group rows of the ore tables (an ore type, a curve id): one spelling per label.

Grouped as written, 'B', ' B' and 'b' were three ore types, each fitted on a third of the particles.
Surrounding whitespace is stripped (a space after a CSV comma is not part of the label); labels still
equal but for case or inner whitespace are refused, with both spellings and their rows, since
which of them the user means is not for the reader to guess.
"""

from __future__ import annotations

import pandas as pd

from ..errors import TwinInputError


def clean_labels(values: pd.Series, column: str, source: str) -> pd.Series:
    """``values`` as str, surrounding whitespace stripped; raise TwinInputError naming every pair of
    labels that differ only by case or whitespace (rows 1-based, as data rows of the table)."""
    raw = values.astype(str).reset_index(drop=True)
    clean = raw.str.strip()
    key = clean.str.casefold().str.replace(r"\s+", "", regex=True)
    first_key: dict[str, int] = {}    # the first row of each label up to case and whitespace
    first_label: dict[str, int] = {}  # the first row of each stripped label
    clashes = []
    for i, (k, label) in enumerate(zip(key, clean)):
        j = first_key.setdefault(k, i)
        if first_label.setdefault(label, i) == i and j != i:  # a new spelling of a label seen before
            clashes.append((j, i))
    if clashes:
        def spell(i):
            stripped = f", {raw.iloc[i]!r} before stripping" if raw.iloc[i] != clean.iloc[i] else ""
            return f"{clean.iloc[i]!r} (row {i + 1}{stripped})"
        pairs = "; ".join(f"{spell(j)} and {spell(i)}" for j, i in clashes[:20])
        raise TwinInputError(
            f"{source}: column '{column}' has labels that differ only by case or whitespace: {pairs}. "
            "Rows are grouped by this label, so one group would be split in two; write each label one way "
            "(surrounding spaces are stripped, case and inner spaces are kept).")
    return pd.Series(clean.to_numpy(), index=values.index, name=values.name)
