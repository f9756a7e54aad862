"""What a served scene runs on, built once before anything connects: the scene's twins, its
NMPC and EKF wired as the in-process closed loop wires them (:mod:`scenarios.run.closed_loop`),
the ores' mineralogies and the soft sensor."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mpc import ClosedLoopResult, FixedInputs, LoopSettings, run_closed_loop
from scenarios.run import build_models
from scenarios.run.closed_loop import (ESTIMATOR_WARMUP_H, check_rk4_substeps, hold_schedule, make_controller,
                                       make_estimator, plant_start, scene_sensors, schedule_blends)
from scenarios.run.feed import component_blend, feed_schedule, initial_blend
from scenarios.run.models import component_ores
from scenarios.online.soft_sensor import SoftSensor
from scenarios.scene import Scene


@dataclass
class ControlParts:
    """The scene's models (``models.control`` the controller's twin), NMPC, EKF, ores
    (component name -> Mineralogy, component order), initial blend and soft sensor."""

    scene: Scene
    models: Any
    controller: Any
    estimator: Any
    ores: dict
    blend0: np.ndarray
    soft_sensor: SoftSensor | None = None

    def reset(self) -> None:
        """Forget every run's state (the controller's warm start, the estimate)."""
        self.controller.reset()
        self.estimator.reset()


def build_parts(scene: Scene, soft_sensor: bool = False, surrogate: bool = False) -> ControlParts:
    """Build the controller's twin, NMPC and EKF for ``scene`` (and the soft sensor)."""
    models = build_models(scene)
    blend0 = initial_blend(scene, models.components)
    css = models.control.steady(feed_tph=scene.feed.feed_tph, speed_frac_critical=scene.feed.speed_frac_critical,
                                blend=blend0)
    check_rk4_substeps(scene, models.control, css, schedule_blends(scene, models))
    ores = component_ores(scene)
    soft = SoftSensor(models.control, ores, scene.mill.preset, with_surrogate=surrogate) if soft_sensor else None
    return ControlParts(scene, models, make_controller(scene, models.control),
                        make_estimator(scene, models.control, css), ores, blend0, soft)


def run_in_process(parts: ControlParts, seed: int, warmup_h: float = ESTIMATOR_WARMUP_H,
                   no_control: bool = False) -> ClosedLoopResult:
    """The scene's closed loop in process on these parts (:func:`mpc.run_closed_loop` wired as
    :mod:`scenarios.run.closed_loop` wires it: plant start, schedule, sensors, EKF start), with a
    sensor seed and warm-up of one's own; ``no_control`` holds the start's inputs. The reference a
    served run is compared with. The parts are reset before and after."""
    scene, m = parts.scene, parts.models
    feed, _ = feed_schedule(scene, m.components, scene.time_grid_h())
    blend = component_blend(feed, m.components)
    schedule = hold_schedule(feed["time_h"].to_numpy(float), blend, scene.scene.sample_period_h)
    ss = plant_start(scene, m, blend[0])
    css = m.control.steady(feed_tph=float(ss.u[0]), speed_frac_critical=float(ss.u[1]), blend=blend[0])
    parts.controller.reset()
    parts.estimator.reset(css.x)
    c = scene.controller
    settings = LoopSettings(scene.scene.duration_h, scene.scene.sample_period_h, seed=seed,
                            preview_lead_h=c.preview_lead_h, target_p80_um=c.target_p80_um,
                            load_band=tuple(c.load_band_frac), estimator_warmup_h=0.0 if no_control else warmup_h)
    controller, estimator = (FixedInputs(ss.u), None) if no_control else (parts.controller, parts.estimator)
    try:
        return run_closed_loop(m.plant.model, controller, estimator, schedule, scene_sensors(scene), ss.x, ss.u,
                               settings)
    finally:
        parts.reset()
