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
  ore fractions (see :func:`mineralogy_to_blend`); a scene with such a history and no
  ``[ores]`` uses the reference types A-D as its components.
- **Start.** A continuous mill (``transport`` effect) starts at the steady state of the initial
  feed rate, speed and blend (so that a run shows the schedule, not a start-up transient); if
  that steady state cannot be found the mill starts at its nominal hold-up filled with feed.
  A batch mill (no ``transport``) starts with ``feed.batch_charge_kg`` of feed of the initial
  blend and grinds it for ``scene.duration_h`` with no feed.
- **Inputs.** Held over each sample period. Controller ``"none"``: the scene's ``feed_tph``
  and ``speed_frac_critical`` throughout (in a replay, the recorded ones where recorded).
  ``"pi"`` and ``"nmpc"`` need the ``mpc`` package's modules (see :func:`_closed_loop`).
- **Analyser.** Open loop, ``p80_analyser_um`` is what the scene's P80 analyser would report
  (:func:`analyser_trace`: dead time, sampling, noise drawn with the scene's seed); the KPIs use
  the plant's ``p80_um``.
- **Progress.** The run is integrated in stretches of ``PROGRESS_CHUNK_STEPS`` samples with a
  tqdm bar; the integrator restarts at each stretch (as at every input change).

KPI definitions (``RunResult.kpis``; keys carry their units)
- ``p80_iae_um_h``: integral over the run of |P80 - target| (trapezoidal, plant P80 as the
  model computes it, not the noisy analyser value); NaN without ``controller.target_p80_um``.
- ``p80_within_10um_frac``: share of samples with |P80 - target| <= 10 um; NaN without target.
- ``specific_energy_kwh_t``: total energy drawn (integral of power) / total fresh feed; for a
  batch grind, / the charge.
- ``throughput_t``: product discharged over the run; for a batch grind the charge ground.
- ``load_outside_band_frac``: share of samples whose load (hold-up / nominal hold-up) is outside
  ``controller.load_band_frac``; NaN for a batch grind (no load dynamics).
- ``solve_time_median_s``, ``solve_time_p95_s``: controller solve times; **NaN in open loop**
  (no solver ran), written as ``null`` in summary.json.
- ``mass_balance_error``: max |fed - produced - (H - H0)| / (fed + H0) over the run.
- Also ``p80_final_um``, ``p80_mean_um``, ``energy_kwh``, ``fed_t``, ``duration_h``.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.optimize import nnls
from tqdm.auto import tqdm

from scenarios.errors import RunError, SceneError
from scenarios.loader import load_scene, scene_from_dict
from scenarios.schema import Scene

#: Samples integrated per call (one progress-bar tick).
PROGRESS_CHUNK_STEPS = 60
#: Band of P80 (um) around the target counted by ``p80_within_10um_frac``.
P80_BAND_UM = 10.0
#: Number of product size distributions kept over time (evenly spaced samples) for plots.
N_PSD_SNAPSHOTS = 6
#: Weight of the "fractions sum to 1" row in the NNLS fit of a mineralogy to the ores (wt%).
SUM_ROW_WEIGHT = 100.0

KPI_KEYS = ("p80_iae_um_h", "p80_within_10um_frac", "specific_energy_kwh_t", "throughput_t",
            "load_outside_band_frac", "solve_time_median_s", "solve_time_p95_s",
            "mass_balance_error")


@dataclass
class RunResult:
    """One run: ``frame`` (one row per sample, unit-suffixed columns), ``summary`` (JSON-able:
    scene, kpis, model description, effects, versions, seed, notes), ``psd`` (product size
    distribution snapshots: rows = times, columns = class upper sizes in um, values = cumulative
    fraction passing) and ``out_dir`` (where it was written, or ``None``)."""

    frame: pd.DataFrame
    summary: dict
    out_dir: Path | None = None
    psd: pd.DataFrame | None = None

    @property
    def kpis(self) -> dict:
        return self.summary["kpis"]


@dataclass
class Models:
    """The twins of a run: ``control`` (the controller's model) and ``plant`` (simulated)."""

    control: Any
    plant: Any
    components: list[str]
    notes: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------- building
def _as_scene(scene_or_path) -> Scene:
    if isinstance(scene_or_path, Scene):
        return scene_or_path
    return load_scene(scene_or_path)


def is_batch(scene: Scene) -> bool:
    """A batch grind: the scene has no ``transport`` effect."""
    return "transport" not in scene.effects


def _component_ores(scene: Scene) -> dict:
    """Component name -> twin Mineralogy: the scene's ores, or the reference types A-D for a
    mineralogy history in a scene without ores."""
    from scenarios.schedule import ore_mineralogies

    if scene.ores:
        return ore_mineralogies(scene)
    from twin.mineralogy import Mineralogy
    from twin.ores import reference_ores

    return {name: Mineralogy(dict(o.wt_pct), o.texture, name=name)
            for name, o in sorted(reference_ores().items())}


def _mill(scene: Scene):
    from twin.breakage_map import shipped_calibration
    from twin.mill import get_mill

    m = scene.mill
    return get_mill(m.preset, shipped_calibration()).with_(
        diameter_m=m.diameter_m, length_m=m.length_m, ball_filling_frac=m.ball_filling_frac)


def _twin(scene: Scene, ores: dict, effects, effect_options, size_classes, n_mixers=None):
    from twin.errors import TwinError
    from twin.sizes import SizeGrid
    from twin.twin import Twin

    try:
        return Twin(list(ores.values()), mill=_mill(scene), effects=list(effects),
                    effect_options=dict(effect_options or {}),
                    grid=SizeGrid(size_classes.top_um, size_classes.ratio, size_classes.count),
                    n_mixers=int(n_mixers or scene.mill.n_mixers), feed_p80_um=scene.feed.p80_um,
                    feed_modulus=scene.feed.ggs_modulus)
    except TwinError as exc:
        src = scene.source_path or scene.scene.name
        raise SceneError(f"{src}: the twin refused the scene: {exc}") from None


def build_models(scene: Scene) -> Models:
    """The controller's twin and, if ``[plant]`` differs, the plant's twin (built once)."""
    ores = _component_ores(scene)
    control = _twin(scene, ores, scene.effects, scene.effect_options, scene.mill.size_classes)
    notes = []
    if not scene.ores:
        notes.append("no [ores]: components are the reference types " + ", ".join(ores))
    plant = control
    p = scene.plant
    if p is not None:
        if p.model != "twin":
            raise RunError(f"plant model {p.model!r} is not supported by the runner yet; use "
                           "plant.model = 'twin'")
        effects = p.effects if p.effects is not None else scene.effects
        # the scene's options apply to the plant's effects that have them
        options = p.effect_options if p.effect_options is not None else {
            k: v for k, v in scene.effect_options.items() if k in effects}
        sizes = p.size_classes if p.size_classes is not None else scene.mill.size_classes
        mixers = p.n_mixers if p.n_mixers is not None else scene.mill.n_mixers
        if (list(effects), dict(options), sizes, mixers) != (
                list(scene.effects), dict(scene.effect_options), scene.mill.size_classes, scene.mill.n_mixers):
            plant = _twin(scene, ores, effects, options, sizes, mixers)
            notes.append("the plant is a separate twin (effects " + ", ".join(effects) + ")")
    return Models(control=control, plant=plant, components=list(ores), notes=notes)


# --------------------------------------------------------------------------- feed over time
def mineralogy_to_blend(wt_pct: pd.DataFrame, ores: dict) -> tuple[np.ndarray, np.ndarray]:
    """Each row of mineral wt% as a mix of the ores: ``(fractions (n, n_ores), residual_wt_pct (n,))``.

    Rule: non-negative least squares of the row's wt% vector on the ores' wt% vectors, with a
    row of weight ``SUM_ROW_WEIGHT`` asking the fractions to sum to 1; the fractions are then
    rescaled to sum exactly to 1. The residual is the Euclidean distance (wt%) between the row
    and the mix, reported per sample: a large residual means the recorded feed is not a mix of
    the scene's ores and the run can only approximate it. Minerals absent from every ore and
    the texture columns of the history do not enter the fit except through the residual.
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


def feed_schedule(scene: Scene, components: list[str], times_h: np.ndarray, ores: dict | None = None
                  ) -> tuple[pd.DataFrame, list[str]]:
    """The feed on the sample grid: columns ``ore_<c>_frac`` per component, the recorded
    plant values (``recorded_*``) if the history has them, ``history_fit_residual_wt_pct`` for
    a mineralogy history. Returns ``(table, notes)``."""
    from scenarios.schedule import feed_table, load_history, ore_column

    notes: list[str] = []
    table = feed_table(scene, times_h).reset_index()
    history = load_history(scene)
    if history is not None:
        notes += [f"history {history.source.name}: {line}" for line in history.report]
    if history is not None and history.kind == "mineralogy":
        ores = ores if ores is not None else _component_ores(scene)
        comp_cols = [c for c in table.columns if c.endswith("_wt_pct")]
        fracs, resid = mineralogy_to_blend(table[comp_cols], ores)
        out = pd.DataFrame({"time_h": table["time_h"]})
        for j, c in enumerate(components):
            out[ore_column(c)] = fracs[:, j]
        out["history_fit_residual_wt_pct"] = resid
        notes.append(f"mineralogy history mapped to ores {', '.join(components)} by NNLS: residual "
                     f"mean {resid.mean():.3g} wt%, max {resid.max():.3g} wt%")
        for c in table.columns:
            if c.startswith("recorded_"):
                out[c] = table[c]
        return out, notes
    for c in components:
        if ore_column(c) not in table.columns:
            table[ore_column(c)] = 0.0
    return table, notes


# --------------------------------------------------------------------------- the run
def run_scene(scene_or_path, out_dir=None, progress: bool = True, *, csv: bool = False,
              plots: bool = True, replay: bool = False) -> RunResult:
    """Run a scene (a ``Scene`` or a path) and, with ``out_dir``, write its outputs there.

    ``replay=True`` drives the inputs with the recorded feed rate and speed of the history (open
    loop) where the history records them. Raises SceneError for a scene the twin refuses and
    RunError when the run fails. See the module docstring for what a run does and the KPIs.
    """
    scene = _as_scene(scene_or_path)
    t_start = time.perf_counter()
    models = build_models(scene)
    times = scene.time_grid_h()
    ores = _component_ores(scene)
    feed, notes = feed_schedule(scene, models.components, times, ores)
    notes = models.notes + notes
    if is_batch(scene):
        frame, psd, extra = _run_batch(scene, models, feed, progress)
    elif scene.controller.kind == "none":
        frame, psd, extra = _run_open_loop(scene, models, feed, progress, replay)
    else:
        frame, psd, extra = _closed_loop(scene, models, feed, progress)
    notes += extra.pop("notes", [])
    for c in feed.columns:
        if c.startswith("recorded_") or c == "history_fit_residual_wt_pct":
            frame[c] = feed[c].to_numpy()
    kpis = compute_kpis(scene, frame, **extra)
    summary = make_summary(scene, models, kpis, notes, time.perf_counter() - t_start)
    if psd is not None:
        summary["final_psd"] = {"what": psd.attrs.get("what", "product"), "time_h": float(psd.index[-1]),
                                "size_um": [float(x) for x in psd.columns],
                                "passing_frac": [float(v) for v in psd.iloc[-1]]}
    result = RunResult(frame=frame, summary=summary, psd=psd)
    if out_dir is not None:
        from scenarios.outputs import write_run

        result.out_dir = write_run(result, out_dir, csv=csv, plots=plots)
    return result


def _component_blend(feed: pd.DataFrame, components: list[str]) -> np.ndarray:
    from scenarios.schedule import ore_column

    B = feed[[ore_column(c) for c in components]].to_numpy(float)
    B = np.clip(B, 0.0, None)
    return B / B.sum(axis=1, keepdims=True)


def _input_series(scene: Scene, feed: pd.DataFrame, replay: bool) -> tuple[np.ndarray, np.ndarray]:
    n = len(feed)
    f = np.full(n, float(scene.feed.feed_tph))
    s = np.full(n, float(scene.feed.speed_frac_critical))
    if replay:
        if "recorded_feed_tph" in feed:
            f = feed["recorded_feed_tph"].to_numpy(float)
        if "recorded_speed_frac_critical" in feed:
            s = feed["recorded_speed_frac_critical"].to_numpy(float)
    return f, s


def _start_state(scene: Scene, twin, u0, blend0, notes: list[str]):
    from twin.errors import TwinError

    try:
        ss = twin.steady(feed_tph=float(u0[0]), speed_frac_critical=float(u0[1]), blend=list(blend0))
        notes.append(f"started at the steady state of the initial inputs (P80 {ss.p80_um:.4g} um)")
        return ss.x
    except (TwinError, RuntimeError) as exc:
        notes.append(f"no steady state at the initial inputs ({exc}); started at nominal hold-up")
        return twin.model.initial_state(list(blend0))


def _simulate_chunks(scene: Scene, twin, x0, feed_tph, speed, blend, progress: bool):
    """Integrate over the grid in stretches; returns (frame, states) with cumulative fed/produced."""
    from twin.errors import TwinError

    dt = scene.scene.sample_period_h
    n = len(feed_tph) - 1
    frames, states = [], [np.asarray(x0, float)[None, :]]
    fed0 = prod0 = 0.0
    x = x0
    with tqdm(total=n, desc=scene.scene.name, unit="sample", disable=not progress) as bar:
        for a in range(0, n, PROGRESS_CHUNK_STEPS):
            b = min(a + PROGRESS_CHUNK_STEPS, n)
            try:
                tr = twin.simulate((b - a) * dt, dt, feed_tph=lambda t, a=a: feed_tph[a + int(round(t / dt))],
                                   speed_frac_critical=lambda t, a=a: speed[a + int(round(t / dt))],
                                   blend=lambda t, a=a: blend[a + int(round(t / dt))], x0=x)
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


def _psd_snapshots(twin, states, frame, components, batch: bool) -> pd.DataFrame:
    """Cumulative passing of the product (continuous) or of the mill content (batch) at
    ``N_PSD_SNAPSHOTS`` evenly spaced samples (first and last included)."""
    model = twin.model
    grid = model.spec.grid
    fn = model.product_psd_function()
    idx = np.unique(np.linspace(0, len(frame) - 1, N_PSD_SNAPSHOTS).round().astype(int))
    rows = {}
    for i in idx:
        u = [frame["feed_tph"].iloc[i], frame["speed_frac_critical"].iloc[i]]
        d = model.d_vector([frame[f"blend_{c}_frac"].iloc[i] for c in components],
                           frame["hardness_scale"].iloc[i])
        mass = np.asarray(fn(states[i], u, d), float).ravel()
        rows[float(frame["time_h"].iloc[i])] = grid.cumulative_passing(mass)
    upper = grid.upper_um
    psd = pd.DataFrame(rows, index=pd.Index(np.round(upper, 4), name="size_um")).T
    psd.index.name = "time_h"
    psd.attrs["what"] = "mill content" if batch else "product"
    return psd


def _run_open_loop(scene, models, feed, progress, replay):
    notes: list[str] = []
    twin = models.plant
    blend = _component_blend(feed, models.components)
    f, s = _input_series(scene, feed, replay)
    if replay and "recorded_feed_tph" in feed:
        notes.append("replay: inputs are the recorded feed rate and speed")
    x0 = _start_state(scene, twin, (f[0], s[0]), blend[0], notes)
    frame, states = _simulate_chunks(scene, twin, x0, f, s, blend, progress)
    frame["p80_analyser_um"] = analyser_trace(frame["time_h"].to_numpy(), frame["p80_um"].to_numpy(),
                                              scene.sensors, scene.scene.seed)
    psd = _psd_snapshots(twin, states, frame, models.components, batch=False)
    return frame, psd, {"notes": notes, "solve_times_s": None}


def analyser_trace(time_h: np.ndarray, p80_um: np.ndarray, sensors, seed: int) -> np.ndarray:
    """What the P80 analyser of ``[sensors]`` reports: the plant P80 ``p80_dead_time_h`` earlier
    (linear interpolation; the first value before t = 0), sampled every ``p80_sample_period_h``
    and held until the next sample, plus Gaussian noise of ``p80_noise_um`` (one draw per
    analyser sample, ``numpy.random.default_rng(seed)``)."""
    t = np.asarray(time_h, float)
    period = sensors.p80_sample_period_h or (t[1] - t[0] if len(t) > 1 else 1.0)
    k = np.floor(t / period + 1e-9)
    t_sample = k * period
    seen = np.interp(t_sample - sensors.p80_dead_time_h, t, np.asarray(p80_um, float))
    n_samples = int(k.max()) + 1 if len(k) else 0
    noise = np.random.default_rng(seed).normal(0.0, 1.0, n_samples) * sensors.p80_noise_um
    return seen + noise[k.astype(int)]


def _run_batch(scene, models, feed, progress):
    twin = models.plant
    blend = _component_blend(feed, models.components)
    charge_t = float(scene.feed.batch_charge_kg) / 1000.0
    x0 = twin.model.initial_state(list(blend[0]), load_frac=charge_t / twin.model.spec.holdup_nominal_t)
    n = len(blend)
    f = np.zeros(n)
    s = np.full(n, float(scene.feed.speed_frac_critical))
    frame, states = _simulate_chunks(scene, twin, x0, f, s, blend, progress)
    energy = _cumulative_energy_kwh(frame)
    frame["specific_energy_kwh_t"] = energy / charge_t  # the twin's power/feed is undefined at zero feed
    psd = _psd_snapshots(twin, states, frame, models.components, batch=True)
    notes = [f"batch grind of {charge_t * 1000:g} kg; specific energy = cumulative energy / charge; "
             "size distributions are of the mill content"]
    return frame, psd, {"notes": notes, "solve_times_s": None, "batch_charge_t": charge_t}


def _cumulative(frame: pd.DataFrame, column: str) -> np.ndarray:
    """Integral of a rate column over time (trapezoidal) at every sample; NaN if absent."""
    if column not in frame:
        return np.full(len(frame), np.nan)
    p = frame[column].to_numpy(float)
    t = frame["time_h"].to_numpy(float)
    return np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(t))])


def _cumulative_energy_kwh(frame: pd.DataFrame) -> np.ndarray:
    """Integral of power over time (trapezoidal) [kWh] at every sample."""
    return _cumulative(frame, "power_kw")


# --------------------------------------------------------------------------- closed loop
def _require(module: str, kind: str):
    """Import ``module`` for controller ``kind``; RunError naming it when it is missing."""
    try:
        found = importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        found = False
    if not found:
        raise RunError(f"controller kind {kind!r} needs {module}, not available")
    return importlib.import_module(module)


def _feed_bounds(scene: Scene) -> tuple[float, float]:
    """Feed-rate bounds: the scene's, else half and one and a half times its feed rate."""
    b = scene.controller.bounds
    f = float(scene.feed.feed_tph)
    return (b.feed_tph_min if b.feed_tph_min is not None else 0.5 * f,
            b.feed_tph_max if b.feed_tph_max is not None else 1.5 * f)


def nmpc_settings(scene: Scene):
    """``mpc.nmpc.NmpcSettings`` from ``[controller]``: names map one to one (weights prefixed
    ``weight_``); unset feed bounds are 0.5x and 1.5x ``feed.feed_tph``; unset rate limits
    and power limit are infinite; ``dt_h`` is the scene's sample period."""
    nmpc = _require("mpc.nmpc", "nmpc")
    c = scene.controller
    lo, hi = _feed_bounds(scene)
    return nmpc.NmpcSettings(
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


def _check_rk4_substeps(scene: Scene, model, css) -> None:
    """Refuse ``controller.rk4_substeps`` below the RK4 stability count of the controller's
    model at its initial steady state (mpc.discretize.stable_rk4_substeps)."""
    from mpc.discretize import RK4_RATE_SAFETY, stable_rk4_substeps

    need = stable_rk4_substeps(model.f, css.x, css.u, css.d, scene.scene.sample_period_h)
    if scene.controller.rk4_substeps < need:
        raise SceneError(f"controller.rk4_substeps = {scene.controller.rk4_substeps} is unstable for the "
                         f"controller's model at the initial steady state: RK4 needs at least {need} "
                         f"steps per {scene.scene.sample_period_h} h sample (rates x {RK4_RATE_SAFETY})")


def make_controller(scene: Scene, twin):
    """The scene's NMPC on the controller's twin: ``mpc.nmpc.Controller`` with
    :func:`nmpc_settings` (the PI baseline is built by the closed loop itself)."""
    return _require("mpc.nmpc", scene.controller.kind).Controller(twin.model, nmpc_settings(scene))


#: The estimator runs this long on the steady plant before the loop closes (as on a plant that
#: was running before; the same as the reference-case benchmark).
ESTIMATOR_WARMUP_H = 2.0


def _closed_loop(scene, models, feed, progress):
    """Closed loop through :func:`mpc.closed_loop.run_closed_loop`.

    Wiring (the same as benchmarks/mpc_reference_case.py): the plant starts at the steady state
    that holds the target P80 at the scene's speed and initial blend (feed solved by
    :func:`mpc.optimize.feed_for_target`; the scene's ``feed_tph`` if it has no target); the
    sensors are the scene's ``[sensors]``; the NMPC gets an EKF on the controller's model
    (hardness as a random walk), warmed up on the steady plant for ``ESTIMATOR_WARMUP_H``; PI is
    :func:`mpc.closed_loop.pi_baseline` (SIMC on the linearised plant twin, analyser delay
    added). ``schedule(t)`` holds the blend of the sample at or before t (clamped at the end).
    A missing module is a RunError naming it; any failure inside the loop a RunError with its
    reason.
    """
    kind = scene.controller.kind
    _require("mpc.nmpc" if kind == "nmpc" else "mpc.pi", kind)
    loop = _require("mpc.closed_loop", kind)
    optimize = _require("mpc.optimize", kind)
    c = scene.controller
    blend = _component_blend(feed, models.components)
    times = feed["time_h"].to_numpy(float)
    dt = scene.scene.sample_period_h
    speed0 = scene.feed.speed_frac_critical
    notes: list[str] = []
    try:
        feed0 = (optimize.feed_for_target(models.plant, blend[0], c.target_p80_um, speed0)
                 if c.target_p80_um is not None else scene.feed.feed_tph)
        if not math.isfinite(feed0):
            raise RunError(f"scene {scene.scene.name}: no feed rate in 5-60 t/h holds the target P80 "
                           f"{c.target_p80_um} um at speed {speed0} with the initial blend")
        ss = models.plant.steady(feed_tph=feed0, speed_frac_critical=speed0, blend=blend[0])
        notes.append(f"the plant starts at steady state, feed {feed0:.4g} t/h, speed {speed0:.3g}")
        sensors = loop.Sensors(**{k: v for k, v in scene.sensors.model_dump().items()
                                  if k in loop.Sensors.__dataclass_fields__})

        def schedule(t_h):
            k = min(max(int(np.searchsorted(times, t_h + 1e-9 * dt, side="right")) - 1, 0), len(times) - 1)
            return blend[k]

        estimator = None
        if kind == "nmpc":
            from mpc.estimator import Ekf

            css = models.control.steady(feed_tph=feed0, speed_frac_critical=speed0, blend=blend[0])
            _check_rk4_substeps(scene, models.control.model, css)
            estimator = Ekf(models.control.model, dt, css.x)
            controller = make_controller(scene, models.control)
        else:
            b = c.bounds
            controller, _ = loop.pi_baseline(
                models.plant.model, ss, sensors, dt, c.target_p80_um,
                feed_tph_min=b.feed_tph_min, feed_tph_max=b.feed_tph_max,
                feed_rate_max_tph_per_h=(b.feed_rate_max_tph_per_h if b.feed_rate_max_tph_per_h is not None
                                         else math.inf))
        res = loop.run_closed_loop(
            models.plant.model, controller, estimator, schedule, sensors, scene.scene.duration_h, dt,
            ss.x, ss.u, seed=scene.scene.seed, preview_lead_h=c.preview_lead_h,
            target_p80_um=c.target_p80_um if c.target_p80_um is not None else math.nan,
            load_band=tuple(c.load_band_frac), progress=progress,
            estimator_warmup_h=ESTIMATOR_WARMUP_H if estimator is not None else 0.0)
    except (RunError, SceneError):
        raise
    except Exception as exc:  # noqa: BLE001 - the loop's failure is the run's failure
        raise RunError(f"scene {scene.scene.name}: the closed loop failed: "
                       f"{type(exc).__name__}: {exc}") from None
    frame = res.frame.copy()
    k = dict(res.kpis)
    extra = {"notes": notes,
             "solve_times_s": frame["solve_time_s"].dropna().to_numpy() if "solve_time_s" in frame else None,
             "solve_time_median_s": k.get("solve_time_median_s", math.nan),
             "solve_time_p95_s": k.get("solve_time_p95_s", math.nan)}
    return frame, None, extra


# --------------------------------------------------------------------------- KPIs
def compute_kpis(scene: Scene, frame: pd.DataFrame, solve_times_s=None, batch_charge_t=None,
                 solve_time_median_s=None, solve_time_p95_s=None) -> dict:
    """The KPIs of a run from its frame (definitions in the module docstring)."""
    t = frame["time_h"].to_numpy(float)
    p80 = frame["p80_um"].to_numpy(float)
    target = scene.controller.target_p80_um
    k: dict[str, Any] = {}
    if target is not None and not is_batch(scene):
        err = np.abs(p80 - target)
        k["p80_iae_um_h"] = float(np.sum(0.5 * (err[1:] + err[:-1]) * np.diff(t)))
        k["p80_within_10um_frac"] = float(np.mean(err <= P80_BAND_UM))
    else:
        k["p80_iae_um_h"] = math.nan
        k["p80_within_10um_frac"] = math.nan
    energy = _cumulative_energy_kwh(frame)[-1]
    if "fed_t" not in frame and "feed_tph" in frame:  # e.g. a closed-loop frame: integrate
        frame["fed_t"] = _cumulative(frame, "feed_tph")
    if "produced_t" not in frame and "throughput_tph" in frame:
        frame["produced_t"] = _cumulative(frame, "throughput_tph")
    fed = float(frame["fed_t"].iloc[-1]) if "fed_t" in frame else math.nan
    if batch_charge_t is not None:
        k["specific_energy_kwh_t"] = float(energy / batch_charge_t)
        k["throughput_t"] = float(batch_charge_t)
    else:
        k["specific_energy_kwh_t"] = float(energy / fed) if fed > 0 else math.nan
        k["throughput_t"] = float(frame["produced_t"].iloc[-1]) if "produced_t" in frame else math.nan
    if "load_frac" in frame:
        lo, hi = scene.controller.load_band_frac
        load = frame["load_frac"].to_numpy(float)
        k["load_outside_band_frac"] = float(np.mean((load < lo) | (load > hi)))
    else:
        k["load_outside_band_frac"] = math.nan
    if solve_times_s is not None and len(solve_times_s):
        k["solve_time_median_s"] = float(np.median(solve_times_s))
        k["solve_time_p95_s"] = float(np.percentile(solve_times_s, 95))
    else:
        k["solve_time_median_s"] = math.nan if solve_time_median_s is None else float(solve_time_median_s)
        k["solve_time_p95_s"] = math.nan if solve_time_p95_s is None else float(solve_time_p95_s)
    k["mass_balance_error"] = _mass_balance_error(frame)
    k["p80_final_um"] = float(p80[-1])
    k["p80_mean_um"] = float(np.nanmean(p80))
    k["energy_kwh"] = float(energy)
    k["fed_t"] = fed
    k["duration_h"] = float(t[-1])
    return k


def _mass_balance_error(frame: pd.DataFrame) -> float:
    if not {"fed_t", "produced_t", "holdup_t"} <= set(frame.columns):
        return math.nan
    h = frame["holdup_t"].to_numpy(float)
    err = frame["fed_t"].to_numpy(float) - frame["produced_t"].to_numpy(float) - (h - h[0])
    return float(np.abs(err).max() / (frame["fed_t"].iloc[-1] + h[0] + 1e-300))


def versions() -> dict:
    """Versions of Python and the libraries that shape a result."""
    import platform
    from importlib import metadata

    out = {"python": platform.python_version()}
    for pkg in ("grindtwin", "numpy", "pandas", "scipy", "casadi", "pydantic"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    try:
        import subprocess

        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parent, timeout=5)
        out["git"] = rev.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        out["git"] = None
    return out


def make_summary(scene: Scene, models: Models, kpis: dict, notes: list[str], wall_s: float) -> dict:
    """The JSON-able summary of a run."""
    plant_desc = None if models.plant is models.control else models.plant.model.describe()
    return {
        "scene": scene.scene.name,
        "description": scene.scene.description,
        "source": str(scene.source_path) if scene.source_path else None,
        "seed": scene.scene.seed,
        "controller": scene.controller.kind,
        "target_p80_um": scene.controller.target_p80_um,
        "load_band_frac": list(scene.controller.load_band_frac),
        "mode": "batch" if is_batch(scene) else ("open_loop" if scene.controller.kind == "none"
                                                  else "closed_loop"),
        "effects": list(scene.effects),
        "components": models.components,
        "kpis": kpis,
        "model": models.control.model.describe(),
        "plant_model": plant_desc,
        "notes": notes,
        "wall_time_s": wall_s,
        "versions": versions(),
    }


# --------------------------------------------------------------------------- replay
def replay_scene(scene_or_path, history_csv, out_dir=None, progress: bool = True, *,
                 duration_h: float | None = None, csv: bool = False, plots: bool = True) -> RunResult:
    """Drive a scene with a recorded history (CSV or Parquet; format in :mod:`scenarios.history`).

    The scene's ``feed.history`` is set to ``history_csv`` (its ``feed.blend`` and schedule are
    dropped) and the scene validated again, so the file is checked by the same rules.
    ``duration_h`` defaults to the history's span (the whole recording, on the scene's sample
    grid). Open loop (controller ``"none"``) the inputs are the recorded feed rate and speed
    where recorded; with a controller the controller chooses them. Either way the recorded
    columns (``recorded_feed_tph``, ``recorded_speed_frac_critical``, ``recorded_p80_um``) sit
    beside the run's own in the frame, and the summary's ``replay`` block compares them
    (mean and mean absolute differences, run minus recorded).
    """
    from scenarios.history import read_history

    scene = _as_scene(scene_or_path)
    history_path = Path(history_csv).resolve()
    data = scene.model_dump(exclude_none=True)
    data["feed"].pop("blend", None)
    data["feed"].pop("schedule", None)
    data["feed"]["history"] = str(history_path)
    if duration_h is None:
        dt = scene.scene.sample_period_h
        span = read_history(history_path, sample_period_h=dt,
                            max_gap_h=scene.feed.history_max_gap_h).span_h
        n = int(np.floor(span / dt + 1e-9))
        if n < 1:
            raise SceneError(f"{history_csv}: the history spans {span:g} h, less than one sample "
                             f"period ({dt:g} h) of the scene")
        duration_h = n * dt
    data["scene"]["duration_h"] = float(duration_h)
    src = scene.source_path
    new = scene_from_dict(data, src if src is not None else Path.cwd() / "scene.toml")
    result = run_scene(new, out_dir=None, progress=progress, replay=True)
    frame = result.frame
    cmp = {}
    for col in ("feed_tph", "speed_frac_critical", "p80_um"):
        rec = f"recorded_{col}"
        if rec in frame:
            diff = frame[col].to_numpy(float) - frame[rec].to_numpy(float)
            cmp[f"{col}_mean_diff"] = float(np.nanmean(diff))
            cmp[f"{col}_mean_abs_diff"] = float(np.nanmean(np.abs(diff)))
    result.summary["replay"] = {"history": str(history_csv), "run_minus_recorded": cmp}
    if out_dir is not None:
        from scenarios.outputs import write_run

        result.out_dir = write_run(result, out_dir, csv=csv, plots=plots)
    return result
