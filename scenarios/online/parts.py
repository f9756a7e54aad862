"""What a served scene runs on, built once before anything connects: the scene's twins, its
NMPC and EKF wired as the in-process closed loop wires them (:mod:`scenarios.run.closed_loop`),
the ores' mineralogies and the soft sensor."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from scenarios.run import build_models
from scenarios.run.closed_loop import check_rk4_substeps, make_controller, make_estimator
from scenarios.run.feed import component_blend, feed_schedule
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


def initial_blend(scene: Scene, components: list[str]) -> np.ndarray:
    """The scene's blend at t = 0 as component fractions."""
    feed, _ = feed_schedule(scene, components, np.array([0.0]))
    return component_blend(feed, components)[0]


def build_parts(scene: Scene, soft_sensor: bool = False, surrogate: bool = False) -> ControlParts:
    """Build the controller's twin, NMPC and EKF for ``scene`` (and the soft sensor)."""
    models = build_models(scene)
    blend0 = initial_blend(scene, models.components)
    css = models.control.steady(feed_tph=scene.feed.feed_tph, speed_frac_critical=scene.feed.speed_frac_critical,
                                blend=blend0)
    check_rk4_substeps(scene, models.control.model, css)
    ores = component_ores(scene)
    soft = SoftSensor(models.control, ores, scene.mill.preset, with_surrogate=surrogate) if soft_sensor else None
    return ControlParts(scene, models, make_controller(scene, models.control),
                        make_estimator(scene, models.control, css), ores, blend0, soft)
