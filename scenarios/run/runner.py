"""Turn a scene into a run: build the twin(s) once, drive the feed, compute the KPIs.

    >>> from scenarios import run_scene
    >>> result = run_scene("scenarios/pyrite_surge.toml", out_dir="runs/pyrite")  # doctest: +SKIP
    >>> result.kpis["specific_energy_kwh_t"]                                    # doctest: +SKIP

Units as everywhere in grindtwin: t, h, um, kW, fraction of critical speed.

What a run does
- **Models.** The controller's model is the twin built from the scene (its effects, size
  classes, mill, ores). When ``[plant]`` differs, a second twin is the simulated plant; else
  the plant is the same model. Open loop only the plant is integrated.
- **Components.** The scene's ores. A history of mineral wt% (``feed.history``) is mapped to
  ore fractions (see :func:`scenarios.run.feed.mineralogy_to_blend`); a scene with such a history and no
  ``[ores]`` uses the reference types A-D as its components.
- **Start.** A continuous mill (``transport`` effect) starts at the steady state of the initial
  feed rate, speed and blend (so that a run shows the schedule, not a start-up transient); if
  that steady state cannot be found the mill starts at its nominal hold-up filled with feed.
  A batch mill (no ``transport``) starts with ``feed.batch_charge_kg`` of feed of the initial
  blend and grinds it for ``scene.duration_h`` with no feed.
- **Inputs.** Open loop, a schedule is linear between samples (a ramp is the ramp, a step
  event a step at its sample) and a history is held sample to sample; closed loop, the
  controller's input is held over each sample period. Controller ``"none"``: the scene's ``feed_tph``
  and ``speed_frac_critical`` throughout (in a replay, the recorded ones where recorded).
  ``"pi"`` and ``"nmpc"`` need the ``mpc`` package's modules (see :mod:`scenarios.run.closed_loop`).
- **Analyser.** Open loop, ``p80_analyser_um`` is what the scene's P80 analyser would report
  (:func:`scenarios.run.open_loop.analyser_trace`); the KPIs use
  the plant's ``p80_um``.
- **Progress.** The run is integrated in stretches of ``PROGRESS_CHUNK_STEPS`` samples with a
  tqdm bar; the integrator restarts at each stretch and where an input jumps or bends.
- **Refusals first.** What the run would refuse is refused before it starts
  (:mod:`scenarios.run.preflight`: the controller's settings, then, once the models are built,
  a controller too large to build); the output folder is claimed before any work
  (:mod:`scenarios.output.write`).

KPIs: :mod:`scenarios.run.kpis`.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from scenarios.errors import SceneError
from scenarios.output import claim_output, workbook_problem, write_files
from scenarios.run.batch import run_batch
from scenarios.run.closed_loop import run_closed
from scenarios.run.feed import fed_file_changes, feed_schedule, fit_warnings, history_changes, history_file_changes
from scenarios.run.kpis import compute_kpis, feed_stopped
from scenarios.run.models import build_models, component_ores, feed_psd_file, is_batch
from scenarios.run.open_loop import analyser_trace, run_open_loop
from scenarios.run.preflight import model_size_problems, refuse, replay_speed_problems, settings_problems
from scenarios.run.summary import make_summary, preset_file_changes
from scenarios.scene import TEXTURE_COLUMNS, Scene, load_history, load_scene, read_history_once, scene_from_dict
from scenarios.scene.history import DEFAULT_MAX_GAP_H
from scenarios.scene.ranges import NO_PRODUCT_FRAC
from scenarios.scene.loader import read_toml
from twin import nominal_pressure_kpa, trajectory_notes


@dataclass
class RunResult:
    """One run: ``frame`` (one row per sample, unit-suffixed columns), ``summary`` (JSON-able:
    scene, kpis, model description, effects, versions, seed, notes), ``psd`` (product size
    distribution snapshots, the mill content's for a batch grind: rows = times, columns = class
    upper sizes in um, values = cumulative fraction passing), ``mill_psd`` (the same of the mill
    content of a continuous mill), ``streams`` (size-by-size tables of every stream at the
    "start" and "end" of the run, :func:`scenarios.run.streams.size_by_size`), ``scene`` (the
    validated scene) and ``out_dir`` (where it was written, or ``None``)."""

    frame: pd.DataFrame
    summary: dict
    out_dir: Path | None = None
    psd: pd.DataFrame | None = None
    mill_psd: pd.DataFrame | None = None
    streams: dict = field(default_factory=dict)
    scene: Scene | None = None

    @property
    def kpis(self) -> dict:
        return self.summary["kpis"]


def _as_scene(scene_or_path) -> Scene:
    return scene_or_path if isinstance(scene_or_path, Scene) else load_scene(scene_or_path)


def run_scene(scene_or_path, out_dir=None, progress: bool = True, *, csv: bool = False,
              plots: bool = True, xlsx: bool = False, replay: bool = False) -> RunResult:
    """Run a scene (a ``Scene`` or a path) and, with ``out_dir``, write its outputs there.

    ``xlsx=True`` adds the workbook ``run.xlsx`` (:mod:`scenarios.output.workbook`).
    ``replay=True`` drives the inputs with the recorded feed rate and speed of the history (open
    loop) where the history records them. Raises SceneError for a scene the twin refuses (or an
    ``out_dir`` that cannot be used: checked before any work, see :mod:`scenarios.output.write`)
    and RunError when the run fails. See the module docstring for what a run does and the KPIs.
    """
    scene = _as_scene(scene_or_path)
    refuse(scene, settings_problems(scene))
    _check_workbook(scene, xlsx)
    with claim_output(out_dir, protect=_scene_files(scene)) as claim:
        result = _run(scene, progress, replay)
        _commit(claim, result, csv, plots, xlsx)
    return result


def _check_workbook(scene: Scene, xlsx: bool) -> None:
    """Refuse ``xlsx`` for a run whose time series no workbook sheet holds, before the run: the
    workbook is written last, and its failure lost every file of a finished run."""
    problem = workbook_problem(len(scene.time_grid_h())) if xlsx else None
    if problem:
        raise SceneError(f"{scene.source_path or 'scene'}: {problem}")


def _scene_files(scene: Scene) -> tuple:
    """The user's files a run reads: their folders are never an output folder."""
    psd = scene.resolve_path(scene.feed.psd_csv) if scene.feed.psd_csv is not None else None
    return tuple(p for p in (scene.source_path, scene.history_path(), psd) if p is not None)


def _commit(claim, result: RunResult, csv: bool, plots: bool, xlsx: bool) -> None:
    if claim is not None:
        result.out_dir = claim.commit(lambda folder: write_files(result, folder, csv, plots, xlsx))
        for note in claim.notes:
            warnings.warn(note, stacklevel=3)


def _run(scene: Scene, progress: bool, replay: bool) -> RunResult:
    t_start = time.perf_counter()
    models = build_models(scene)
    psd_file = feed_psd_file(scene)  # the screen analysis the twins were fed (cached): its hash is recorded
    refuse(scene, model_size_problems(scene, models))
    times = scene.time_grid_h()
    ores = component_ores(scene)
    history = load_history(scene)  # what the run is fed (feed_schedule's, cached): its changes and hash are said
    feed, notes = feed_schedule(scene, models.components, times, ores)
    read_changes = history_changes(history)  # of the bytes read now, not of a file replaced during the run
    if replay:
        refuse(scene, replay_speed_problems(scene, models, feed))
    notes = models.notes + notes
    recorded = [c[len("recorded_"):] for c in feed.columns if c in ("recorded_feed_tph", "recorded_speed_frac_critical")]
    if recorded and not replay:  # they sat in the history, unused, and nothing said so
        notes.append(f"the history records {' and '.join(recorded)}; run uses the scene's inputs (grindtwin replay "
                     "drives the recorded ones)")
    if is_batch(scene):
        frame, sizes, extra = run_batch(scene, models, feed, progress)
    elif scene.controller.kind == "none":
        frame, sizes, extra = run_open_loop(scene, models, feed, progress, replay)
    else:
        frame, sizes, extra = run_closed(scene, models, feed, progress)
    psd = sizes["psd"]
    notes += extra.pop("notes", [])
    warnings_ = read_changes + fit_warnings(feed, models.components) + extra.pop("warnings", [])
    health = extra.get("controller_health")
    for c in feed.columns:
        if c.startswith("recorded_") or c in ("history_fit_residual_wt_pct", "history_textural_index_ratio"):
            frame[c] = feed[c].to_numpy()
    kpis = compute_kpis(scene, frame, **extra)
    if not kpis["fed_t"] > 0 and not is_batch(scene):
        warnings_.append("specific energy is undefined: nothing was fed")
    if kpis["p80_kpis_exclude_h"] > 0:  # naming the P80 KPIs the run defines (no target: the mean alone)
        named = [w for k, w in (("p80_iae_um_h", "IAE"), ("p80_within_10um_frac", "share within the band"),
                                ("p80_mean_um", "mean")) if math.isfinite(kpis[k])]
        warnings_.append(f"the P80 KPIs ({', '.join(named)}) leave out {kpis['p80_kpis_exclude_h']:.3g} h "
                         f"of a feed stop (product or feed below {NO_PRODUCT_FRAC:.0%} of the nominal feed: the P80 is "
                         "then the charge draining and grinding down)")
    warnings_ += trajectory_notes(frame, models.plant.spec, models.plant.model.effect_names,
                                  product_psd=None if is_batch(scene) else psd,
                                  nominal_pressure_kpa=nominal_pressure_kpa(models.plant.model))
    warnings_ += preset_file_changes(scene) + history_file_changes(history)
    if psd_file is not None:
        warnings_ += fed_file_changes("screen analysis (feed.psd_csv)", psd_file["path"], psd_file["sha256"])
    summary = make_summary(scene, models, kpis, notes + warnings_, time.perf_counter() - t_start)
    summary["controller_health"] = health
    summary["warnings"] = warnings_
    if history is not None:  # the bytes the run was fed: a path alone names whatever the file holds later
        summary["history_file"] = {"path": str(history.source.resolve()), "sha256": history.sha256}
    if psd_file is not None:
        summary["psd_file"] = psd_file
    if psd is not None:
        summary["final_psd"] = {"what": psd.attrs.get("what", "product"), "time_h": float(psd.index[-1]),
                                "size_um": [float(x) for x in psd.columns],
                                "passing_frac": [float(v) for v in psd.iloc[-1]]}
    return RunResult(frame=frame, summary=summary, psd=psd, mill_psd=sizes["mill_psd"], streams=sizes["streams"],
                     scene=scene)


def replay_scene(scene_or_path, history_csv, out_dir=None, progress: bool = True, *,
                 duration_h: float | None = None, csv: bool = False, plots: bool = True,
                 xlsx: bool = False) -> RunResult:
    """Drive a scene with a recorded history (CSV or Parquet; format in :mod:`scenarios.scene.history`).

    The scene's ``feed.history`` is set to ``history_csv`` (its ``feed.blend`` and schedule are
    dropped) and the scene validated again, so the file is checked by the same rules; a scene
    given as a path is validated only so (:func:`replay_input_scene`: its own history unread).
    ``duration_h`` defaults to the history's span (the whole recording, on the scene's sample
    grid). Open loop (controller ``"none"``) the inputs are the recorded feed rate and speed
    where recorded; with a controller the controller chooses them. Either way the recorded
    columns (``recorded_feed_tph``, ``recorded_speed_frac_critical``, ``recorded_p80_um``) sit
    beside the run's own in the frame, and the summary's ``replay`` block compares them
    (mean and mean absolute differences, run minus recorded; the P80 as the scene's analyser reads the
    run's without its noise, :data:`P80_AS_RECORDED`, as the recorded P80 is an analyser's).
    """
    scene = scene_or_path if isinstance(scene_or_path, Scene) else replay_input_scene(scene_or_path, history_csv,
                                                                                        duration_h)
    refuse(scene, settings_problems(scene))
    history_path = Path(history_csv).resolve()
    with claim_output(out_dir, protect=(*_scene_files(scene), history_path)) as claim:
        result = _replay(scene, history_path, progress, duration_h, xlsx)
        _commit(claim, result, csv, plots, xlsx)
    return result


def replay_input_scene(scene_path, history_csv, duration_h: float | None = None) -> Scene:
    """The scene file ``scene_path`` with the history ``history_csv`` as its feed, validated once: the
    scene's own ``feed.history`` (and its ``history_texture``, when the new history has texture
    columns), ``blend`` and ``schedule`` are replaced unread, and it lasts ``duration_h``
    (``--duration-h``, checked as such) or the history's span. Checking the scene as written first
    refused a replay for its own history (missing, or one needing a texture the new one has)."""
    data = read_toml(scene_path)
    feed = data.get("feed")
    if not isinstance(feed, dict) or not isinstance(data.get("scene"), dict):
        return scene_from_dict(data, scene_path)  # the tables' own messages
    dt = data["scene"].get("sample_period_h")
    gap = feed.get("history_max_gap_h")
    number = isinstance(gap, (int, float)) and not isinstance(gap, bool)
    _with_history(data, Path(history_csv).resolve(), dt if isinstance(dt, (int, float)) and dt > 0 else None,
                  float(gap) if number and gap > 0 else DEFAULT_MAX_GAP_H, duration_h)
    return scene_from_dict(data, scene_path)


def _with_history(data: dict, history_path: Path, dt: float | None, max_gap_h: float,
                  duration_h: float | None) -> None:
    """A scene table (``data``, in place) fed by the history: its ``blend``, ``schedule`` and own
    ``history`` dropped, its ``history_texture`` too when the history has texture columns, and its
    duration :func:`_replay_duration_h` (unless its sample period ``dt`` is not known yet: the
    scene's validation then names it)."""
    feed = data["feed"]
    for key in ("blend", "schedule", "history"):
        feed.pop(key, None)
    if dt is not None:
        history = read_history_once(history_path, float(dt), max_gap_h=max_gap_h)
        if all(c in history.frame.columns for c in TEXTURE_COLUMNS):
            feed.pop("history_texture", None)
        data["scene"]["duration_h"] = _replay_duration_h(history, float(dt), duration_h)
    feed["history"] = str(history_path)


def _replay_duration_h(history, dt: float, duration_h: float | None) -> float:
    """The replay's length [h]: ``duration_h`` (a whole number of sample periods within the history's
    span, else a SceneError naming --duration-h) or the whole span on the sample grid."""
    span = history.span_h
    if duration_h is None:
        n = int(np.floor(span / dt + 1e-9))
        if n < 1:
            raise SceneError(f"{history.source}: the history spans {span:g} h, less than one sample "
                             f"period ({dt:g} h) of the scene")
        return n * dt
    if not duration_h > 0:  # a whole number of periods, -1 of them, was the reason given
        raise SceneError(f"duration_h (--duration-h) {duration_h:g}: must be > 0 h, a whole number of the scene's "
                         f"sample periods ({dt:g} h)")
    n = round(duration_h / dt)
    if n < 1 or abs(n * dt - duration_h) > 1e-9 * max(1.0, duration_h):
        raise SceneError(f"duration_h (--duration-h) {duration_h:g}: must be a whole number of the scene's sample "
                         f"periods ({dt:g} h)")
    if span + dt < duration_h - 1e-9:
        raise SceneError(f"duration_h (--duration-h) {duration_h:g}: the history {history.source} covers {span:g} h; "
                         f"allowed: up to {span + dt:g} h")
    return float(duration_h)


def _written_duration_h(scene: Scene):
    """The scene's ``duration_h`` as its file says (a replay's scene already lasts the history's span)."""
    src = scene.source_path
    if src is None or not Path(src).is_file():
        return scene.scene.duration_h
    return read_toml(src).get("scene", {}).get("duration_h")


#: A replay's column of the run's P80 as the scene's analyser reads it without its noise (dead time, sample
#: period): what a recorded P80, an analyser's reading, is compared with.
P80_AS_RECORDED = "p80_as_recorded_um"


def _as_read(scene: Scene, frame, values) -> np.ndarray:
    """``values`` (one per sample of ``frame``) as the scene's P80 analyser reads them without its noise."""
    return analyser_trace(frame["time_h"].to_numpy(), np.asarray(values, float),
                          scene.sensors.model_copy(update={"p80_noise_um": 0.0}), 0)


def _replay(scene: Scene, history_path: Path, progress: bool, duration_h: float | None,
            xlsx: bool = False) -> RunResult:
    data = scene.model_dump(exclude_none=True)
    _with_history(data, history_path, scene.scene.sample_period_h, scene.feed.history_max_gap_h, duration_h)
    src = scene.source_path
    new = scene_from_dict(data, src if src is not None else Path.cwd() / "scene.toml")
    _check_workbook(new, xlsx)  # the replay's length is known only now
    # read before the run, not after it: the history the run reads (_run's, cached: its clock and hash, not those of
    # a file rewritten meanwhile) and the scene file's duration_h (a file being edited when the run ended lost the
    # run, exit 2, or named the edited duration)
    history = load_history(new)
    scene_h = _written_duration_h(scene) if duration_h is None else None
    result = _run(new, progress, replay=True)
    frame = result.frame
    if "recorded_p80_um" in frame:
        frame[P80_AS_RECORDED] = _as_read(new, frame, frame["p80_um"])
    cmp = {}
    for col, run in (("feed_tph", "feed_tph"), ("speed_frac_critical", "speed_frac_critical"),
                     ("p80_um", P80_AS_RECORDED)):
        rec = f"recorded_{col}"
        if rec in frame:
            diff = frame[run].to_numpy(float) - frame[rec].to_numpy(float)
            if col == "p80_um":  # readings of a feed stop's draining charge, left out as of the KPIs
                diff[_as_read(new, frame, feed_stopped(new, frame)) > 0] = np.nan
            cmp[f"{col}_mean_diff"] = float(np.nanmean(diff))
            cmp[f"{col}_mean_abs_diff"] = float(np.nanmean(np.abs(diff)))
    start = history.start  # the plant's clock at time_h 0 (None for a time_h history)
    result.summary["replay"] = {"history": str(history_path), "run_minus_recorded": cmp,
                                "history_start": None if start is None else start.isoformat()}
    replayed = new.scene.duration_h
    if isinstance(scene_h, (int, float)) and not math.isclose(replayed, scene_h, rel_tol=1e-9):
        result.summary["notes"].append(
            f"replayed {replayed:g} h, the history's span on the {new.scene.sample_period_h:g} h sample grid, not the "
            f"scene's duration_h {scene_h:g} h (--duration-h sets the replay's length)")
    return result
