"""The feed on a run's sample grid: blend fractions of the scene's components (a recorded
mineralogy mapped onto them), and the recorded plant inputs of a history."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import nnls

from scenarios.scene import TEXTURE_COLUMNS, Scene, feed_table, load_history, ore_column, ore_mineralogies
from scenarios.scene.history import History
from twin import Mineralogy, Texture, file_sha256, reference_ores

#: Weight of the "fractions sum to 1" row in the NNLS fit of a mineralogy to the ores (wt%).
SUM_ROW_WEIGHT = 100.0


def component_ores(scene: Scene) -> dict:
    """Component name -> twin Mineralogy: the scene's ores, or the reference types A-D for a
    mineralogy history in a scene without ores."""
    if scene.ores:
        return ore_mineralogies(scene)
    return {name: Mineralogy(dict(o.wt_pct), o.texture, name=name)
            for name, o in sorted(reference_ores().items())}


def mineralogy_to_blend(wt_pct: pd.DataFrame, ores: dict) -> tuple[np.ndarray, np.ndarray]:
    """Each row of mineral wt% as a mix of the ores: ``(fractions (n, n_ores), residual_wt_pct (n,))``.

    Rule: non-negative least squares of the row's wt% vector on the ores' wt% vectors, with a
    row of weight ``SUM_ROW_WEIGHT`` asking the fractions to sum to 1; the fractions are then
    rescaled to sum exactly to 1. The residual is the Euclidean distance (wt%) between the row
    and the mix, reported per sample: a large residual means the recorded feed is not a mix of
    the scene's ores and the run can only approximate it. Minerals absent from every ore enter only
    through the residual; the texture columns do not enter the fit (:func:`texture_ratios` compares
    them with the mix's).
    """
    minerals = [c[: -len("_wt_pct")] for c in wt_pct.columns if c.endswith("_wt_pct")]
    all_minerals = sorted(set(minerals) | {m for o in ores.values() for m in o.wt_pct})
    A = np.array([[ores[n].wt_pct.get(m, 0.0) for n in ores] for m in all_minerals], float)
    A_aug = np.vstack([A, SUM_ROW_WEIGHT * np.ones(len(ores))])
    Y = np.zeros((len(wt_pct), len(all_minerals)))
    for j, m in enumerate(all_minerals):
        if m in minerals:
            Y[:, j] = wt_pct[f"{m}_wt_pct"].to_numpy(float)
    fracs = np.empty((len(wt_pct), len(ores)))
    resid = np.empty(len(wt_pct))
    cache: dict[bytes, tuple] = {}
    for i, y in enumerate(Y):
        key = y.tobytes()
        if key not in cache:
            w, _ = nnls(A_aug, np.append(y, SUM_ROW_WEIGHT))
            w = w / w.sum() if w.sum() > 0 else np.ones(len(ores)) / len(ores)
            cache[key] = (w, float(np.linalg.norm(A @ w - y)))
        fracs[i], resid[i] = cache[key]
    return fracs, resid


#: NNLS residual [wt%, Euclidean over the minerals] above which a recorded mineralogy is not a mix
#: of the scene's ores: several times the residual of the shipped day's history (max 0.9 wt%),
#: whose assays are mixes of the ores plus noise; a mineral the ores lack moves it by its wt%.
FIT_RESIDUAL_WARN_WT_PCT = 5.0


#: Ratio of textural indices (twin.ore.Texture.textural_index, the texture's part in the breakage
#: rates) between the simulated mix of ores and a recorded texture beyond which a run warns: the step
#: between neighbouring reference ore types (A to B 1.51x, B to C 1.52x), so the recorded ore breaks
#: as another type would. The shipped day's textures lie within 1.18x of its mixes.
TEXTURE_RATIO_WARN = 1.5


def fit_warnings(feed: pd.DataFrame, components: list[str]) -> list[str]:
    """Warnings when a mineralogy history's samples are not mixes of the ores (the feed table's
    ``history_fit_residual_wt_pct`` above :data:`FIT_RESIDUAL_WARN_WT_PCT`), or their texture is not
    the mix's (``history_textural_index_ratio``, mix over recorded, beyond :data:`TEXTURE_RATIO_WARN`
    either way): the simulated feed is not the recorded one there."""
    out = []
    t = feed["time_h"].to_numpy(float)
    if "history_fit_residual_wt_pct" in feed.columns:
        resid = feed["history_fit_residual_wt_pct"].to_numpy(float)
        misfit = resid > FIT_RESIDUAL_WARN_WT_PCT
        if misfit.any():
            out.append(f"the recorded mineralogy is not a mix of the ores {', '.join(components)} on "
                       f"{misfit.mean():.0%} of the samples (from {t[misfit][0]:.4g} h; NNLS residual up to "
                       f"{resid.max():.3g} wt%, above {FIT_RESIDUAL_WARN_WT_PCT:g}): the simulated feed is not the "
                       "recorded one there; add an ore that holds the missing minerals")
    if "history_textural_index_ratio" in feed.columns:
        ratio = feed["history_textural_index_ratio"].to_numpy(float)
        off = np.abs(np.log(ratio)) > np.log(TEXTURE_RATIO_WARN)
        if off.any():
            worst = ratio[np.argmax(np.abs(np.log(ratio)))]
            out.append(f"the recorded texture is not that of the mix of the ores {', '.join(components)} on "
                       f"{off.mean():.0%} of the samples (from {t[off][0]:.4g} h; the mix's textural index "
                       f"{worst:.3g}x the recorded, beyond {TEXTURE_RATIO_WARN:g}x either way): a run breaks the "
                       "ores' textures, not the recorded one; add an ore with the recorded texture")
    return out


def texture_ratios(table: pd.DataFrame, fracs: np.ndarray, ores: dict) -> np.ndarray:
    """Textural index of each sample's mix of the ores (Mineralogy.blend) over that of its recorded
    texture (the table's texture columns)."""
    comps = list(ores.values())
    out = np.empty(len(table))
    for i, (row, w) in enumerate(zip(table[list(TEXTURE_COLUMNS)].itertuples(index=False), fracs)):
        mix = Mineralogy.blend(comps, list(w)).texture.textural_index
        out[i] = mix / Texture(*row).textural_index
    return out


def history_changes(history: History | None) -> list[str]:
    """What reading the history changed in its records (``History.changes``: rows sorted or
    dropped, values held, columns dropped), for the run's warnings: as notes inside summary.json, an
    hour of records dropped as duplicates went unseen."""
    return [] if history is None else [f"history {history.source.name}: {line}" for line in history.changes]


def history_file_changes(history: History | None) -> list[str]:
    """A warning when the history file is not, at the end of a run, the bytes the run was fed (rewritten
    or removed meanwhile: summary.json records the SHA-256 of what was read); else none."""
    if history is None or history.sha256 is None:
        return []
    return fed_file_changes("history file", history.source, history.sha256)


def fed_file_changes(what: str, path, sha256: str, *, read: str = "the run was fed the file with SHA-256",
                     consequence: str = "") -> list[str]:
    """A warning when the file at ``path`` (``what``: "history file") is not, at the end of a run, the bytes of
    ``sha256`` (``read``: when that was read) the run was fed (rewritten or removed meanwhile); else none.
    ``consequence``: what the change may have done to the run, said before the advice."""
    path = Path(path)
    now = file_sha256(path) if path.is_file() else None
    if now == sha256:
        return []
    found = f"its SHA-256 is now {now[:12]}" if now else "it is gone"
    return [f"the {what} {path} changed during the run ({read} {sha256[:12]}, which summary.json records; "
            f"{found}): {consequence}run again with the file left as it is"]


def feed_schedule(scene: Scene, components: list[str], times_h: np.ndarray, ores: dict | None = None
                  ) -> tuple[pd.DataFrame, list[str]]:
    """The feed on the sample grid: columns ``ore_<c>_frac`` per component, the recorded
    plant values (``recorded_*``) if the history has them, ``history_fit_residual_wt_pct`` for
    a mineralogy history. Returns ``(table, notes)``."""
    notes: list[str] = []
    table = feed_table(scene, times_h).reset_index()
    history = load_history(scene)
    if history is not None:
        notes += [f"history {history.source.name}: {line}" for line in history.report if line not in history.changes]
        if len(times_h) < len(history.frame):  # the report counts the whole history's samples
            notes.append(f"history {history.source.name}: the run replays its first {len(times_h)} samples "
                         f"({times_h[-1]:g} of {history.span_h:g} h)")
    if history is not None and history.kind == "mineralogy":
        ores = ores if ores is not None else component_ores(scene)
        comp_cols = [c for c in table.columns if c.endswith("_wt_pct")]
        fracs, resid = mineralogy_to_blend(table[comp_cols], ores)
        out = pd.DataFrame({"time_h": table["time_h"]})
        for j, c in enumerate(components):
            out[ore_column(c)] = fracs[:, j]
        out["history_fit_residual_wt_pct"] = resid
        notes.append(f"mineralogy history mapped to ores {', '.join(components)} by NNLS: residual "
                     f"mean {resid.mean():.3g} wt%, max {resid.max():.3g} wt%")
        if all(c in table.columns for c in TEXTURE_COLUMNS):
            _texture_ratio(table, fracs, ores, out, notes)
        for c in table.columns:
            if c.startswith("recorded_"):
                out[c] = table[c]
        return out, notes
    for c in components:
        if ore_column(c) not in table.columns:
            table[ore_column(c)] = 0.0
    if history is not None and all(c in table.columns for c in TEXTURE_COLUMNS):  # ore fractions with a texture
        _texture_ratio(table, table[[ore_column(c) for c in components]].to_numpy(float),
                       ores if ores is not None else component_ores(scene), table, notes)
    return table, notes


def _texture_ratio(table: pd.DataFrame, fracs: np.ndarray, ores: dict, out: pd.DataFrame, notes: list) -> None:
    """The mix's textural index over the recorded one's at every sample (``out``'s
    ``history_textural_index_ratio``, which :func:`fit_warnings` judges) and its note."""
    ratio = texture_ratios(table, fracs, ores)
    out["history_textural_index_ratio"] = ratio
    notes.append(f"the recorded texture enters through the ores' own: the mix's textural index is "
                 f"{ratio.min():.3g}-{ratio.max():.3g}x the recorded")


def component_blend(feed: pd.DataFrame, components: list[str]) -> np.ndarray:
    """Blend fractions of the components at every sample (rows sum to 1)."""
    B = feed[[ore_column(c) for c in components]].to_numpy(float)
    B = np.clip(B, 0.0, None)
    return B / B.sum(axis=1, keepdims=True)


def input_series(scene: Scene, feed: pd.DataFrame, replay: bool) -> tuple[np.ndarray, np.ndarray]:
    """Feed rate [t/h] and speed at every sample: the scene's, or in a replay the recorded ones."""
    n = len(feed)
    f = np.full(n, float(scene.feed.feed_tph))
    s = np.full(n, float(scene.feed.speed_frac_critical))
    if replay:
        if "recorded_feed_tph" in feed:
            f = feed["recorded_feed_tph"].to_numpy(float)
        if "recorded_speed_frac_critical" in feed:
            s = feed["recorded_speed_frac_critical"].to_numpy(float)
    return f, s


def initial_blend(scene: Scene, components: list[str]) -> np.ndarray:
    """The scene's blend at t = 0 as component fractions."""
    feed, _ = feed_schedule(scene, components, np.array([0.0]))
    return component_blend(feed, components)[0]
