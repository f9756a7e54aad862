"""A scene's closed loop: the plant twin, the scene's sensors, and the NMPC (with an EKF) or
the PI baseline, wired as the reference-case benchmark wires them."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.linalg

from mpc import (EKF_RK4_SUBSTEPS, FEED_RANGE_NOMINAL, MEASUREMENTS, RK4_RATE_SAFETY, Controller, Ekf, LoopSettings,
                 MpcInputError, MpcSolverError, NmpcSettings, Sensors, TwinPlant, check_out_dir, export_controller,
                 feed_for_target, pi_baseline, run_closed_loop, stable_rk4_substeps, state_jacobian)
from scenarios.errors import RunError, SceneError
from scenarios.run.feed import component_blend
from scenarios.run.streams import Samples, run_size_data
from scenarios.scene import Scene
from scenarios.scene.ranges import scene_nominal_feed_tph
from twin import EFFECTS, SolverError, file_sha256

#: Scalar outputs of the plant's model recorded beside the loop's columns when the model has
#: them (the hydrocyclone's cut size and circulating load).
EXTRA_OUTPUTS = ("cyclone_d50c_um", "circulating_load_frac")


class RecordingPlant(TwinPlant):
    """The plant twin, keeping the (x, u, d) of every measurement (the loop measures once a
    sample, after the estimator's warm-up has measured its own) and adding
    :data:`EXTRA_OUTPUTS` to the measured values."""

    def __init__(self, model):
        super().__init__(model)
        self.seen: list[tuple] = []
        self._extra = {k: model.outputs[k] for k in EXTRA_OUTPUTS if k in model.outputs}

    def measure(self, x, u, d) -> dict:
        self.seen.append((np.array(x, float), np.array(u, float), np.array(d, float)))
        return super().measure(x, u, d) | {k: float(fn(x, u, d)) for k, fn in self._extra.items()}

    def samples(self, time_h: np.ndarray) -> Samples:
        """The last ``len(time_h)`` measurements: the loop's samples."""
        x, u, d = (np.array(a) for a in zip(*self.seen[-len(time_h):]))
        return Samples(np.asarray(time_h, float), x, u, d)


def feed_bounds(scene: Scene) -> tuple[float, float]:
    """Feed-rate bounds: the scene's, else half and one and a half times its feed rate."""
    b = scene.controller.bounds
    f = float(scene.feed.feed_tph)
    return (b.feed_tph_min if b.feed_tph_min is not None else 0.5 * f,
            b.feed_tph_max if b.feed_tph_max is not None else 1.5 * f)


def nmpc_settings(scene: Scene):
    """``mpc.nmpc.NmpcSettings`` from ``[controller]``: names map one to one (weights prefixed
    ``weight_``); unset feed bounds are 0.5x and 1.5x ``feed.feed_tph``; unset rate limits
    and power limit are infinite; ``dt_h`` is the scene's sample period."""
    c = scene.controller
    lo, hi = feed_bounds(scene)
    return NmpcSettings(
        target_p80_um=float(c.target_p80_um), horizon_steps=c.horizon_steps,
        dt_h=scene.scene.sample_period_h, move_block=c.move_block, rk4_substeps=c.rk4_substeps,
        weight_p80=c.weights.p80, weight_du_feed=c.weights.du_feed,
        weight_du_speed=c.weights.du_speed, weight_energy=c.weights.energy,
        feed_tph_min=lo, feed_tph_max=hi, speed_min=c.bounds.speed_min, speed_max=c.bounds.speed_max,
        feed_rate_max_tph_per_h=(c.bounds.feed_rate_max_tph_per_h
                                 if c.bounds.feed_rate_max_tph_per_h is not None else math.inf),
        speed_rate_max_per_h=(c.bounds.speed_rate_max_per_h
                              if c.bounds.speed_rate_max_per_h is not None else math.inf),
        load_band_frac=tuple(c.load_band_frac),
        power_max_kw=c.power_max_kw if c.power_max_kw is not None else math.inf,
        solver=c.solver, qpsol=c.qpsol, preview=c.preview_lead_h > 0)


#: Bisections of the feed range for the top of the load band (:func:`band_top_steady`): the feed to
#: 1/4096 of the range (0.006 t/h on 20-45 t/h), the rates there to far less than RK4_RATE_SAFETY's margin.
BAND_TOP_BISECTIONS = 12


def band_top_steady(scene: Scene, twin, blend, feed_lo_tph: float):
    """The controller model's steady state at the scene's speed and ``blend`` with the highest feed in
    [``feed_lo_tph``, the controller's feed bound] whose load stays within the top of the load band (a
    feed with no steady state counts as past it: the mill fills); None when ``feed_lo_tph`` passes it."""
    hi = scene.controller.load_band_frac[1]
    speed = scene.feed.speed_frac_critical

    def within(feed):
        try:
            ss = twin.steady(feed_tph=feed, speed_frac_critical=speed, blend=blend)
        except SolverError:  # no steady state: the mill fills, past the band
            return None
        return ss if ss.outputs["load_frac"] <= hi else None

    lo, up = float(feed_lo_tph), feed_bounds(scene)[1]
    best = within(up)
    if best is not None or lo >= up:
        return best
    best = within(lo)
    for _ in range(BAND_TOP_BISECTIONS if best is not None else 0):
        mid = 0.5 * (lo + up)
        ss = within(mid)
        lo, up, best = (mid, up, ss) if ss is not None else (lo, mid, best)
    return best


#: A feed of more distinct blends than this (a recorded history) is represented by its extremes
#: (:func:`schedule_blends`): each band-top check solves about a dozen steady states.
MAX_CHECKED_BLENDS = 8


def schedule_blends(scene: Scene, models) -> list:
    """The distinct blends (component fractions) of the scene's feed over its run; of more than
    :data:`MAX_CHECKED_BLENDS`, the first and those richest and poorest in each component."""
    from scenarios.run.feed import feed_schedule
    from scenarios.run.models import component_ores

    feed, _ = feed_schedule(scene, models.components, scene.time_grid_h(), component_ores(scene))
    blends = np.round(component_blend(feed, models.components), 12)
    rows = np.unique(blends, axis=0)
    if len(rows) > MAX_CHECKED_BLENDS:
        pick = {0} | {int(f(blends[:, j])) for j in range(blends.shape[1]) for f in (np.argmax, np.argmin)}
        rows = np.unique(blends[sorted(pick)], axis=0)
    return list(rows)


def check_rk4_substeps(scene: Scene, twin, css, blends=()) -> None:
    """Refuse ``controller.rk4_substeps`` below the RK4 stability count of the controller's
    model (mpc.discretize.stable_rk4_substeps) at its initial steady state ``css`` and, for each of
    ``blends``, at the top of the load band (:func:`band_top_steady`, from the start's feed): the
    controller may take the plant anywhere in its band, and the model's fastest rate, the mill's
    through-flow over its hold-up, grows with the load, and in a closed circuit with the
    circulating load too (a reverse circuit's mill passes CL x feed)."""
    dt, n = scene.scene.sample_period_h, scene.controller.rk4_substeps
    points = [("at the initial steady state", css)]
    for b in blends:
        top = band_top_steady(scene, twin, b, float(css.u[0]))
        if top is not None:
            points.append((f"at the top of the load band (load {scene.controller.load_band_frac[1]:g}, feed "
                           f"{float(top.u[0]):.4g} t/h, blend {np.round(b, 3).tolist()})", top))
    for where, ss in points:
        try:
            need = stable_rk4_substeps(twin.model.f, ss.x, ss.u, ss.d, dt)
        except MpcInputError as exc:
            raise SceneError(f"the controller's model {where}: {exc} {fastest_state(twin.model, ss)}") from None
        if n < need:
            raise SceneError(f"controller.rk4_substeps = {n} is unstable for the controller's model {where}: RK4 "
                             f"needs at least {need} steps per {dt} h sample (rates x {RK4_RATE_SAFETY}); "
                             + fastest_state(twin.model, ss))


def fastest_state(model, ss) -> str:
    """Which of the model's states the fastest mode of df/dx at the steady state ``ss`` lives
    in, as a sentence naming its state group and effect: a short analyser dead time, not the
    mill, can be what an RK4 step count has to follow. The state of largest participation factor
    |w_i v_i| (left and right eigenvectors; Perez-Arriaga, Verghese & Schweppe 1982, IEEE Trans.
    PAS 101), which unlike the eigenvector alone does not depend on the states' units."""
    lam, left, right = scipy.linalg.eig(state_jacobian(model.f, ss.x, ss.u, ss.d), left=True, right=True)
    k = int(np.argmax(np.abs(lam)))
    i = int(np.argmax(np.abs(left[:, k].conj() * right[:, k])))
    start = 0
    for name, size in model.state_groups:
        if i < start + size:
            break
        start += size
    owner = "the mill's masses" if i < model.n_mass else f"{name} (effect {model.effect_of.get(name, '?')})"
    return f"its fastest rate, {abs(lam[k]):.3g} /h, is in {owner}"


def make_controller(scene: Scene, twin, codegen: str = "auto"):
    """The scene's NMPC on the controller's twin: ``mpc.nmpc.Controller`` with
    :func:`nmpc_settings` (the PI baseline is built by the closed loop itself)."""
    settings = nmpc_settings(scene)
    settings.codegen = codegen
    return Controller(twin.model, settings)


def start_mode(scene: Scene) -> str:
    """``feed.start`` with its default: "target" for a closed loop, "scene" for an open loop."""
    if scene.feed.start is not None:
        return scene.feed.start
    return "scene" if scene.controller.kind == "none" else "target"


def start_feed_bounds_tph(scene: Scene) -> tuple:
    """The feed range [t/h] searched for the target's steady state (feed.start = "target"):
    mpc.optimize's range around the nominal feed of the scene's mill (its preset's, scaled by its
    power: scenarios.scene.ranges), not the twin's, which a scene sets to its own feed_tph. A fixed
    5-60 t/h held no steady state of a laboratory mill."""
    nominal = float(scene_nominal_feed_tph(scene))
    return tuple(f * nominal for f in FEED_RANGE_NOMINAL)


def start_feed_tph(scene: Scene, models, blend0) -> float:
    """The run's initial feed rate (``feed.start``, :func:`start_mode`): the steady state holding
    the target P80 at the scene's speed and initial blend (:func:`mpc.optimize.feed_for_target`)
    for "target" (or a scene without a target's feed_tph), the scene's ``feed_tph`` for "scene"."""
    c = scene.controller
    if c.target_p80_um is None or start_mode(scene) == "scene":
        return float(scene.feed.feed_tph)
    lo, hi = start_feed_bounds_tph(scene)
    feed0 = feed_for_target(models.plant, blend0, c.target_p80_um, scene.feed.speed_frac_critical, (lo, hi))
    if not math.isfinite(feed0):
        raise SceneError(f"scene {scene.scene.name}: controller.target_p80_um = {c.target_p80_um:g} um cannot be "
                         f"the start: no feed rate in {lo:g}-{hi:g} t/h (0.2-2x the mill's nominal) holds it at "
                         f"feed.speed_frac_critical = {scene.feed.speed_frac_critical:g} with the initial blend; give "
                         "a target the plant reaches there, or feed.start = \"scene\" to start at feed.feed_tph")
    return float(feed0)


def make_estimator(scene: Scene, twin, css, codegen: str = "auto"):
    """The NMPC's EKF on the controller's twin, started at the steady state ``css``, with the
    scene's disturbance model. Its prediction takes the scene's ``controller.rk4_substeps`` (the
    count :func:`check_rk4_substeps` found stable for this model), or the EKF's default where that
    is more: it integrates the same model over the same sample as the NMPC, and with fewer steps
    than the stable count its prediction and covariance grow without bound (a reverse circuit at
    rk4_substeps = 4 diverged on the EKF's 3 once the load passed 0.88)."""
    c = scene.controller
    return Ekf(twin.model, scene.scene.sample_period_h, css.x, disturbance_model=c.disturbance_model,
               rk4_substeps=max(c.rk4_substeps, EKF_RK4_SUBSTEPS), codegen=codegen)


def scene_sensors(scene: Scene) -> Sensors:
    """``mpc.Sensors`` from the scene's ``[sensors]``."""
    return Sensors(**{k: v for k, v in scene.sensors.model_dump().items() if k in Sensors.__dataclass_fields__})


def hold_schedule(times_h, blend, dt_h: float):
    """``schedule(t)``: the blend of the sample at or before t (clamped at the ends)."""
    times_h = np.asarray(times_h, float)

    def schedule(t_h):
        k = min(max(int(np.searchsorted(times_h, t_h + 1e-9 * dt_h, side="right")) - 1, 0), len(times_h) - 1)
        return blend[k]
    return schedule


def plant_start(scene: Scene, models, blend0):
    """Where a closed loop starts: the plant's steady state at :func:`start_feed_tph`
    (``feed.start``), the scene's speed and ``blend0``; SceneError if no feed rate holds the target."""
    return models.plant.steady(feed_tph=start_feed_tph(scene, models, blend0),
                               speed_frac_critical=scene.feed.speed_frac_critical, blend=blend0)


#: The estimator runs this long on the steady plant before the loop closes (as on a plant that
#: was running before; the same as the reference-case benchmark).
ESTIMATOR_WARMUP_H = 2.0


@dataclass
class LoopStart:
    """Where a closed loop starts: the feed rate, the plant's steady state there and (NMPC) the
    controller's model's steady state at the same inputs."""

    feed_tph: float
    plant: object  # twin.SteadyState
    control: object | None


def loop_start(scene: Scene, models, blend0) -> LoopStart:
    """:func:`plant_start` and (NMPC) the controller's model's steady state at its inputs."""
    ss = plant_start(scene, models, blend0)
    feed0, speed0 = float(ss.u[0]), scene.feed.speed_frac_critical
    _refuse_start_outside_bounds(scene, feed0)
    css = (models.control.steady(feed_tph=feed0, speed_frac_critical=speed0, blend=blend0)
           if scene.controller.kind == "nmpc" else None)
    return LoopStart(feed0, ss, css)


def _refuse_start_outside_bounds(scene: Scene, feed0: float) -> None:
    """A closed loop's start feed outside ``controller.bounds``: its first move jumped into them, faster than
    the feed's rate limit, with a note on one row only (the scene's own feed_tph is checked with the scene,
    a start at the target's feed only here, where it is known)."""
    b = scene.controller.bounds
    if scene.controller.kind == "none" or b.feed_tph_min <= feed0 <= b.feed_tph_max:
        return
    raise SceneError(f"controller.bounds: the closed loop starts at {feed0:.4g} t/h, the feed rate that holds "
                     f"controller.target_p80_um = {scene.controller.target_p80_um:g} um at the initial blend and "
                     f"speed (feed.start = \"target\"), outside the feed bounds [{b.feed_tph_min:g}, "
                     f"{b.feed_tph_max:g}] t/h: the first move would jump into them, past the feed's rate limit; "
                     "widen the bounds to hold it, or start at feed.feed_tph with feed.start = \"scene\"")


def nmpc_parts(scene: Scene, models, start: LoopStart, codegen: str = "auto"):
    """The NMPC's EKF (started at the controller model's steady state ``start.control``) and the
    NMPC itself, after the RK4 stability check."""
    check_rk4_substeps(scene, models.control, start.control, schedule_blends(scene, models))
    return make_estimator(scene, models.control, start.control, codegen), make_controller(scene, models.control, codegen)


def measurement_range(scene: Scene) -> np.ndarray:
    """``(low, high)`` of the EKF's measurements (mpc.estimator.MEASUREMENTS) on the scene's mill, ends
    included: their physical limits (:func:`scenarios.scene.physical.physical_limits`), an open end the
    nearest float inside."""
    from scenarios.scene.physical import physical_limits

    out = np.empty((2, len(MEASUREMENTS)))
    for i, name in enumerate(MEASUREMENTS):
        lo, hi, lo_open, hi_open, _ = physical_limits(name, scene)
        out[:, i] = np.nextafter(lo, math.inf) if lo_open else lo, np.nextafter(hi, -math.inf) if hi_open else hi
    return out


def export_scene_controller(scene: Scene, out_dir, source: str = "") -> list[str]:
    """The scene's NMPC and EKF as C source in ``out_dir`` (:func:`mpc.export_controller`), at the
    closed loop's initial state; returns the files written."""
    _check_exportable(scene)
    try:
        check_out_dir(out_dir)  # before any work
    except MpcInputError as exc:
        raise SceneError(str(exc)) from None
    args, kwargs = _export_arguments(scene)
    try:
        return export_controller(*args, out_dir, source=source, **kwargs)
    except MpcInputError as exc:
        raise SceneError(str(exc)) from None


#: Items of an export's manifest a check reports without calling the export stale: the scene's path as typed
#: (``source``) and where the scene, calibration and preset files were (a checkout elsewhere, as in CI: their
#: sha256 are compared), and the versions that made it (the files the export writes are regenerated and compared,
#: so a version that changes them shows there).
CHECK_NOTE_ITEMS = ("source", "casadi", "built_from.scene.path", "built_from.calibration.path",
                    "built_from.mill_preset_file.path", "built_from.versions")


def check_scene_export(scene: Scene, out_dir, source: str = "") -> list:
    """What differs between the export in ``out_dir`` and what :func:`export_scene_controller` would write
    now (:func:`mpc.export.check_export`: a list of ExportDifference, empty when current); writes nothing.
    SceneError for a scene it would not export, a folder that holds no export or a manifest that does not
    say what it was built from."""
    from mpc import check_export, recorded_export

    _check_exportable(scene)
    again = f"grindtwin export-controller {source or scene.source_path} --out {out_dir}"
    try:
        recorded_export(out_dir, again)  # before any work
        args, kwargs = _export_arguments(scene)
        return check_export(out_dir, *args, source=source, note_items=CHECK_NOTE_ITEMS, again=again, **kwargs)
    except MpcInputError as exc:
        raise SceneError(str(exc)) from None


def _check_exportable(scene: Scene) -> None:
    """SceneError unless the scene's controller is one export-controller exports (before any model is built)."""
    c = scene.controller
    if c.kind != "nmpc":
        raise SceneError(f"controller.kind = {c.kind!r}: export-controller exports an NMPC "
                         f"(controller.kind = 'nmpc')")
    if c.solver != "rti" or c.qpsol != "condensed":  # before the models: an IPOPT build took 10 s to be refused
        key, value, allowed = (("controller.solver", c.solver, "rti") if c.solver != "rti"
                               else ("controller.qpsol", c.qpsol, "condensed"))
        raise SceneError(f"{key} = {value!r}: export-controller exports only {key} = {allowed!r} (the real-time "
                         f"iteration on the condensed QP, the same QP as HPIPM's: controller.solver = 'rti' and "
                         f"controller.qpsol = 'condensed')")


def _export_arguments(scene: Scene) -> tuple[tuple, dict]:
    """The scene's models built, and :func:`mpc.export_controller`'s arguments for its NMPC and EKF at the
    closed loop's initial state: ``(controller, estimator, u0)`` and the keywords but ``out_dir`` and ``source``."""
    from scenarios.run.feed import feed_schedule
    from scenarios.run.models import build_models, component_ores
    from scenarios.scene.physical import physical_limits

    models = build_models(scene)
    feed, _ = feed_schedule(scene, models.components, scene.time_grid_h(), component_ores(scene))
    start = loop_start(scene, models, component_blend(feed, models.components)[0])
    estimator, controller = nmpc_parts(scene, models, start, codegen="off")
    return ((controller, estimator, [start.feed_tph, scene.feed.speed_frac_critical]),
            {"preview_lead_h": scene.controller.preview_lead_h, "measurement_range": measurement_range(scene),
             "feed_max_tph": physical_limits("feed_tph", scene)[1], "built_from": export_provenance(scene, models)})


def export_provenance(scene: Scene, models) -> dict:
    """What an export was built from, as a run's summary.json records it (the manifest's ``built_from``): the
    scene file (resolved path, sha256) and the scene as loaded, the calibration, the mill preset file, the
    controller model's effects and size grid, the versions. The manifest said only the scene's path as typed
    (``scenarios/x.toml``): an export could not be told from one of an edited scene or another calibration."""
    from scenarios.run.summary import preset_file_identity, versions

    path = scene.source_path
    grid = models.control.model.spec.grid
    known = path is not None and Path(path).is_file()
    return {"scene": {"path": str(Path(path).resolve()), "sha256": file_sha256(path)} if known else None,
            "scene_as_loaded": scene.model_dump(mode="json", exclude_none=True),
            "calibration": models.calibration.identity() if models.calibration is not None else None,
            "mill_preset_file": preset_file_identity(scene),
            "controller_effects": list(models.control.model.effect_names),
            "controller_size_classes": {"top_um": float(grid.upper_um[0]), "ratio": float(grid.ratio),
                                        "count": int(len(grid.upper_um))},
            "versions": versions()}


def run_closed(scene: Scene, models, feed: pd.DataFrame, progress: bool):
    """Closed loop through :func:`mpc.closed_loop.run_closed_loop`.

    Wiring (the same as benchmarks/mpc_reference_case.py): the plant starts at
    :func:`loop_start` (``feed.start``); the sensors are the scene's ``[sensors]``; the NMPC gets an EKF on the
    controller's model (hardness as a random walk), warmed up on the steady plant for
    ``ESTIMATOR_WARMUP_H`` and reset where its estimate stops being finite
    (:class:`CountingEstimator`); PI is :func:`mpc.closed_loop.pi_baseline` (SIMC on the
    linearised plant twin, analyser delay added). ``schedule(t)`` holds the blend of the sample
    at or before t (clamped at the end). Any failure inside the loop is a RunError with its
    reason; the controller's failures, fallbacks and the estimator's resets are counted in the
    returned ``extra["controller_health"]``.
    """
    c = scene.controller
    blend = component_blend(feed, models.components)
    times = feed["time_h"].to_numpy(float)
    dt = scene.scene.sample_period_h
    notes: list[str] = []
    estimator = None
    try:
        start = loop_start(scene, models, blend[0])
        ss = start.plant
        notes.append(f"the plant starts at steady state, feed {start.feed_tph:.4g} t/h, "
                     f"speed {scene.feed.speed_frac_critical:.3g}")
        notes += dead_time_notes(scene)
        sensors = scene_sensors(scene)
        schedule = hold_schedule(times, blend, dt)
        controller, estimator = _controller_and_estimator(scene, models, start, sensors)
        settings = LoopSettings(
            scene.scene.duration_h, dt, seed=scene.scene.seed, preview_lead_h=c.preview_lead_h,
            target_p80_um=c.target_p80_um if c.target_p80_um is not None else math.nan,
            load_band=tuple(c.load_band_frac), progress=progress,
            estimator_warmup_h=ESTIMATOR_WARMUP_H if estimator is not None else 0.0)
        plant = RecordingPlant(models.plant.model)
        res = run_closed_loop(plant, controller, estimator, schedule, sensors, ss.x, ss.u, settings)
    except (RunError, SceneError):
        raise
    except MpcInputError as exc:  # a setting the controller refuses: bad input, not a failed run
        raise SceneError(f"scene {scene.scene.name}: the controller refused the scene: {exc}") from None
    except Exception as exc:  # noqa: BLE001 - the loop's failure is the run's failure
        raise RunError(f"scene {scene.scene.name}: the closed loop failed: "
                       f"{type(exc).__name__}: {exc}") from None
    frame = res.frame.copy()
    sizes = run_size_data(models.plant.model, plant.samples(frame["time_h"].to_numpy(float)), batch=False)
    k = dict(res.kpis)
    checked_top = c.load_band_frac[1] if c.kind == "nmpc" else None  # the top check_rk4_substeps checked
    health = controller_health(frame, estimator, checked_top)
    extra = {"notes": notes, "warnings": health_notes(health), "controller_health": health,
             "solve_times_s": frame["solve_time_s"].dropna().to_numpy() if "solve_time_s" in frame else None,
             "solve_time_median_s": k.get("solve_time_median_s", math.nan),
             "solve_time_p95_s": k.get("solve_time_p95_s", math.nan),
             "start_feed_tph": start.feed_tph}  # the frame's first feed is the first move (NMPC: at t = 0)
    return frame, sizes, extra


def _controller_and_estimator(scene: Scene, models, start: LoopStart, sensors):
    """The NMPC with its EKF (on the controller's model, RK4 sub-steps checked first), or the PI
    baseline without one."""
    c, dt = scene.controller, scene.scene.sample_period_h
    if c.kind == "nmpc":
        estimator, controller = nmpc_parts(scene, models, start)
        return controller, CountingEstimator(estimator)
    b = c.bounds
    controller, _ = pi_baseline(
        models.plant.model, start.plant, sensors, dt, c.target_p80_um,
        feed_tph_min=b.feed_tph_min, feed_tph_max=b.feed_tph_max,
        feed_rate_max_tph_per_h=b.feed_rate_max_tph_per_h if b.feed_rate_max_tph_per_h is not None else math.inf)
    return controller, None


class CountingEstimator:
    """The EKF with its resets counted: when an update leaves a non-finite estimate (or its
    linear algebra fails), the EKF is reset to its initial estimate and covariance and the
    reset is recorded (``resets``: the numbers of the estimator steps at which it was reset,
    1 = its first step, warm-up included). Everything else is the EKF's own."""

    def __init__(self, ekf):
        self.ekf = ekf
        self.resets: list[int] = []
        self._calls = 0

    def __getattr__(self, name):
        return getattr(self.ekf, name)

    def make_step(self, y_meas, u, d_known):
        self._calls += 1
        try:
            x, d = self.ekf.make_step(y_meas, u, d_known)
            ok = bool(np.all(np.isfinite(x)) and np.all(np.isfinite(d)) and np.all(np.isfinite(self.ekf.P)))
        except (np.linalg.LinAlgError, MpcSolverError):  # the latter: a non-finite update (Ekf.make_step)
            ok = False
        if ok:
            return x, d
        self.resets.append(self._calls)
        self.ekf.reset()
        return self.ekf.x_est, np.r_[np.asarray(d_known, float).reshape(-1)[: self.ekf.nd - 1],
                                     self.ekf.hardness_est]


def controller_health(frame: pd.DataFrame, estimator, checked_load_top: float | None = None) -> dict:
    """What went wrong in a closed loop, counted over its samples: steps whose solve failed,
    fallbacks by kind, steps that reached no plan for the target, estimator resets, and (with
    ``checked_load_top``, the load up to which the NMPC's RK4 step count was checked stable,
    :func:`check_rk4_substeps`) samples whose plant load was above it."""
    n = len(frame)
    success = frame["success"].astype(bool) if "success" in frame else pd.Series(True, index=frame.index)
    fallback = frame["fallback"] if "fallback" in frame else pd.Series(None, index=frame.index)
    status = frame["status"].astype(str) if "status" in frame else pd.Series("", index=frame.index)
    kinds = fallback.dropna().value_counts()
    failed = ~success
    return {"steps": n, "failed_steps": int(failed.sum()),
            "fallback_steps": int(fallback.notna().sum()),
            "fallbacks": {str(k): int(v) for k, v in kinds.items()},
            "target_unreachable_steps": int(status.str.startswith("target_unreachable").sum()),
            "first_failure_time_h": float(frame.loc[failed, "time_h"].iloc[0]) if failed.any() else None,
            "failure_statuses": {str(k): int(v) for k, v in status[failed].value_counts().head(5).items()},
            "estimator_resets": len(estimator.resets) if estimator is not None else 0,
            "hardness_at_bound_steps": _hardness_at_bound(frame, estimator),
            **_above_checked_load(frame, checked_load_top)}


def _above_checked_load(frame: pd.DataFrame, top: float | None) -> dict:
    """Samples whose plant load was above ``top`` (none without it), and the highest load with its
    time: the controller's model was checked for RK4 stability up to that load only."""
    if top is None or "load_frac" not in frame:
        return {}
    load = frame["load_frac"].to_numpy(float)
    above = load > top
    k = int(np.nanargmax(load)) if np.isfinite(load).any() else 0
    return {"above_checked_load_steps": int(above.sum()), "checked_load_top": float(top),
            "load_max": float(load[k]), "load_max_time_h": float(frame["time_h"].iloc[k])}


def _hardness_at_bound(frame: pd.DataFrame, estimator) -> int:
    """Samples whose hardness estimate sits at a bound of the EKF's clip (``hardness_bounds``):
    the estimate is saturated there, and the controller runs a model it knows to be wrong."""
    ekf = getattr(estimator, "ekf", None)
    if ekf is None or not getattr(ekf, "has_hardness", False) or "hardness_est" not in frame:
        return 0
    h = frame["hardness_est"].to_numpy(float)
    lo, hi = ekf.hardness_bounds
    return int(np.sum(np.isclose(h, lo, rtol=1e-9, atol=0.0) | np.isclose(h, hi, rtol=1e-9, atol=0.0)))


def dead_time_notes(scene: Scene) -> list[str]:
    """An NMPC whose model's analyser dead time (``effect_options.sensor_delay.dead_time_h``, none without the
    effect) is not the analyser's (``sensors.p80_dead_time_h``): a mismatch study, or a slip the run said
    nothing of (docs/scenes.md asks for the two to be equal)."""
    if scene.controller.kind != "nmpc":
        return []
    analyser = scene.sensors.p80_dead_time_h
    if "sensor_delay" in scene.effects:
        default = EFFECTS["sensor_delay"].options["dead_time_h"].default
        model = float(scene.effect_options.get("sensor_delay", {}).get("dead_time_h", default))
        where = "effect_options.sensor_delay.dead_time_h"
    else:
        model, where = 0.0, "no sensor_delay effect"
    if abs(model - analyser) <= 1e-9 * max(analyser, 1.0):
        return []
    return [f"the controller's model assumes an analyser dead time of {model:g} h ({where}), the analyser's is "
            f"{analyser:g} h (sensors.p80_dead_time_h)"]


def health_notes(health: dict) -> list[str]:
    """One note per thing that went wrong (none when the controller and estimator were fine)."""
    notes = []
    if health["failed_steps"]:
        kinds = ", ".join(f"{k} {v}" for k, v in health["fallbacks"].items()) or "none"
        notes.append(f"the controller's solve failed on {health['failed_steps']} of {health['steps']} "
                     f"steps (first at {health['first_failure_time_h']:.4g} h; fallbacks: {kinds}; "
                     f"statuses: {health['failure_statuses']})")
    if health["estimator_resets"]:
        notes.append(f"the estimator was reset {health['estimator_resets']} times (its estimate was "
                     "not finite)")
    if health.get("target_unreachable_steps"):
        notes.append(f"on {health['target_unreachable_steps']} of {health['steps']} steps the controller found no "
                     "plan that reaches the P80 target within its input bounds")
    if health.get("hardness_at_bound_steps"):
        notes.append(f"on {health['hardness_at_bound_steps']} of {health['steps']} steps the estimator's hardness sat "
                     "at a bound of its range (estimator hardness_bounds): the ore differs from the model by more "
                     "than the estimator may say, and the controller ran a model it knew to be wrong")
    if health.get("above_checked_load_steps"):
        notes.append(f"on {health['above_checked_load_steps']} of {health['steps']} steps the mill's load was above "
                     f"{health['checked_load_top']:g} of nominal, the top of the load band up to which the "
                     f"controller's RK4 step count was checked stable (it reached {health['load_max']:.3g} at "
                     f"{health['load_max_time_h']:.3g} h): its predictions there were not checked")
    return notes
