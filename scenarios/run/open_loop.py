"""Open-loop runs: the plant twin integrated under inputs known in advance (the scene's, or
a history's recorded ones), read by the scene's analyser."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from mpc import Sensors, SensorState
from scenarios.errors import RunError
from scenarios.run.closed_loop import start_feed_tph, start_mode
from scenarios.run.feed import component_blend, input_series
from scenarios.run.streams import Samples, run_size_data
from scenarios.scene import Scene, event_started
from twin import TwinError

#: Samples integrated per call (one progress-bar tick; the integrator restarts between calls).
PROGRESS_CHUNK_STEPS = 120
#: Sample times are snapped to the sample they are within this fraction of (floating-point
#: round-off of k * dt / dt).
SAMPLE_SNAP = 1e-12


def start_state(scene: Scene, twin, u0, blend0, notes: list[str], warnings: list[str]):
    """The steady state of the initial inputs (so that a run shows the schedule, not a start-up
    transient), else the nominal hold-up filled with feed; the note says which, a warning the latter
    (it was a note only: a circuit running away from its scene's own feed showed start_p80_um as if
    at steady state)."""
    try:
        ss = twin.steady(feed_tph=float(u0[0]), speed_frac_critical=float(u0[1]), blend=list(blend0))
        notes.append(f"started at the steady state of the initial inputs (P80 {ss.p80_um:.4g} um)")
        return ss.x
    except (TwinError, RuntimeError) as exc:
        warnings.append(f"no steady state at the initial inputs (feed {float(u0[0]):g} t/h, speed "
                        f"{float(u0[1]):g}): started from the mill filled to its nominal hold-up with feed, so "
                        f"start_p80_um is that fill's, not a steady state's ({exc})")
        return twin.model.initial_state(list(blend0))


def step_samples(scene: Scene, n_samples: int) -> np.ndarray:
    """Where the inputs may jump: at the samples where a ``step`` event of the schedule takes
    effect (its first sample at or after ``at_h``); between the others a schedule is linear
    (ramps are ramps). A recorded history is held sample to sample (its rule,
    :mod:`scenarios.scene.schedule`), so every one of its samples may jump."""
    if scene.feed.history is not None:
        return np.ones(n_samples, bool)
    jumps = np.zeros(n_samples, bool)
    times = scene.time_grid_h()[:n_samples]
    for ev in scene.feed.schedule:
        started = event_started(times, ev.at_h)  # the first sample at which blend_at has it
        k = int(np.argmax(started)) if started.any() else n_samples
        if ev.kind == "step" and 0 < k < n_samples:
            jumps[k] = True
    return jumps


def sampled_input(values: np.ndarray, jumps: np.ndarray, dt: float, offset_h: float = 0.0):
    """A function of time [h] (from ``offset_h``) through the sample values: linear between
    samples, except before a sample in ``jumps``, where the previous value is held up to it."""
    values = np.asarray(values, float)
    last = len(values) - 1

    def fn(t_h: float):
        x = (t_h + offset_h) / dt
        k = min(max(int(np.floor(x + SAMPLE_SNAP)), 0), last)
        if k == last:
            return values[last]
        w = x - k
        return values[k] if jumps[k + 1] else values[k] + w * (values[k + 1] - values[k])
    return fn


def simulate_chunks(scene: Scene, twin, x0, feed_tph, speed, blend, progress: bool, jumps=None):
    """Integrate over the grid in stretches of ``PROGRESS_CHUNK_STEPS`` samples (the inputs
    linear between samples, stepping at ``jumps``: :func:`step_samples`); returns (frame,
    states) with cumulative fed/produced."""
    dt = scene.scene.sample_period_h
    n = len(feed_tph) - 1
    jumps = np.zeros(n + 1, bool) if jumps is None else jumps
    frames, states = [], [np.asarray(x0, float)[None, :]]
    fed0 = prod0 = 0.0
    x = x0
    with tqdm(total=n, desc=scene.scene.name, unit="sample", disable=not progress) as bar:
        for a in range(0, n, PROGRESS_CHUNK_STEPS):
            b = min(a + PROGRESS_CHUNK_STEPS, n)
            try:
                tr = twin.simulate((b - a) * dt, dt, feed_tph=sampled_input(feed_tph, jumps, dt, a * dt),
                                   speed_frac_critical=sampled_input(speed, jumps, dt, a * dt),
                                   blend=sampled_input(blend, jumps, dt, a * dt), x0=x)
            except TwinError as exc:
                raise RunError(f"scene {scene.scene.name}: the plant integration failed between "
                               f"t = {a * dt:.4g} h and {b * dt:.4g} h: {exc}") from None
            fr = tr.frame.copy()
            fr["time_h"] = fr["time_h"] + a * dt
            fr["fed_t"] = fr["fed_t"] + fed0
            fr["produced_t"] = fr["produced_t"] + prod0
            fed0, prod0 = float(fr["fed_t"].iloc[-1]), float(fr["produced_t"].iloc[-1])
            frames.append(fr if a == 0 else fr.iloc[1:])
            states.append(tr.states[1:])
            x = tr.states[-1]
            bar.update(b - a)
    frame = pd.concat(frames, ignore_index=True)
    frame["time_h"] = np.arange(len(frame)) * dt  # exact grid, no drift
    return frame, np.vstack(states)


def run_open_loop(scene: Scene, models, feed: pd.DataFrame, progress: bool, replay: bool):
    """The plant under the scene's (or, in a replay, the recorded) inputs; returns
    ``(frame, size data of scenarios.run.streams.run_size_data, extra)``."""
    notes: list[str] = []
    twin = models.plant
    blend = component_blend(feed, models.components)
    f, s = input_series(scene, feed, replay)
    if replay and "recorded_feed_tph" in feed:
        notes.append("replay: inputs are the recorded feed rate and speed")
    elif start_mode(scene) == "target":  # feed.start = "target": hold the feed rate of the target
        f = np.full_like(f, start_feed_tph(scene, models, blend[0]))
        notes.append(f"feed.start = \"target\": the feed rate holding the target P80 "
                     f"{scene.controller.target_p80_um:g} um at the initial blend, {f[0]:.4g} t/h, held")
    warnings: list[str] = []
    x0 = start_state(scene, twin, (f[0], s[0]), blend[0], notes, warnings)
    frame, states = simulate_chunks(scene, twin, x0, f, s, blend, progress, step_samples(scene, len(f)))
    frame["p80_analyser_um"] = analyser_trace(frame["time_h"].to_numpy(), frame["p80_um"].to_numpy(),
                                              scene.sensors, scene.scene.seed)
    sizes = run_size_data(twin.model, Samples.from_frame(twin.model, states, frame, models.components), batch=False)
    return frame, sizes, {"notes": notes, "warnings": warnings, "solve_times_s": None}


def analyser_trace(time_h: np.ndarray, p80_um: np.ndarray, sensors, seed: int) -> np.ndarray:
    """What the scene's P80 analyser reports along a trace, read through the one analyser model
    (:class:`mpc.SensorState`: sampled every ``p80_sample_period_h``, reported
    ``p80_dead_time_h`` later and held, with noise; seeded by ``seed``). NaN before the first
    report."""
    s = Sensors(p80_noise_um=sensors.p80_noise_um, p80_dead_time_h=sensors.p80_dead_time_h,
                p80_sample_period_h=sensors.p80_sample_period_h, power_noise_kw=0.0, load_noise_frac=0.0)
    state = SensorState(s, np.random.default_rng(seed))
    return np.array([state.make_step(float(t), float(p), math.nan, math.nan)[1] for t, p in zip(time_h, p80_um)])
