"""What the feed is at any time of a scene: blend fractions, or a recorded mineralogy.

A runner asks either
- :func:`blend_at(scene, t_h) <blend_at>`: ore name -> fraction at one time (every ore of the
  scene, zeros included); for schedules and for histories of ore fractions; or
- :func:`feed_table(scene, times_h) <feed_table>`: a DataFrame indexed by ``time_h`` on the
  scene's grid (or the given times), the form to use for previews (``t + preview_lead_h``)
  and for mineralogy histories.

Schedule semantics: before the first event the feed is ``feed.blend``. A ``step`` event sets
its blend at ``at_h``. A ``ramp`` moves linearly from the blend in force at ``at_h`` to its
blend, reached at ``at_h + ramp_h``. Histories are held sample to sample (previous value on
the history's grid); after the last record the last value holds.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from scenarios.errors import SceneError
from scenarios.scene.history import RECORDED_COLUMNS, TEXTURE_COLUMNS, History, read_history_once
from scenarios.scene.ranges import nominal_feed_tph
from scenarios.scene.schema import Scene
from twin import Mineralogy, Texture, reference_ores


def ore_column(ore: str) -> str:
    """Column name of an ore's fraction in feed tables and histories: ``ore_<name>_frac``."""
    return f"ore_{ore}_frac"


def ore_mineralogies(scene: Scene) -> dict:
    """Each ore of the scene as a ``twin.Mineralogy`` (reference types from ``twin.reference_ores``)."""
    out = {}
    for name, ore in scene.ores.items():
        if ore.type is not None:
            ref = reference_ores()[ore.type]
            out[name] = Mineralogy(dict(ref.wt_pct), ref.texture, name=name)
        else:
            out[name] = Mineralogy(dict(ore.mineralogy), Texture(**ore.texture.model_dump()),
                                   name=name)
    return out


def load_history(scene: Scene) -> History | None:
    """The scene's recorded history on its sample grid (cached per file), or ``None``; read with the ranges the
    scene's check reads it with (its mill's nominal feed, its feed P80): a file rewritten after the check (a feed in
    kg/h) was read without them, and run."""
    path = scene.history_path()
    if path is None:
        return None
    feed_p80_um = None if scene.feed.psd is not None or scene.feed.psd_csv is not None else scene.feed.p80_um
    return read_history_once(path, scene.scene.sample_period_h, max_gap_h=scene.feed.history_max_gap_h,
                             feed_nominal_tph=nominal_feed_tph(scene.mill_spec(), scene.mill.model_dump()),
                             feed_p80_um=feed_p80_um)


#: A schedule event at ``at_h`` has taken effect at times from ``at_h`` less this [h]: a grid time k dt
#: is computed to a rounding (111 / 60 h is 1.8499999999999999), and a step at 1.85 h took effect a
#: sample late, while the open loop marked its jump at 1.85 (the plant ramped over the sample between).
EVENT_TIME_TOL_H = 1e-9


def event_started(t_h: float, at_h: float) -> bool:
    """Whether an event at ``at_h`` [h] has taken effect at ``t_h`` (:data:`EVENT_TIME_TOL_H`)."""
    return t_h >= at_h - EVENT_TIME_TOL_H


def blend_at(scene: Scene, t_h: float) -> dict[str, float]:
    """Blend (every ore of the scene -> fraction) at time ``t_h``."""
    history = load_history(scene)
    if history is not None:
        if history.kind != "blend":
            raise SceneError(f"{scene.history_path()}: the history records mineralogy, not ore "
                             "fractions; use feed_table(scene)")
        row = _rows_at(history, np.array([float(t_h)])).iloc[0]
        return {ore: float(row.get(ore_column(ore), 0.0)) for ore in scene.ores}
    blend = {ore: scene.feed.blend.get(ore, 0.0) for ore in scene.ores}
    for ev in scene.feed.schedule:
        if not event_started(t_h, ev.at_h):
            break
        target = {ore: ev.blend.get(ore, 0.0) for ore in scene.ores}
        if ev.kind == "step" or event_started(t_h, ev.at_h + ev.ramp_h):
            blend = target
        else:
            w = max(0.0, (t_h - ev.at_h) / ev.ramp_h)
            blend = {ore: (1 - w) * blend[ore] + w * target[ore] for ore in scene.ores}
    return blend


def feed_table(scene: Scene, times_h=None) -> pd.DataFrame:
    """Feed over time, indexed by ``time_h`` (default: the scene's grid).

    Columns: ``ore_<name>_frac`` for schedules and ore-fraction histories; for mineralogy
    histories ``<mineral>_wt_pct`` plus the texture (``mean_grain_um``, ``uniformity``,
    ``association_entropy``); for any history the recorded plant values prefixed
    ``recorded_`` (``recorded_feed_tph``, ...) when the file has them.
    """
    times = scene.time_grid_h() if times_h is None else np.asarray(times_h, dtype=float)
    index = pd.Index(times, name="time_h")
    history = load_history(scene)
    if history is None:
        rows = [blend_at(scene, t) for t in times]
        return pd.DataFrame({ore_column(o): [r[o] for r in rows] for o in scene.ores}, index=index)
    table = _rows_at(history, times).set_index(index)
    if history.kind == "mineralogy" and scene.feed.history_texture is not None:
        for key in TEXTURE_COLUMNS:
            table[key] = getattr(scene.feed.history_texture, key)
    return table.rename(columns={c: f"recorded_{c}" for c in RECORDED_COLUMNS})


def _rows_at(history: History, times: np.ndarray) -> pd.DataFrame:
    grid = history.frame.index.to_numpy()
    j = np.clip(np.searchsorted(grid, times + 1e-9, side="right") - 1, 0, len(grid) - 1)
    return history.frame.iloc[j].reset_index(drop=True)
