"""Batch grinds: a scene without ``transport`` grinds one charge."""

from __future__ import annotations

import numpy as np
import pandas as pd

from mpc import cumulative
from scenarios.run.feed import component_blend
from scenarios.run.open_loop import simulate_chunks
from scenarios.run.streams import Samples, run_size_data
from scenarios.scene import Scene


def run_batch(scene: Scene, models, feed: pd.DataFrame, progress: bool):
    """A batch grind: ``feed.batch_charge_kg`` of the initial blend ground for the scene's
    duration with no feed; returns ``(frame, size data of the mill content, extra)``."""
    twin = models.plant
    blend = component_blend(feed, models.components)
    charge_t = float(scene.feed.batch_charge_kg) / 1000.0
    x0 = twin.model.initial_state(list(blend[0]), holdup_t=charge_t)
    n = len(blend)
    f = np.zeros(n)
    s = np.full(n, float(scene.feed.speed_frac_critical))
    frame, states = simulate_chunks(scene, twin, x0, f, s, blend, progress)
    energy = cumulative(frame["time_h"], frame["power_kw"])
    frame["specific_energy_kwh_t"] = energy / charge_t  # the twin's power/feed is undefined at zero feed
    sizes = run_size_data(twin.model, Samples.from_frame(twin.model, states, frame, models.components), batch=True)
    notes = [f"batch grind of {charge_t * 1000:g} kg; specific energy = cumulative energy / charge; "
             "size distributions are of the mill content"]
    return frame, sizes, {"notes": notes, "solve_times_s": None, "batch_charge_t": charge_t}
