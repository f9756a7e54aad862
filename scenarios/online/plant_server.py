"""``grindtwin plant-server``: the scene's plant twin behind an OPC UA server, as a virtual plant
for commissioning ``grindtwin serve`` and for operator training.

The server holds every node of a tag map (:mod:`scenarios.online.tags`), as a plant's DCS would:
- each sample period (``sample_period_h / speedup`` wall-clock seconds, or :meth:`tick` in lock
  step) the twin advances one sample; a setpoint takes effect at the first scan mark (a share
  :data:`MIN_PIECE_FRAC` of a sample) after the plant time it was written (the input is
  piecewise constant between writes, as a feeder's setpoint is);
- the P80 analyser is :class:`mpc.SensorState` (noise, dead time, sampling and hold: the one
  analyser model of grindtwin); a value is published at each analyser report with its source
  timestamp; power and load carry their noise; the actual feed and speed are the inputs in
  effect; the belt analyser reports the blend ``lead_h`` before it reaches the mill;
- the plant starts at the steady state that holds the target P80 (as the in-process closed loop
  does) and, with ``hold_h``, runs that long at the initial blend before the scene's time 0;
- a watchdog: once the service's heartbeat has been seen, a heartbeat older than ``watchdog_h``
  while the mode is auto sheds the service (mode set to manual), as a DCS does;
- an instructor's analyser malfunction node (``Instructor.P80Fault``: none, bad, uncertain,
  frozen, stale), a freeze/run switch (``Simulation.Run``; ``paused`` starts frozen) and the
  speed-up (``Simulation.Speedup``), as operator training simulators have;
- the plant's true trajectory is recorded (``record_dir/plant.parquet``, the columns of
  :func:`mpc.run_closed_loop`'s frame) so a served run's KPIs are those of an in-process one;
  ``setpoint_applied_at_frac`` says how far into each sample its last setpoint write took effect
  (the in-process loop moves at the sample instant, 0).
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pandas as pd
from asyncua import ua
from asyncua.common.callback import CallbackType

from mpc import CLOSED_LOOP_READS, SensorState, TwinPlant, loop_kpis
from scenarios.errors import SceneError
from scenarios.online.clock import Clock, Stoppable, sleep_until
from scenarios.online.security import ServerSecurity, make_server
from scenarios.online.tags import TagMap
from scenarios.output import MANIFEST, replace_recorded_files, strangers
from scenarios.run import build_models
from scenarios.run.closed_loop import hold_schedule, plant_start, scene_sensors
from scenarios.run.feed import component_blend, feed_schedule
from scenarios.scene import Scene
from twin import json_text, nominal_pressure_kpa, temporaries_of, trajectory_notes

log = logging.getLogger("grindtwin.online.plant")

#: The virtual plant's namespace (its node ids are ``ns=2;...`` or ``nsu=<this>;...``).
NAMESPACE_URI = "urn:grindtwin:virtual-plant"
NAMESPACE_INDEX = 2  # the first namespace a server registers
#: The service is shed after this many sample periods without a heartbeat (default watchdog).
WATCHDOG_SAMPLES = 3
#: A setpoint takes effect at the next mark of this share of a sample after it was written, as a
#: DCS picks it up at its next scan (5 %: 9 s of a 3-minute sample). Each piece between marks
#: restarts the integrator (as costly as a whole sample), so a client writing many times a sample
#: cannot stall the plant; and the pieces are whole numbers of marks, so their integrators (one
#: per length, built in about a sample's integration time) are built once, not at every write.
MIN_PIECE_FRAC = 0.05
FAULTS = ("none", "bad", "uncertain", "frozen", "stale")
#: Nodes of the simulator itself, beside the tag map's.
SIM_NODES = {"time_h": "Simulation.Time_h", "p80_true_um": "Simulation.P80True_um",
             "speedup": "Simulation.Speedup", "run": "Simulation.Run", "fault": "Instructor.P80Fault"}
RECORD_FILES = ("plant.parquet", "plant-kpis.json")


@dataclass
class PlantServerSettings:
    """How the virtual plant runs."""

    url: str
    security: ServerSecurity
    speedup: float = 1.0
    hold_h: float = 0.0
    duration_h: float | None = None
    record_dir: Path | None = None
    record_every: int = 20
    watchdog_h: float | None = None
    initial_mode: str | int | None = None
    paused: bool = False
    seed: int | None = None
    """The analysers' noise seed (None: the scene's, as the in-process loop's default)."""


class PlantServer(Stoppable):
    """The scene's plant twin behind an OPC UA server with the nodes of ``tags``."""

    log_name = log.name

    def __init__(self, scene: Scene, tags: TagMap, settings: PlantServerSettings, models=None,
                 clock: Clock | None = None):
        self.scene, self.tags, self.s = scene, tags, settings
        self._check_record_dir()  # before the models are built: a refusal costs nothing
        self.clock = clock or Clock(settings.speedup)
        self.dt_h = scene.scene.sample_period_h
        self._node_ids = self._plant_node_ids(tags)
        models = models or build_models(scene)
        self.components = models.components
        feed, _ = feed_schedule(scene, self.components, scene.time_grid_h())
        self.schedule = hold_schedule(feed["time_h"].to_numpy(float), component_blend(feed, self.components), self.dt_h)
        ss = plant_start(scene, models, self.schedule(0.0))
        self.plant = TwinPlant(models.plant.model)
        self.x, self.u = np.asarray(ss.x, float).copy(), np.asarray(ss.u, float).copy()
        seed = scene.scene.seed if settings.seed is None else settings.seed
        self.sensor = SensorState(scene_sensors(scene), np.random.default_rng(seed))
        self.lead_h = tags.belt_analyser.lead_h if tags.belt_analyser is not None else 0.0
        self.watchdog_h = settings.watchdog_h or WATCHDOG_SAMPLES * self.dt_h
        auto = tags.mode.auto_value
        self.manual_value = "manual" if isinstance(auto, str) else (0 if auto != 0 else 1)
        self.mode = settings.initial_mode if settings.initial_mode is not None else auto
        self.t_h = self.t_start_h = -float(settings.hold_h)
        self.anchor = (self.clock.monotonic(), self.t_h)  # (monotonic clock [s], plant time [h]) of the last sample
        self.fault, self.frozen_value = "none", math.nan
        self.running = not settings.paused
        self.heartbeat_seen_h: float | None = None
        self.writes: list[tuple[float, int, float]] = []  # (plant time [h], input index, value)
        self.fed_t = self.produced_t = 0.0
        self.rows: list[dict] = []
        self._outside = False  # the last sample lay outside what the models describe (_say_validity)
        self._restores: set[asyncio.Task] = set()  # node write-backs of ignored setpoints (_apply_write)
        self.published: dict[str, ua.DataValue] = {}
        self.server = None
        self.stop_reason: str | None = None
        self._wake: asyncio.Event | None = None
        self._retimed = False  # the speed-up or run/freeze changed: the run loop re-times the sample
        self._built = False  # the integrators of every piece length (_build_integrators)
        self.applied_at_frac = math.nan  # when in the last sample its last setpoint write took effect (share)

    # ------------------------------------------------------------------ nodes
    @staticmethod
    def _plant_node_ids(tags: TagMap) -> dict[str, str]:
        """Role -> node id (``ns=2;...``) of every node the plant serves; SceneError for a node
        outside the plant's namespace or one that collides with the simulator's own."""
        roles = tags.read_roles() | tags.write_roles()
        out = {}
        for role, nid in roles.items():
            ns, rest = nid.split(";", 1)
            if ns not in (f"ns={NAMESPACE_INDEX}", f"nsu={NAMESPACE_URI}"):
                raise SceneError(f"tag map: {role}: the virtual plant serves node ids in ns={NAMESPACE_INDEX} "
                                 f"or nsu={NAMESPACE_URI} (got {nid!r})")
            out[role] = f"ns={NAMESPACE_INDEX};{rest}"
        for role, name in SIM_NODES.items():
            nid = f"ns={NAMESPACE_INDEX};s={name}"
            if nid in out.values():
                raise SceneError(f"tag map: node {nid!r} is the virtual plant's own {role} node; use another id")
            out[f"sim.{role}"] = nid
        return out

    async def start(self) -> None:
        """Build the server and its nodes (with the last published values) and listen."""
        server = await make_server(self.s.security)
        server.set_endpoint(self.s.url)
        server.set_server_name("grindtwin virtual plant")
        idx = await server.register_namespace(NAMESPACE_URI)
        if idx != NAMESPACE_INDEX:
            raise SceneError(f"the virtual plant's namespace got index {idx}, expected {NAMESPACE_INDEX}")
        folder = await server.nodes.objects.add_object(idx, "VirtualPlant")
        for role, nid in self._node_ids.items():
            value, vtype, writable = self._node_spec(role)
            var = await folder.add_variable(ua.NodeId.from_string(nid), nid.split("=", 2)[-1], value, vtype)
            if writable:
                await var.set_writable()
        server.subscribe_server_callback(CallbackType.PostWrite, self._on_write)
        self.server = server
        await asyncio.to_thread(self._build_integrators)
        if not self.published:  # the first sample, recorded too: the KPIs integrate from it
            vals = self._measure()
            self._publish(vals, self.clock.now())
            self._record(vals)
        for role, dv in self.published.items():
            await server.write_attribute_value(ua.NodeId.from_string(self._node_ids[role]), dv)
        await server.start()
        log.info("virtual plant %s serving at %s (%s), plant time %.3f h, speed-up %g", self.scene.scene.name,
                 self.s.url, "insecure" if self.s.security.insecure else "Basic256Sha256 SignAndEncrypt",
                 self.t_h, self.s.speedup)

    def _build_integrators(self) -> None:
        """Build now the integrator of every piece length a write can cut a sample into (whole
        scan marks), not at the first write that needs it: a build takes tens of times a sample's
        integration, and a sped-up plant would fall behind real time there (once built, each is
        cached by the twin's solver)."""
        if self._built:
            return
        t0 = time.perf_counter()
        marks = round(1 / MIN_PIECE_FRAC)
        d = self.plant.disturbance(self.t_h, self.schedule(max(self.t_h, 0.0)), 1.0)
        for dt_h in [self.dt_h] + [m * (self.dt_h / marks) for m in range(1, marks)]:
            self.plant.step(self.x, self.u.copy(), d, dt_h)  # the state is not advanced
        self._built = True
        log.info("the plant's integrators for %d piece lengths built in %.1f s", marks, time.perf_counter() - t0)

    def _node_spec(self, role: str):
        """(initial value, variant type, writable by clients) of a role's node."""
        if role == "mode":
            vt = ua.VariantType.String if isinstance(self.mode, str) else ua.VariantType.Int32
            return self.mode, vt, True
        if role.startswith("setpoints."):
            return float(self.u[0 if role.endswith("feed_tph") else 1]), ua.VariantType.Double, True
        if role == "heartbeat":
            return 0, ua.VariantType.UInt32, True
        if role == "sim.speedup":
            return float(self.clock.speedup), ua.VariantType.Double, True
        if role in ("status", "sim.fault"):
            return ("none" if role == "sim.fault" else ""), ua.VariantType.String, True
        if role == "sim.run":
            return self.running, ua.VariantType.Boolean, True
        return 0.0, ua.VariantType.Double, role.startswith("soft_sensor.")

    async def stop_server(self) -> None:
        """Stop the server for good (the plant's state is kept: :meth:`start` builds a new one)."""
        if self.server is not None:
            server, self.server = self.server, None
            await server.stop()
            log.info("virtual plant server stopped at plant time %.3f h", self.t_h)

    async def drop(self) -> None:
        """A network outage: every session closed and nothing listens; the plant runs on."""
        await self.server.bserver.stop()
        log.warning("%.3f h: virtual plant off the network", self.t_h)

    async def restore(self) -> None:
        """Back on the network after :meth:`drop`."""
        await self.server.bserver.start()
        log.warning("%.3f h: virtual plant back on the network", self.t_h)

    def _on_write(self, event, _dispatcher) -> None:
        """A client wrote: setpoints take effect now, mode and heartbeat are noted (PostWrite)."""
        t = self.plant_time()
        user = event.user.name or "anonymous"
        by_id = {nid: role for role, nid in self._node_ids.items()}
        for wv, res in zip(event.request_params.NodesToWrite, event.response_params):
            role = by_id.get(wv.NodeId.to_string())
            if role is None or not res.is_good():
                continue
            value = wv.Value.Value.Value if wv.Value.Value is not None else None
            self._apply_write(role, value, t, user)

    def _apply_write(self, role: str, value, t: float, user: str) -> None:
        if role.startswith("setpoints."):
            i = 0 if role.endswith("feed_tph") else 1
            ok = isinstance(value, float) and math.isfinite(value) and value > 0 and (i == 0 or value < 1)
            if ok:
                self.writes.append((t, i, value))
            else:
                log.error("%.3f h: %s wrote %s = %r: not a physical setpoint, the plant ignores it and its "
                          "node reads the setpoint in effect again", t, user, role, value)
                if self.server is not None:  # the write was answered Good (PostWrite): undo it on the node
                    kept = next((w[2] for w in reversed(self.writes) if w[1] == i), float(self.u[i]))
                    task = asyncio.get_running_loop().create_task(self.server.write_attribute_value(
                        ua.NodeId.from_string(self._node_ids[role]),
                        ua.DataValue(ua.Variant(kept, ua.VariantType.Double), ua.StatusCode(ua.StatusCodes.Good),
                                     self.clock.now())))
                    self._restores.add(task)  # held until done (the loop keeps only a weak reference)
                    task.add_done_callback(self._restores.discard)
        elif role == "heartbeat":
            self.heartbeat_seen_h = t
        elif role == "mode":
            log.info("%.3f h: %s set the mode to %r", t, user, value)
            self.mode = value
        elif role == "sim.fault":
            self.set_fault(str(value))
        elif role == "sim.speedup":
            if isinstance(value, float) and math.isfinite(value) and value > 0:
                self._retime(speedup=value)
                log.info("%.3f h: %s set the speed-up to x%g", t, user, value)
            else:
                log.error("%.3f h: %s wrote speed-up %r: must be a float > 0; ignored", t, user, value)
        elif role == "sim.run":
            self._retime(running=bool(value))
            log.info("%.3f h: %s %s the simulation", t, user, "runs" if self.running else "freezes")

    def set_fault(self, fault: str) -> None:
        """The instructor's P80 analyser malfunction (one of :data:`FAULTS`)."""
        if fault not in FAULTS:
            log.error("instructor fault %r is not one of %s; ignored", fault, FAULTS)
            return
        if fault == "frozen" and self.fault != "frozen":
            dv = self.published.get("p80_um")
            self.frozen_value = dv.Value.Value if dv is not None and dv.Value.Value is not None else math.nan
        log.warning("%.3f h: P80 analyser malfunction: %s", self.t_h, fault)
        self.fault = fault

    # ------------------------------------------------------------------ time
    def plant_time(self) -> float:
        """Plant time now (standing still while frozen), on the monotonic clock: on the wall clock, a step of it
        (NTP, an operator) moved the plant time of a client's write, stepped back 1 h a write half a sample in took
        effect at the sample's start."""
        m0, t0 = self.anchor
        return t0 + self.clock.hours_since(m0) if self.running else self.t_h

    def _retime(self, speedup: float | None = None, running: bool | None = None) -> None:
        """A new speed-up or run/freeze from now on: plant time so far counts at the old pace, and
        the run loop (woken) times the rest of the sample at the new one."""
        self.anchor = (self.clock.monotonic(), self.plant_time())
        if speedup is not None:
            self.clock.speedup = speedup
        if running is not None:
            self.running = running
        self._retimed = True
        if self._wake is not None:
            self._wake.set()

    def _next_sample(self, loop) -> tuple[float, datetime, float]:
        """(loop time, wall time, monotonic clock) of the next sample after :meth:`_retime`."""
        self._retimed = False
        self._wake.clear()
        left_h = self.t_h + self.dt_h - self.plant_time() if self.running else self.dt_h
        left_s = self.clock.wall_seconds(min(max(left_h, 0.0), self.dt_h))
        return loop.time() + left_s, self.clock.now() + timedelta(seconds=left_s), self.clock.monotonic() + left_s

    async def tick(self, wall: datetime | None = None, monotonic: float | None = None) -> None:
        """Advance one sample (``wall``, ``monotonic``: the wall-clock time, its source timestamps', and the
        monotonic clock's of the new sample instant; now when not given)."""
        t0, t1 = self.t_h, self.t_h + self.dt_h
        d = self.plant.disturbance(t0, self.schedule(max(t0, 0.0)), 1.0)
        marks = round(1 / MIN_PIECE_FRAC)
        gap = self.dt_h / marks

        def mark(tw: float) -> int:  # the first scan mark at or after a write (0: the sample's start)
            return max(0, math.ceil((tw - t0) / gap - 1e-9))  # 1e-9: a write on a mark is at it, not after

        # writes after the sample's last mark wait for the next sample (applied at t1, not before they came)
        pending = sorted(((mark(w[0]), w) for w in self.writes if mark(w[0]) < marks),
                         key=lambda mw: mw[0])  # stable: write order within a mark
        self.writes = [w for w in self.writes if mark(w[0]) >= marks]
        done = 0
        self.applied_at_frac = max((m for m, _ in pending), default=math.nan) / marks
        for m, (_, i, value) in pending:
            if m > done:
                await self._step(d, (m - done) * gap)
                done = m
            self.u[i] = value
        await self._step(d, self.dt_h if done == 0 else (marks - done) * gap)
        wall = wall or self.clock.now()
        self.t_h, self.anchor = t1, (self.clock.monotonic() if monotonic is None else monotonic, t1)
        vals = self._measure()
        self._publish(vals, wall)
        # the record (a file every record_every samples) before the sample is served: a client
        # that cycles on the new values then finds the server free
        self._record(vals)
        if self.server is not None:
            for role, dv in self.published.items():
                await self.server.write_attribute_value(ua.NodeId.from_string(self._node_ids[role]), dv)
            await self._watchdog()

    async def _step(self, d, dt_h: float) -> None:
        """Integrate in a worker thread (CasADi's integrator releases the GIL), so that the server
        answers reads while the plant moves."""
        self.x, fed, produced = await asyncio.to_thread(self.plant.step, self.x, self.u.copy(), d, dt_h)
        self.fed_t += fed
        self.produced_t += produced

    # ------------------------------------------------------------------ measurements
    def _measure(self) -> dict:
        blend = np.asarray(self.schedule(max(self.t_h, 0.0)), float)
        vals = self.plant.measure(self.x, self.u, self.plant.disturbance(self.t_h, blend, 1.0))
        # the analyser's clock starts with the plant (SensorState counts samples from its t = 0)
        new, held, pw, ld = self.sensor.make_step(self.t_h - self.t_start_h, vals["p80_um"],
                                                  *(vals[k] for k in CLOSED_LOOP_READS))
        return vals | {"p80_new": new, "p80_held": held, "power_meas_kw": pw, "load_meas_frac": ld, "blend": blend}

    def _publish(self, vals: dict, wall: datetime) -> None:
        """The data values of this sample (kept, for a server that restarts)."""
        def dv(value, code=ua.StatusCodes.Good, vt=ua.VariantType.Double):
            variant = ua.Variant(None, ua.VariantType.Null) if value is None else ua.Variant(value, vt)
            return ua.DataValue(variant, ua.StatusCode(code), wall)

        pub = {"power_kw": dv(vals["power_meas_kw"]), "load_frac": dv(vals["load_meas_frac"]),
               "feed_tph": dv(float(self.u[0])), "speed_frac_critical": dv(float(self.u[1])),
               "sim.time_h": dv(self.t_h), "sim.p80_true_um": dv(float(vals["p80_um"])),
               "sim.speedup": dv(float(self.clock.speedup))}
        future = np.asarray(self.schedule(max(self.t_h + self.lead_h, 0.0)), float)
        if self.tags.belt_analyser is not None:
            pub |= {f"blend.{c}": dv(float(f)) for c, f in zip(self.components, future)}
        pub = {k: v for k, v in pub.items() if k in self._node_ids}
        p80 = self._p80_value(vals, dv)
        if p80 is not None:
            pub["p80_um"] = p80
        self.published |= pub

    def _p80_value(self, vals: dict, dv):
        """The analyser's data value now under the instructor's fault (None: leave the node as is)."""
        if self.fault == "bad":
            return dv(None, ua.StatusCodes.BadSensorFailure)
        if self.fault == "stale":
            return None
        if not math.isfinite(vals["p80_new"]):  # no new report: the node keeps the last one
            return None if "p80_um" in self.published else dv(None, ua.StatusCodes.BadWaitingForInitialData)
        if self.fault == "frozen":
            return dv(float(self.frozen_value))
        code = ua.StatusCodes.UncertainSensorNotAccurate if self.fault == "uncertain" else ua.StatusCodes.Good
        return dv(float(vals["p80_new"]), code)

    async def _watchdog(self) -> None:
        """Shed the service (mode manual) when its heartbeat stops while in auto."""
        if self.heartbeat_seen_h is None or self.mode != self.tags.mode.auto_value:
            return
        quiet = self.t_h - self.heartbeat_seen_h
        if quiet > self.watchdog_h:
            log.error("%.3f h: watchdog: no heartbeat from the service for %.3g h (limit %.3g h): mode set to %r, "
                      "the setpoints stay where they are", self.t_h, quiet, self.watchdog_h, self.manual_value)
            self.mode, self.heartbeat_seen_h = self.manual_value, None
            vt = ua.VariantType.String if isinstance(self.manual_value, str) else ua.VariantType.Int32
            await self.server.write_attribute_value(ua.NodeId.from_string(self._node_ids["mode"]), ua.DataValue(
                ua.Variant(self.manual_value, vt), ua.StatusCode(ua.StatusCodes.Good), self.clock.now()))

    # ------------------------------------------------------------------ record
    def _record(self, vals: dict) -> None:
        p80_pub = self.published.get("p80_um")
        self.rows.append({
            "time_h": self.t_h, "feed_tph": float(self.u[0]), "speed_frac_critical": float(self.u[1]),
            "p80_um": vals["p80_um"], "p80_measured_um": p80_pub.Value.Value if p80_pub and p80_pub.Value.Value
            is not None else math.nan, "p80_target_um": float(self.scene.controller.target_p80_um or math.nan),
            **{k: vals[k] for k in ("power_kw", "load_frac", "throughput_tph", "specific_energy_kwh_t", "holdup_t",
                                    "power_meas_kw", "load_meas_frac")},
            "fed_t": self.fed_t, "produced_t": self.produced_t,
            **{f"blend_{c}_frac": float(b) for c, b in zip(self.components, vals["blend"])},
            "hardness_scale": 1.0, "mode": str(self.mode), "p80_fault": self.fault,
            "setpoint_applied_at_frac": self.applied_at_frac,
            "solve_time_s": math.nan, "fallback": None})
        self._say_validity(self.rows[-1])
        if self.s.record_dir is not None and len(self.rows) % self.s.record_every == 0:
            self.write_record()

    def _say_validity(self, row: dict) -> None:
        """Log when the plant leaves (and re-enters) what its models describe, as a run warns
        (:func:`twin.trajectory_notes`: hold-up past the shell, a centrifuging speed)."""
        spec = self.plant.model.spec
        notes = trajectory_notes(pd.DataFrame([row]), spec, self.plant.model.effect_names,
                                 nominal_pressure_kpa=nominal_pressure_kpa(self.plant.model))
        if notes and not self._outside:
            log.warning("%.3f h: the plant left what its models describe: %s", self.t_h, "; ".join(notes))
        elif self._outside and not notes:
            log.info("%.3f h: the plant is back within what its models describe", self.t_h)
        self._outside = bool(notes)

    def _check_record_dir(self) -> None:
        """A new folder, or one this command wrote (its manifest lists every file, each as written): a file
        of the user's named like a record's, or a record edited since, was replaced (it was known by name)."""
        d = self.s.record_dir
        if d is None:
            return
        d = Path(d)
        if d.exists():
            others = strangers(d, also=tuple(temporaries_of(d, (*RECORD_FILES, MANIFEST)))) if d.is_dir() else [d.name]
            if others:
                raise SceneError(f"--record {d}: must be a new folder or one this command wrote, as it wrote it (it "
                                 f"holds {', '.join(others[:5])}, which it did not write or which changed since)")
        if d.is_dir() and any(d.iterdir()):
            log.warning("--record %s: the recording it holds is replaced by this one when it ends", d)

    def frame(self) -> pd.DataFrame:
        return pd.DataFrame(self.rows)

    def kpis(self) -> dict:
        """KPIs of the recorded run from the scene's time 0 (:func:`mpc.loop_kpis`). A row holds the
        inputs in effect at its time, the end of the sample before; the in-process frame's row holds
        the inputs applied from its time on (its feed is integrated forward), so the inputs are the
        next row's here (the last row keeps its own)."""
        f = self.frame()
        for c in ("feed_tph", "speed_frac_critical"):
            f[c] = f[c].shift(-1).fillna(f[c])
        f = f[f["time_h"] >= -1e-9].reset_index(drop=True)
        k = loop_kpis(f, tuple(self.scene.controller.load_band_frac)) if len(f) > 1 else {}
        return {key: v for key, v in k.items() if not key.startswith(("solve_time", "fallback"))}

    def write_record(self) -> None:
        """The record's files and manifest, each renamed into place (the server may be stopped mid-write, a
        reader may open them any time), so that a stop at any point leaves a folder the next --record takes."""
        frame, kpis = self.frame(), self.kpis()
        Path(self.s.record_dir).mkdir(parents=True, exist_ok=True)  # at the end: a stop while building left it empty
        replace_recorded_files(Path(self.s.record_dir), "plant-record", {
            "plant.parquet": lambda path: frame.to_parquet(path, index=False),
            # an undefined KPI (NaN: the specific energy of a run that fed nothing) is null, as in summary.json: the
            # text NaN is no JSON
            "plant-kpis.json": lambda path: path.write_text(json_text(kpis, indent=2), encoding="utf-8")})

    # ------------------------------------------------------------------ run
    async def run(self, install_signal_handlers: bool = True) -> None:
        """Serve and advance in (sped-up) real time until stopped (SIGTERM, SIGINT) or ``duration_h``;
        then stop the server and write the record (a second signal meanwhile changes nothing)."""
        loop = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        signals = self.stop_on_signals(loop, install_signal_handlers)
        started = False
        try:
            await self.start()
            started = True
            period = self.clock.wall_seconds(self.dt_h)
            next_t, next_wall = loop.time() + period, self.clock.now() + timedelta(seconds=period)
            next_mono = self.clock.monotonic() + period  # the sample instant on the plant's clock
            while self.stop_reason is None:
                if await sleep_until(next_t, self._wake):
                    if self.stop_reason is None and self._retimed:  # a new speed-up or run/freeze
                        next_t, next_wall, next_mono = self._next_sample(loop)
                    continue
                period = self.clock.wall_seconds(self.dt_h)
                if loop.time() - next_t > period:
                    log.warning("the virtual plant fell %.2f s behind real time (x%g); its clock restarts from now",
                                loop.time() - next_t, self.clock.speedup)
                    next_t, next_wall, next_mono = loop.time(), self.clock.now(), self.clock.monotonic()
                wall, mono = next_wall, next_mono
                next_t, next_mono = next_t + period, next_mono + period
                next_wall += timedelta(seconds=period)
                if not self.running:  # frozen: plant time stands still
                    self.anchor = (mono, self.t_h)
                    continue
                await self.tick(wall, mono)
                if self.s.duration_h is not None and self.t_h >= self.s.duration_h - 1e-9:
                    self.request_stop(f"duration {self.s.duration_h:g} h reached")
        finally:
            try:
                await self.stop_server()
                if self.s.record_dir is not None and started:  # a start that failed (a port in use) replaced
                    self.write_record()                        # the folder's last recording with one empty row
                log.info("virtual plant stopped (%s) at plant time %.3f h", self.stop_reason or "ended", self.t_h)
            finally:  # only now: a second signal while stopping must not cut the stop short (it asks again)
                for sig in signals:
                    loop.remove_signal_handler(sig)
