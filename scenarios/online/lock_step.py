"""The served loop in lock step: the virtual plant and the service over OPC UA on loopback, on one
manual clock, so a served run can be set beside the in-process loop of the same seed
(:func:`scenarios.online.run_in_process`) with no wall-clock timing in it."""

from __future__ import annotations

import socket
from pathlib import Path

from scenarios.online.clock import ManualClock
from scenarios.online.parts import ControlParts
from scenarios.online.plant_server import PlantServer, PlantServerSettings
from scenarios.online.security import ClientSecurity, ServerSecurity
from scenarios.online.service import ServeSettings, Service
from scenarios.online.tags import TagMap
from scenarios.run.closed_loop import ESTIMATOR_WARMUP_H


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def run_lock_step(parts: ControlParts, tags: TagMap, seed: int, audit_dir: Path,
                        warmup_h: float = ESTIMATOR_WARMUP_H, late_frac: float = 0.0) -> PlantServer:
    """Serve ``parts.scene`` on its virtual plant (analysers' noise ``seed``, held ``warmup_h``
    before time 0 while the estimator warms up, as in process) to the scene's end, each cycle
    ``late_frac`` of a sample after the plant's sample (0: at it, the in-process loop's timing);
    returns the plant (its :meth:`~PlantServer.kpis` and :meth:`~PlantServer.frame`). The parts
    are reset before and after."""
    if not 0.0 <= late_frac < 1.0:
        raise ValueError(f"The 'late_frac' of run_lock_step must be in [0, 1). Got {late_frac!r}.")
    scene, dt = parts.scene, parts.scene.scene.sample_period_h
    parts.reset()
    clock, url = ManualClock(), f"opc.tcp://127.0.0.1:{_free_port()}"
    plant = PlantServer(scene, tags, PlantServerSettings(url, ServerSecurity(insecure=True), hold_h=warmup_h,
                                                         seed=seed), models=parts.models, clock=clock)
    service = Service(parts, tags, ServeSettings(url, ClientSecurity(insecure=True), audit_dir, warmup_h=warmup_h),
                      clock=clock)
    await plant.start()
    try:
        await service.connect()
        await service.cycle()  # the estimator starts with the plant's hold, as in process
        for _ in range(round((warmup_h + scene.scene.duration_h) / dt)):
            clock.advance(dt * (1 - late_frac))
            await plant.tick()
            clock.advance(dt * late_frac)
            await service.cycle()
        await service.shutdown("end of the scene")
    finally:
        await plant.stop_server()
        parts.reset()
    return plant
