"""What a run would refuse, found before it starts: ``grindtwin check`` runs all of it, a run the
part that needs no models before it claims its output folder and the rest once its models are
built, before any simulation.

- **Settings** (no models needed): the NMPC's settings as :class:`mpc.NmpcSettings` accepts
  them (solver and QP solver combinations, bounds), each refusal under its scene key.
- **Models**: the twins are built (an effect option the effect refuses, a model the twin cannot
  assemble); the controller's NLP must fit in memory (:func:`nmpc_build_bytes` against
  :data:`NMPC_BUILD_MEMORY_LIMIT_GB`: a model too large is refused with its size and the fix);
  the closed loop's start exists (a feed rate that holds the target) and the RK4 sub-steps are
  stable there. The memory estimate is for the NMPC as built now (RTI's stage-wise compiled QP
  data, the exact-Hessian NLP of the others): benchmarks/mpc_nmpc_build.py measures it.

``check`` also notes (warns, :class:`mpc.OutsideModelsWarning`, and still says OK) the speeds a
scene lets the plant run at that the twin's models do not describe (:func:`speed_notes`), as
``steady`` notes such a speed and a run warns of it.
"""

from __future__ import annotations

import re
import warnings

from mpc import CLOSED_LOOP_READS, MpcInputError, OutsideModelsWarning, speed_max_note
from scenarios.errors import RunError, SceneError
from scenarios.run.closed_loop import check_rk4_substeps, loop_start, nmpc_settings, schedule_blends
from scenarios.run.feed import component_blend, feed_schedule
from scenarios.run.models import build_models, component_ores, is_batch
from scenarios.scene import Scene, check_scene as check_scene_file, load_scene
from twin import SPEED_FACTOR_ZERO_FRAC_CRITICAL, TwinError, blend_density_t_m3, centrifuging_note

#: NmpcSettings field -> the scene key it comes from (scenarios.run.closed_loop.nmpc_settings).
NMPC_KEYS = {
    "target_p80_um": "controller.target_p80_um", "horizon_steps": "controller.horizon_steps",
    "dt_h": "scene.sample_period_h", "move_block": "controller.move_block",
    "rk4_substeps": "controller.rk4_substeps", "weight_p80": "controller.weights.p80",
    "weight_du_feed": "controller.weights.du_feed", "weight_du_speed": "controller.weights.du_speed",
    "weight_energy": "controller.weights.energy", "feed_tph_min": "controller.bounds.feed_tph_min",
    "feed_tph_max": "controller.bounds.feed_tph_max", "speed_min": "controller.bounds.speed_min",
    "speed_max": "controller.bounds.speed_max",
    "feed_rate_max_tph_per_h": "controller.bounds.feed_rate_max_tph_per_h",
    "speed_rate_max_per_h": "controller.bounds.speed_rate_max_per_h",
    "load_band_frac": "controller.load_band_frac", "power_max_kw": "controller.power_max_kw",
    "solver": "controller.solver", "qpsol": "controller.qpsol"}

#: Memory the build of IPOPT, SQP and fatrop takes per unit of (operations of the model's
#: right-hand side x states x RK4 steps per sample x horizon stages) [bytes]: the whole
#: horizon's shooting constraints are expanded to scalar expressions and differentiated twice.
#: Measured by benchmarks/mpc_nmpc_build.py (results/mpc_nmpc_build.md): the largest ratio,
#: 1221, with ~15 % margin for models between those measured.
NLP_BUILD_BYTES_PER_UNIT = 1400
#: RTI builds one stage's QP data (compiled, mpc.codegen) and maps it over the horizon: bytes
#: per (operations x states x RK4 steps) for the stage and per (states^2 x horizon stage) for the
#: QP's matrices; the same benchmark's largest values (85 and 362) with ~10-20 % margin.
RTI_STAGE_BYTES_PER_UNIT = 100
RTI_BYTES_PER_STATE2_STAGE = 400
#: A controller whose build is estimated above this is refused before it is built: IPOPT on the
#: full 25-class grid at horizon 60 asked for more than 20 GB and was killed (issue 14).
NMPC_BUILD_MEMORY_LIMIT_GB = 4.0


def nmpc_build_bytes(model, horizon_steps: int, rk4_substeps: int, solver: str) -> float:
    """Estimated memory [bytes] the NMPC's build takes for ``model`` (see the module docstring)."""
    stage = model.n_instructions * model.n_x * rk4_substeps
    if solver == "rti":
        return RTI_STAGE_BYTES_PER_UNIT * stage + RTI_BYTES_PER_STATE2_STAGE * model.n_x ** 2 * horizon_steps
    return NLP_BUILD_BYTES_PER_UNIT * stage * horizon_steps


def settings_problems(scene: Scene) -> list[str]:
    """The controller settings the NMPC refuses, as ``key.path: why`` messages."""
    if scene.controller.kind != "nmpc":
        return []
    try:
        nmpc_settings(scene)
    except MpcInputError as exc:
        m = re.search(r"The '(\w+)' parameter", str(exc))
        key = NMPC_KEYS.get(m.group(1), "controller") if m else "controller"
        return [f"{key}: {exc}"]
    return []


def speed_notes(scene: Scene) -> list[str]:
    """The speeds the scene sets beyond where the charge centrifuges (twin.CENTRIFUGING_FRAC_CRITICAL),
    each naming its key, value and the limit: ``feed.speed_frac_critical`` (held open loop, a
    closed loop's start) and an NMPC's ``controller.bounds.speed_max`` (the speeds it may plan);
    call it on settings :func:`settings_problems` accepts."""
    speed = scene.feed.speed_frac_critical
    notes = [f"feed.speed_frac_critical = {speed:g}: {centrifuging_note(speed)}"] if centrifuging_note(speed) else []
    if scene.controller.kind == "nmpc":
        notes += [n for n in [speed_max_note(nmpc_settings(scene), NMPC_KEYS["speed_max"])] if n]
    return notes


def model_size_problems(scene: Scene, models) -> list[str]:
    """A batch charge the mill cannot hold, and the controller's NLP if its build is estimated
    above the memory limit."""
    return (_slow_speed_problems(scene, models) + _batch_charge_problems(scene, models)
            + _plant_output_problems(scene, models) + _nlp_size_problems(scene, models))


def _slow_speed_problems(scene: Scene, models) -> list[str]:
    """Speeds at or below twin.SPEED_FACTOR_ZERO_FRAC_CRITICAL for a plant with the ``speed``
    effect: every breakage rate is zero there and negative below, and the run failed in the
    solver. ``feed.speed_frac_critical`` (held, or a closed loop's start) and an NMPC's
    ``controller.bounds.speed_min`` (the speeds it may plan)."""
    return _slow_speeds(scene, getattr(getattr(models.plant, "model", None), "effect_names", ()))


def _slow_speeds(scene: Scene, effects) -> list[str]:
    if "speed" not in effects:
        return []
    speeds = {"feed.speed_frac_critical": scene.feed.speed_frac_critical}
    if scene.controller.kind == "nmpc":
        speeds[NMPC_KEYS["speed_min"]] = nmpc_settings(scene).speed_min
    return [f"{key}: {v:g} {_SLOW_SPEED}" for key, v in speeds.items()
            if v is not None and v <= SPEED_FACTOR_ZERO_FRAC_CRITICAL]


_SLOW_SPEED = (f"is at or below {SPEED_FACTOR_ZERO_FRAC_CRITICAL:g} of critical, where the breakage rates of the speed "
               f"effect (Austin et al. 1984, eq. 8.4) are zero, and negative below; allowed: above "
               f"{SPEED_FACTOR_ZERO_FRAC_CRITICAL:g}")


def replay_speed_problems(scene: Scene, models, feed) -> list[str]:
    """:func:`_slow_speed_problems` of the recorded speeds a replay drives (``feed``: the feed table on the
    sample grid): the history's own checks allow any speed in (0, 1), and a replay through a stop failed
    in the solver after the run had started."""
    effects = getattr(getattr(models.plant, "model", None), "effect_names", ())
    if "speed" not in effects or "recorded_speed_frac_critical" not in feed:
        return []
    speed = feed["recorded_speed_frac_critical"].to_numpy(float)
    slow = speed <= SPEED_FACTOR_ZERO_FRAC_CRITICAL
    if not slow.any():
        return []
    t = feed["time_h"].to_numpy(float)[slow]
    return [f"feed.history {scene.history_path()}: column speed_frac_critical: {speed[slow].min():g} (the lowest "
            f"sample-period mean; {int(slow.sum())} samples from t = {t[0]:g} h to {t[-1]:g} h) {_SLOW_SPEED}; a "
            "stopped mill cannot be replayed: replay the history before or after the stop"]


def _plant_output_problems(scene: Scene, models) -> list[str]:
    """A closed loop whose plant model lacks an output its sensors read (a plant.effects without
    ``power``, say): it failed after the build with a bare KeyError."""
    outputs = getattr(getattr(models.plant, "model", None), "outputs", None)
    if scene.controller.kind == "none" or is_batch(scene) or outputs is None:
        return []
    missing = [k for k in CLOSED_LOOP_READS if k not in outputs]
    if not missing:
        return []
    key = "plant.effects" if scene.plant is not None and scene.plant.effects is not None else "effects"
    return [f"{key}: a closed loop reads the plant's {' and '.join(missing)} every sample (its sensors and KPIs); "
            f"the plant's effects {list(models.plant.model.effect_names)} give no {', '.join(missing)}: add the effect "
            "that does (power: 'power'; load: 'holdup')"]


def _batch_charge_problems(scene: Scene, models) -> list[str]:
    """A batch charge beyond what the plant's mill holds filled to its shell
    (:meth:`twin.Mill.max_holdup_t`): no mill grinds it, and its numbers would be the model's."""
    plant = models.plant
    if not is_batch(scene) or getattr(plant, "mill", None) is None:
        return []
    feed, _ = feed_schedule(scene, models.components, scene.time_grid_h()[:1], component_ores(scene))
    shares = component_blend(feed, models.components)[0]  # the charge's blend
    capacity_t = plant.mill.max_holdup_t(blend_density_t_m3(plant.spec, shares))  # at the charge's own density
    charge_t = scene.feed.batch_charge_kg / 1000.0
    if charge_t <= capacity_t:
        return []
    return [f"feed.batch_charge_kg: {scene.feed.batch_charge_kg:g} kg is more than the mill holds filled to its "
            f"shell around its balls ({1000.0 * capacity_t:.4g} kg of this ore); allowed: up to "
            f"{1000.0 * capacity_t:.4g} kg"]


def _nlp_size_problems(scene: Scene, models) -> list[str]:
    """The controller's NLP, if its build is estimated above the memory limit."""
    c = scene.controller
    if c.kind != "nmpc":
        return []
    need = nmpc_build_bytes(models.control.model, c.horizon_steps, c.rk4_substeps, c.solver)
    if need <= NMPC_BUILD_MEMORY_LIMIT_GB * 2**30:
        return []
    m = models.control.model
    grid = scene.mill.size_classes
    fix = ["coarsen the controller's model (mill.size_classes, e.g. { ratio = 2.5, count = 7 }, or "
           "fewer mill.n_mixers) and keep the full grid for the plant in [plant]",
           "shorten controller.horizon_steps"]
    if c.solver != "rti":
        rti = nmpc_build_bytes(m, c.horizon_steps, c.rk4_substeps, "rti")
        fix.append(f'use controller.solver = "rti" (a Gauss-Newton QP per sample: about {rti / 2**30:.2g} GB)')
    return [f"controller: the NMPC's model is too large to build: {m.n_x} states ({m.n_components} ores x "
            f"{m.spec.n_mixers} mixers x {grid.count} size classes, {m.n_instructions} operations) x "
            f"horizon {c.horizon_steps} x {c.rk4_substeps} RK4 steps with solver {c.solver!r} needs about "
            f"{need / 2**30:.3g} GB, above the limit of {NMPC_BUILD_MEMORY_LIMIT_GB:g} GB; "
            + "; or ".join(fix)]


def start_problems(scene: Scene, models) -> list[str]:
    """A closed loop without a start (no feed holds the target) or with unstable RK4 sub-steps."""
    if scene.controller.kind == "none" or is_batch(scene):
        return []
    feed, _ = feed_schedule(scene, models.components, scene.time_grid_h()[:1], component_ores(scene))
    try:
        start = loop_start(scene, models, component_blend(feed, models.components)[0])
        if scene.controller.kind == "nmpc":
            check_rk4_substeps(scene, models.control, start.control, schedule_blends(scene, models))
    except (SceneError, RunError, TwinError) as exc:
        return [f"{scene.source_path or scene.scene.name}: the closed loop cannot start: {exc}"]
    return []


def check_scene(path) -> list[str]:
    """Every problem ``grindtwin check`` reports for a scene file: the file's own
    (:func:`scenarios.scene.check_scene`: schema and cross-field checks), then, when the file is
    valid, everything the run would refuse (this module's checks, with the models built). Speeds
    the models do not describe are warned, not returned (:func:`speed_notes`)."""
    problems = check_scene_file(path)
    if problems:
        return problems
    scene = load_scene(path)
    problems = [f"{path}: {m}" for m in settings_problems(scene)]
    if problems:
        return problems
    for note in speed_notes(scene):
        warnings.warn(f"{path}: {note}", OutsideModelsWarning, stacklevel=2)
    return built_problems(scene, f"{path}: ")


def run_problems(scene: Scene) -> list[str]:
    """Everything a run of ``scene`` refuses before it simulates: its settings, else what
    :func:`built_problems` finds (a sweep checks each case so before any runs)."""
    return settings_problems(scene) or built_problems(scene)


def built_problems(scene: Scene, prefix: str = "") -> list[str]:
    """What a run of ``scene`` (its settings accepted) refuses once its models are built: the twins'
    own refusals, then :func:`model_size_problems` (each after ``prefix``), else :func:`start_problems`."""
    try:
        models = build_models(scene)
    except SceneError as exc:
        return [str(exc)]
    return [prefix + m for m in model_size_problems(scene, models)] or start_problems(scene, models)


def refuse(scene: Scene, problems: list[str]) -> None:
    """SceneError listing ``problems`` (nothing if there are none)."""
    if problems:
        where = scene.source_path or scene.scene.name
        raise SceneError(f"{where}: " + f"\n{where}: ".join(problems))
