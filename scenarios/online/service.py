"""``grindtwin serve``: the scene's estimator and NMPC against a live plant over OPC UA.

One cycle every sample period (``sample_period_h / speedup`` wall-clock seconds), on the
service's timer or, with the tag map's ``[cycle] on_new``, as soon as the plant publishes a new
value of that measurement (the timer stands in when none comes):
1. read every tag of the map in one request (values, status codes, source timestamps);
2. judge each reading (:mod:`scenarios.online.quality`): usable, or bad (a Bad status code, or a
   value outside its plausible range, :func:`scenarios.online.tags.plausible_range`) / uncertain /
   stale / frozen; an unusable reading is not used (the modes below say what stands in);
3. estimate: the EKF predicts over the last period with the actual inputs and the blend that
   entered the mill (the belt analyser's reading ``lead_h`` ago), and updates with the usable
   measurements (a P80 only when the analyser reported a new one);
4. solve: the NMPC from the estimate, the belt's preview and the actual inputs;
5. write the setpoints (limited again at the writer, :mod:`scenarios.online.writer`), the
   heartbeat and the status in one request; then the soft sensor's predictions.
Each cycle is a row of the audit log (:mod:`scenarios.online.audit`) with its mode and reason;
times in the log and the audit (``service_time_h``) are plant hours since the service started, on
the monotonic clock: a step of the wall clock (NTP, an operator) is logged and moves neither them
nor the estimator (readings' ages are judged on the wall clock, their source timestamps' own).

Modes (each change logged):
- ``warmup``: for ``warmup_h`` after the estimator starts it estimates and writes only the
  heartbeat (as the in-process loop warms its EKF up on the running plant);
- ``auto``: the controller's move is written, unless it is ready only once the next sample has
  begun (a solve that overran its sample): then it is discarded and the plant keeps the last setpoints;
- ``manual`` (the mode node is not ``auto_value``, or unreadable): nothing is written; the
  controller runs with the actual inputs as its last inputs, so the first move back in auto
  starts where the operator left the plant (bumpless);
- ``hold``: nothing is written (the plant keeps the last setpoints) while the P80 has been
  unusable for longer than ``fallback.p80_hold_after_h`` (until then the controller runs on its
  model), the actual inputs for longer than ``fallback.inputs_hold_after_h`` (until then the
  last written setpoints stand in for them), the estimator or controller failed, or on taking over an
  actual input lies outside its bounds by more than a sample's rate limit (the first move would jump);
- ``disconnected``: the estimator predicts with the last written setpoints, which the plant
  keeps; a task reconnects with exponential back-off.
SIGTERM or SIGINT ends the service after the running cycle: only the status is written, the
audit flushed, and the log names the setpoints left in the plant; a second signal while it stops
changes nothing. ``grindtwin serve`` then exits 0, a clean stop to a service manager.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from asyncua import ua

from mpc import MpcError
from scenarios.online.audit import AuditLog
from scenarios.online.clock import Clock, Stoppable, sleep_until
from scenarios.online.opcua import CONNECTION_ERRORS, NodeError, PlantConnection, Trigger, status_name
from scenarios.online.parts import ControlParts
from scenarios.online.quality import BAD, GOOD, Reading, TagQuality, Verdict, raw_number, severity
from scenarios.online.security import ClientSecurity
from scenarios.online.tags import TagMap, blend_range, plausible_range, setpoint_range, source_period_h
from scenarios.online.writer import Limit, limit_move
from scenarios.run.closed_loop import ESTIMATOR_WARMUP_H
from twin import TwinError, power_kw

log = logging.getLogger("grindtwin.online.service")

INPUTS = ("feed_tph", "speed_frac_critical")
#: A turning mill draws its ball charge's power (Bond's power is the balls'): a power reading below this fraction
#: of the control model's at the actual speed is Bad (a reading in MW, 0.163 for 163 kW, was Good: the physical
#: range starts at a stopped mill's 0); a charge worn to a tenth of its balls is no operating mill either.
POWER_TURNING_MIN_FRAC = 0.1
#: A weigh feeder's own loop holds the feed at its setpoint: an actual feed reading beyond this factor of the
#: setpoint the service wrote, while it is in auto, is Bad (and the setpoint stands in for it, then the service
#: holds: ``fallback.inputs_hold_after_h``). A feed in kg/s reads 3.6 times low, in t/min 60 times, in kg/h
#: 1000 times high: each was Good, inside the physical range that starts at a stopped feeder's 0.
FEED_FOLLOW_FACTOR = 2.0

#: Failures of the estimator's or controller's numerics: held and reported, never hidden
#: (CasADi raises RuntimeError on a failed function evaluation).
NUMERIC_ERRORS = (MpcError, TwinError, np.linalg.LinAlgError, RuntimeError)
#: Back-off jitter: each wait is the nominal one times a factor in [1 - J, 1 + J], so that
#: several services do not retry in step.
BACKOFF_JITTER = 0.2
#: Consecutive request time-outs after which the session counts as lost and is rebuilt (one is
#: a busy server, three in a row at seconds each is a dead one).
LOST_AFTER_TIMEOUTS = 3
STATUS_MAX_CHARS = 240
#: With ``[cycle] on_new``, the plant's server is asked to send a new value within this share of
#: a sample (the subscription's publishing interval; 30 ms at x60, 1.8 s in real time), and no
#: faster than every TRIGGER_MIN_PUBLISHING_MS: a move then follows its sample by about a
#: cycle, as in the in-process loop, not by up to a sample.
TRIGGER_PUBLISHING_FRAC = 0.01
TRIGGER_MIN_PUBLISHING_MS = 10.0
TIMER = "timer"  #: what the audit's ``started_by`` says of a cycle the service's own timer started


@dataclass
class ServeSettings:
    """How a service runs (the scene and tag map say what it controls)."""

    url: str
    security: ClientSecurity
    audit_dir: Path
    speedup: float = 1.0
    warmup_h: float | None = None
    """Estimate this long before moving anything (None: the in-process loop's ESTIMATOR_WARMUP_H)."""
    duration_h: float | None = None
    audit_flush_every: int = 20



def _feed_follows(reading: float, setpoint: float) -> bool:
    """True unless a running feeder's reading and its setpoint (both above 0) lie beyond
    :data:`FEED_FOLLOW_FACTOR` of each other (a stopped feeder's 0, or a setpoint of 0, is not judged)."""
    if not (reading > 0 and setpoint > 0):
        return True
    return 1.0 / FEED_FOLLOW_FACTOR <= reading / setpoint <= FEED_FOLLOW_FACTOR


class Service(Stoppable):
    """The served controller of ``parts.scene`` on the plant named by ``tags`` (see the module
    docstring). Drive it with :meth:`run`, or cycle by cycle (:meth:`connect`, :meth:`cycle`,
    :meth:`shutdown`) under a :class:`~scenarios.online.clock.ManualClock`."""

    log_name = log.name

    def __init__(self, parts: ControlParts, tags: TagMap, settings: ServeSettings, clock: Clock | None = None):
        self.parts, self.tags, self.s = parts, tags, settings
        self.scene = parts.scene
        self.clock = clock or Clock(settings.speedup)
        self.dt_h = self.scene.scene.sample_period_h
        self.warmup_h = ESTIMATOR_WARMUP_H if settings.warmup_h is None else settings.warmup_h
        self.n_stages = parts.controller.settings.horizon_steps
        self.limits = {name: Limit.of(name, sp) for name, sp in tags.setpoints}
        self.quality = {name: TagQuality.of(name, m, plausible_range(name, m, self.scene),
                                            source_period_h(name, self.scene))
                        for name, m in tags.measurements if m is not None}
        if tags.belt_analyser is not None:
            ba, period = tags.belt_analyser, source_period_h("belt_analyser", self.scene)
            self.quality |= {f"blend.{o}": TagQuality.of(f"blend.{o}", ba, blend_range(ba), period) for o in parts.ores}
        log.info("plausible ranges (a reading outside is bad): %s",
                 ", ".join(f"{role} {q.plausible}" for role, q in self.quality.items()))
        self.audit = AuditLog(settings.audit_dir, settings.audit_flush_every)
        self.conn: PlantConnection | None = None
        self._reconnect_task: asyncio.Task | None = None
        self._wake: asyncio.Event | None = None
        self._rng = np.random.default_rng(self.scene.scene.seed)
        self.start = self.clock.now()
        self.start_monotonic = self.clock.monotonic()
        self.wall_offset_h = 0.0  # how far the wall clock has been stepped since the start [plant h]
        self.k = 0
        self.t_model_h: float | None = None  # the service time the estimator has been advanced to [h]
        self.skipped_cycles = 0
        self.late_moves = 0  # moves discarded because the next sample had begun before they were ready
        self.samples_unsolved = 0  # samples since the controller's last step (it plans nothing while disconnected)
        self.belt: deque = deque()  # (plant time of the reading [h], blend fractions)
        self.u_written: np.ndarray | None = None
        self.t_written_h = math.nan
        self.setpoints_refused: tuple[float, dict] | None = None  # (service time [h], {tag: status}) once refused
        self.est_start_h: float | None = None
        self.blend_prev: np.ndarray | None = None
        self.p80_held = math.nan
        self.bad_since: dict[str, float] = {}
        self.last_u: np.ndarray | None = None  # the last known inputs (actual, else written)
        self.raw_mode: object = None
        self.mode = "start"
        self.timeouts = 0
        self.heartbeat = 0
        self.stop_reason: str | None = None
        self.new_data = False  # the trigger's node has a new value since the last cycle started
        self.fresh_sample = False  # ... and it is a new sample, not the value it held when subscribed
        self.reanchor = False  # reconnected: the model clock takes the phase of the trigger's next fresh sample
        self.skipped_reconnected = 0  # cycles skipped meanwhile

    # ------------------------------------------------------------------ connection
    def _new_connection(self) -> PlantConnection:
        trigger = None
        if self.tags.cycle.on_new is not None:
            ms = max(TRIGGER_MIN_PUBLISHING_MS, 1e3 * TRIGGER_PUBLISHING_FRAC * self.clock.wall_seconds(self.dt_h))
            trigger = Trigger(self.tags.cycle.on_new, self._on_new, ms)
        return PlantConnection(self.s.url, self.s.security, self.tags.read_roles(), self.tags.write_roles(),
                               self.tags.connection.request_timeout_s, trigger,
                               {f"setpoints.{n}": setpoint_range(n, self.scene) for n, _ in self.tags.setpoints})

    def _on_new(self, fresh: bool) -> None:
        """The trigger's node has a new value (``fresh``: a new sample): wake the run loop for a cycle."""
        self.new_data = True
        self.fresh_sample = self.fresh_sample or fresh
        if self._wake is not None:
            self._wake.set()

    async def connect(self) -> None:
        """Open the session now (raises a connection error if the plant refuses or is away)."""
        conn = self._new_connection()
        await conn.open()
        try:
            self._check_feed_units(conn.held_values.get("setpoints.feed_tph"), (await conn.read()).get("feed_tph"))
        except BaseException:
            await conn.close()
            raise
        self.conn = conn
        # a restarted plant server samples at a phase of its own (the trigger's samples only: the timer's are ours)
        self.reanchor = self.t_model_h is not None and self.tags.cycle.on_new is not None
        log.info("connected to %s (%s)", self.s.url, "insecure" if self.s.security.insecure else
                 "Basic256Sha256 SignAndEncrypt, user " + str(self.s.security.username))

    def _start_reconnect(self) -> None:
        if self._reconnect_task is None or self._reconnect_task.done():
            self._reconnect_task = asyncio.get_running_loop().create_task(self._reconnect())

    async def _reconnect(self) -> None:
        """Connect, retrying with exponential back-off (``[connection]``) until it works or the service stops."""
        c = self.tags.connection
        delay, attempt, t0 = c.reconnect_initial_s, 0, time.monotonic()
        while self.stop_reason is None:
            attempt += 1
            try:
                await self.connect()
                log.info("connection established after %d attempt(s), %.1f s", attempt, time.monotonic() - t0)
                return
            except CONNECTION_ERRORS as exc:
                wait = delay * (1 + BACKOFF_JITTER * self._rng.uniform(-1, 1))
                log.warning("connecting to %s failed (attempt %d: %s: %s); next try in %.2f s",
                            self.s.url, attempt, type(exc).__name__, exc, wait)
                await asyncio.sleep(wait)
                delay = min(2 * delay, c.reconnect_max_s)

    async def _lost(self, exc: BaseException) -> None:
        log.error("connection to %s lost (%s: %s); the plant keeps the last setpoints (%s); reconnecting",
                  self.s.url, type(exc).__name__, exc, self._last_written_text())
        conn, self.conn = self.conn, None
        if conn is not None:
            await conn.close()
        self._start_reconnect()

    def _last_written_text(self) -> str:
        if self.u_written is None:
            return "none written by this service"
        return (f"feed {self.u_written[0]:.4g} t/h, speed {self.u_written[1]:.4g} of critical, written at service time "
                f"{self.t_written_h:.3f} h")

    # ------------------------------------------------------------------ one cycle
    async def cycle(self, started_by: str = "") -> dict:
        """One sample: read, estimate, solve, write (module docstring); returns its audit row
        (``started_by``: what started it, for the audit). Connection losses, bad data and
        numerical failures are handled here, logged and audited."""
        t0, cpu0 = time.perf_counter(), time.process_time()
        now = self.clock.now()
        t_h = self.clock.hours_since(self.start_monotonic)  # the wall clock stepped back 1 h skipped every
        self._wall_step(now, t_h)  # triggered cycle for an hour and forward 0.5 h ran the EKF 10 samples blind
        fresh, self.fresh_sample = self.fresh_sample, False
        steps = self._model_steps(t_h, started_by, fresh)
        if steps < 1:
            return {"service_time_h": t_h, "skipped": True, "started_by": started_by}
        self.samples_unsolved += steps
        row = {"wall_time_utc": now, "service_time_h": t_h, "cycle": self.k, "mode": "disconnected", "written": False,
               "reason": "", "started_by": started_by}
        if self.conn is not None:
            try:
                await self._connected_cycle(now, t_h, steps, row, t0, cpu0)
                self.timeouts = 0
            except asyncio.TimeoutError as exc:  # a busy plant: hold this cycle, lost after a few
                self.timeouts += 1
                if self.timeouts >= LOST_AFTER_TIMEOUTS:
                    await self._lost(exc)
                else:
                    self._no_answer(steps, row)
            except CONNECTION_ERRORS as exc:
                await self._lost(exc)
        if self.conn is None:
            self._blind(steps, row)
        row["cycle_s"] = time.perf_counter() - t0
        self.audit.record(row)
        self.k += 1
        return row

    def _wall_step(self, now, t_h: float) -> None:
        """Log a step of the wall clock of more than half a sample since the last cycle."""
        offset = self.clock.hours_between(self.start, now) - t_h
        if abs(offset - self.wall_offset_h) > 0.5 * self.dt_h:
            log.warning("%.3f h: the wall clock stepped %+.4g plant h (NTP? an operator?); the service's time runs on "
                        "the monotonic clock, readings' source timestamps are judged on the wall clock",
                        t_h, offset - self.wall_offset_h)
            self.wall_offset_h = offset

    def _model_steps(self, t_h: float, started_by: str, fresh: bool) -> int:
        """The whole samples the estimator advances this cycle (0: the cycle is skipped), and the model clock
        (``t_model_h``) moved on by them. It follows the plant's in whole samples: a trigger under half a sample
        after the last cycle (a gateway refreshing source timestamps every scan) advanced it a whole sample each
        time, 15.8 model hours in 2; such a cycle is skipped (unread, unaudited), counted and logged once. The
        timer's cycles are never skipped: after the trigger's timeout (1.5 samples) they come half a sample off
        the model clock, and rounding skipped every other one. After a reconnection the clock takes the phase of
        the trigger's first fresh sample at least half a sample on (a restarted server's samples come at a phase
        of their own: those a little under half a sample off were skipped and the next run two samples on)."""
        if self.t_model_h is None:
            self.t_model_h = t_h
            return 1
        ahead = (t_h - self.t_model_h) / self.dt_h
        steps = max(round(ahead), 1 if started_by == TIMER else 0)
        if steps < 1:
            self.skipped_cycles += 1
            if self.reanchor:  # the reconnection's, said once when the clock re-anchors
                self.skipped_reconnected += 1
                return 0
        else:
            self.t_model_h += steps * self.dt_h
            if self.reanchor and fresh:
                self.t_model_h, self.reanchor = t_h, False
                log.info("%.3f h: the plant's samples after the reconnection come %+.2f of a sample off the model "
                         "clock's phase: it takes theirs (%d cycle(s) skipped meanwhile)", t_h, ahead - steps,
                         self.skipped_reconnected)
                self.skipped_reconnected = 0
        self._condition("early cycles", steps < 1, t_h, f"cycles started under half a sample ({self.dt_h:g} h) "
                        "after the last are skipped: the trigger fires faster than the samples")
        return steps

    def _predict_blind(self, steps: int, row: dict) -> None:
        """The estimator predicts with the inputs the plant keeps (unless it ran this cycle)."""
        u = self.u_written if self.u_written is not None else self.last_u
        if "estimate_s" in row or self.est_start_h is None or u is None or self.blend_prev is None:
            return
        for _ in range(steps):
            self.parts.estimator.make_step([math.nan] * 3, u, self.blend_prev)

    def _blind(self, steps: int, row: dict) -> None:
        """No connection: predict; the plant keeps the last setpoints."""
        self._predict_blind(steps, row)
        reason = f"no connection: setpoints left at {self._last_written_text()}"
        self._set_mode("disconnected", reason)
        row.update(mode="disconnected", reason=self._write_fate(row, reason))

    def _no_answer(self, steps: int, row: dict) -> None:
        """A request timed out: this cycle holds (a write in flight may or may not have landed)."""
        self._predict_blind(steps, row)
        reason = (f"the plant did not answer within {self.tags.connection.request_timeout_s:g} s "
                  f"({self.timeouts} of {LOST_AFTER_TIMEOUTS} before the connection counts as lost)")
        log.warning("%s", reason)
        self._set_mode("hold", reason)
        row.update(mode="hold", reason=self._write_fate(row, reason))

    @staticmethod
    def _write_fate(row: dict, reason: str) -> str:
        """``reason`` after what became of this cycle's setpoint write before the request failed: a loss after the
        write (the soft sensor's) made the row read unwritten, while the plant had the move and the log named it."""
        if any(row.get(f"{n}_written") for n in INPUTS):
            return f"{row['mode']}: setpoints written ({row['reason'] or 'no note'}), then {reason}"
        if any(math.isfinite(row.get(k, math.nan)) for k in ("feed_sp_tph", "speed_sp_frac_critical")):
            return (f"{reason}; a setpoint write (feed {row['feed_sp_tph']:.4g} t/h, speed "
                    f"{row['speed_sp_frac_critical']:.4g}) was in flight: the plant may have it")
        return reason

    async def _connected_cycle(self, now, t_h: float, steps: int, row: dict, t0: float, cpu0: float) -> None:
        readings = await self.conn.read()
        row["read_s"], row["read_cpu_s"] = time.perf_counter() - t0, time.process_time() - cpu0
        v = self._feed_following(self._power_while_turning(
            {role: self.quality[role].assess(r, now, self.clock) for role, r in readings.items() if role != "mode"}))
        for role, verdict in v.items():
            row[f"{role}_quality"] = verdict.quality
            row[f"{role}_quality_reason"] = verdict.reason  # the audit says why, each cycle (empty when good)
            row[f"{role}_raw"] = raw_number(readings[role].value)  # what the tag read, used or not
            self._condition(role, not verdict.ok, t_h, f"{role} unusable: {verdict.quality} ({verdict.reason})")
        auto = self._auto(readings["mode"], t_h)
        blend_now, preview = self._belt(v, t_h)
        u_act, inputs_note = self._inputs(v, t_h)
        t1, c1 = time.perf_counter(), time.process_time()
        x_est, d_est, est_note = self._estimate(v, u_act, blend_now, steps, t_h)
        row["estimate_s"], row["estimate_cpu_s"] = time.perf_counter() - t1, time.process_time() - c1
        mode, reason = self._decide(auto, x_est, t_h, inputs_note or est_note, u_act)
        u_prop, res, solve_note = self._solve(mode, x_est, d_est, preview, u_act, row)
        mode, reason = ("hold", solve_note) if solve_note else (mode, reason)
        values, write_note = self._moves(mode, u_prop, u_act)
        values, late_note = self._in_time(values, t_h, row)
        write_note = "; ".join(n for n in (write_note, late_note) if n)
        row.update(self._row_values(v, u_act, u_prop, x_est, d_est, res))
        reason = "; ".join(n for n in (reason, write_note) if n)
        self._set_mode(mode, reason)
        await self._write(values, mode, reason, t_h, row)
        reason = "; ".join(n for n in (reason, row.pop("write_refused", "")) if n)  # it overwrote the refusal
        row.update(mode=mode, reason=reason, write_done_s=time.perf_counter() - t0,
                   write_done_cpu_s=time.process_time() - cpu0)
        await self._soft_sensor(u_act, row)

    # ------------------------------------------------------------------ readings
    def _condition(self, key: str, active: bool, t_h: float, message: str) -> None:
        """Log a condition when it starts and when it ends (not every cycle)."""
        since = self.bad_since.get(key)
        if active and since is None:
            self.bad_since[key] = t_h
            log.warning("%.3f h: %s", t_h, message)
        elif not active and since is not None:
            del self.bad_since[key]
            log.info("%.3f h: %s good again after %.3f h", t_h, key, t_h - since)

    def _refused(self, key: str, results: dict, t_h: float, consequence: str) -> dict:
        """``{role: status name}`` of the writes among ``results`` (role -> status code) the server refused, logged
        (``key``, with ``consequence``) when such refusals start and when they end, not at every cycle's write."""
        refused = {r: status_name(c) for r, c in results.items() if c != ua.StatusCodes.Good}
        self._condition(key, bool(refused), t_h, f"the server refused the {key}s: {refused}; {consequence}")
        return refused

    def _bad_for_h(self, key: str, t_h: float) -> float:
        since = self.bad_since.get(key)
        return 0.0 if since is None else t_h - since

    def _auto(self, reading: Reading, t_h: float) -> bool:
        """True if the operator's mode is auto; a mode without Good status counts as manual."""
        good = severity(reading.status) == GOOD
        self.raw_mode = reading.value if good else f"unreadable ({reading.status_name})"
        self._condition("mode", not good, t_h, f"mode unreadable ({reading.status_name}): treated as manual")
        return good and reading.value == self.tags.mode.auto_value

    def _belt(self, v: dict, t_h: float):
        """The blend entering the mill now and the preview's blend per stage, from the belt
        analyser's readings (held when a reading is unusable; the scene's initial blend without one)."""
        ba = self.tags.belt_analyser
        if ba is None:
            return self.parts.blend0, [self.parts.blend0] * self.n_stages
        verdicts = [v[f"blend.{o}"] for o in self.parts.ores]
        if all(x.ok for x in verdicts) and verdicts[0].new:
            b = np.array([x.value for x in verdicts])
            total = b.sum()
            if abs(total - 1.0) <= ba.sum_tolerance and np.all(b >= 0):
                self.belt.append((t_h, b / total))
                self._condition("belt sum", False, t_h, "")
            else:
                self._condition("belt sum", True, t_h, f"belt analyser fractions sum to {total:.4g}, outside 1 +- "
                                f"{ba.sum_tolerance:g}: reading refused, last blend held")
        if not self.belt:
            return None, None
        while len(self.belt) > 1 and self.belt[1][0] <= t_h - ba.lead_h - self.dt_h:
            self.belt.popleft()  # keep one reading older than the lead
        at = [self._belt_at(min(t_h + j * self.dt_h, t_h + ba.lead_h) - ba.lead_h) for j in range(self.n_stages)]
        return at[0], at

    def _belt_at(self, t_h: float) -> np.ndarray:
        """The belt reading taken at or before ``t_h`` (half a sample's tolerance), else the oldest."""
        best = self.belt[0][1]
        for t, b in self.belt:
            if t <= t_h + 0.5 * self.dt_h:
                best = b
        return best

    def _check_feed_units(self, setpoint: float | None, reading: Reading | None) -> None:
        """NodeError if a running feeder's Good feed reading (above 0) lies beyond :data:`FEED_FOLLOW_FACTOR` of the
        feed setpoint node's value (above 0) when the session opens, or, with no Good value there (a DCS starting up,
        a node never written), of every feed the service may write (the setpoint's bounds) and the scene's feed: one
        of them in other units (a reading in kg/s took 30 t/h for 8.3, and the first move in auto, from the actual
        feed, wrote 8.3 t/h)."""
        if reading is None or severity(reading.status) != GOOD:
            return
        value = raw_number(reading.value)
        where = (f"measurements.feed_tph: node {self.tags.measurements.feed_tph.node!r} reads {value:g} while the "
                 f"feed setpoint node {self.tags.setpoints.feed_tph.node!r}")
        units = "one of them is in other units (kg/s? kg/h?); give both nodes in t/h"
        if setpoint is not None:
            if _feed_follows(value, setpoint):
                return
            raise NodeError(f"{where} holds {setpoint:g} t/h: {value / setpoint:.3g} times it, beyond a feeder's "
                            f"following (a factor {FEED_FOLLOW_FACTOR:g}): {units}")
        lim, nominal = self.limits["feed_tph"], self.scene.feed.feed_tph
        lo, hi = (lim.min, lim.max) if nominal is None else (min(lim.min, nominal), max(lim.max, nominal))
        if not value > 0 or lo / FEED_FOLLOW_FACTOR <= value <= hi * FEED_FOLLOW_FACTOR:
            return
        scene = "" if nominal is None else f" and the scene's {nominal:g} t/h"
        raise NodeError(f"{where} holds no Good value to compare it with: beyond a feeder's following (a factor "
                        f"{FEED_FOLLOW_FACTOR:g}) of the feeds the service writes, [{lim.min:g}, {lim.max:g}] t/h"
                        f"{scene}: {units}, and give the setpoint node the plant's setpoint")

    def _feed_following(self, v: dict) -> dict:
        """``v`` with a usable feed reading above 0 made Bad when the service is in auto and the reading lies
        beyond :data:`FEED_FOLLOW_FACTOR` of the feed setpoint it wrote (a stopped feeder's 0 is a reading)."""
        feed = v.get("feed_tph")
        if feed is None or not feed.ok or self.mode != "auto" or self.u_written is None:
            return v
        written = float(self.u_written[0])
        if _feed_follows(feed.value, written):
            return v
        return {**v, "feed_tph": Verdict(math.nan, BAD, f"feed_tph = {feed.value:g} t/h while the service's feed "
                                         f"setpoint is {written:.4g} t/h: {feed.value / written:.3g} times it, beyond "
                                         f"a feeder's following (a factor {FEED_FOLLOW_FACTOR:g}; kg/s? kg/h? t/h "
                                         "expected)", feed.new)}

    def _power_while_turning(self, v: dict) -> dict:
        """``v`` with a usable power reading made Bad when the mill turns (a usable speed above 0) and the power
        lies below :data:`POWER_TURNING_MIN_FRAC` of the control model's power at that speed."""
        power, speed = v.get("power_kw"), v.get("speed_frac_critical")
        if power is None or speed is None or not (power.ok and speed.ok and speed.value > 0):
            return v
        expected = float(power_kw(self.parts.models.control.mill, min(speed.value, 1.0)))
        if power.value >= POWER_TURNING_MIN_FRAC * expected:
            return v
        return {**v, "power_kw": Verdict(math.nan, BAD, f"power_kw = {power.value:g} kW while the mill turns at "
                                         f"{speed.value:.3g} of critical: below {POWER_TURNING_MIN_FRAC:.0%} of its "
                                         f"power model's {expected:.4g} kW (MW? kW expected)", power.new)}

    def _inputs(self, v: dict, t_h: float):
        """The actual inputs (the last written setpoints stand in for unusable ones for
        ``inputs_hold_after_h``); ``(u or None, hold note)``."""
        act = np.array([v[n].value for n in INPUTS])
        ok = np.isfinite(act)
        self._condition("inputs", not ok.all(), t_h, "actual feed or speed unusable")
        if not ok.all() and self.u_written is not None:
            act = np.where(ok, act, self.u_written)
        if not np.all(np.isfinite(act)):
            return None, "the actual inputs are unknown"
        self.last_u = act
        if self._bad_for_h("inputs", t_h) > self.tags.fallback.inputs_hold_after_h:
            return act, f"actual inputs unusable for {self._bad_for_h('inputs', t_h):.3g} h"
        return act, ""

    # ------------------------------------------------------------------ estimate, decide, solve
    def _estimate(self, v: dict, u, blend_now, steps: int, t_h: float):
        """``(x_est, d_est, note)``; the EKF starts at the controller model's steady state at
        the first actual inputs and blend, then predicts and updates every cycle."""
        ekf = self.parts.estimator
        if u is None or blend_now is None:
            return None, None, "no actual inputs or belt analyser reading for the estimator yet"
        p80 = v["p80_um"]
        if p80.ok:
            self.p80_held = p80.value
        try:
            if self.est_start_h is None:
                css = self.parts.models.control.steady(feed_tph=u[0], speed_frac_critical=u[1], blend=blend_now)
                ekf.reset(css.x)
                self.est_start_h, self.blend_prev = t_h, blend_now
                log.info("%.3f h: estimator started at the steady state of feed %.4g t/h, speed %.4g", t_h, *u)
                return ekf.x_est, np.r_[blend_now, ekf.hardness_est], ""
            for _ in range(steps - 1):
                ekf.make_step([math.nan] * 3, u, self.blend_prev)
            y = [p80.value if (p80.ok and p80.new) else math.nan] + [
                v[m].value if m in v else math.nan for m in ("power_kw", "load_frac")]
            x, d = ekf.make_step(y, u, self.blend_prev)
        except NUMERIC_ERRORS as exc:
            log.exception("%.3f h: the estimator failed", t_h)
            return None, None, f"the estimator failed: {type(exc).__name__}: {exc}"
        self.blend_prev = blend_now
        if getattr(ekf, "has_hardness", False):  # a saturated estimate: logged when it starts and ends
            at_bound = any(math.isclose(ekf.hardness_est, b, rel_tol=1e-9) for b in ekf.hardness_bounds)
            self._condition("hardness_bound", at_bound, t_h, f"the estimator's hardness sits at a bound of its range "
                            f"{ekf.hardness_bounds}: the ore differs from the model by more than it may say")
        return x, d, ""

    def _decide(self, auto: bool, x_est, t_h: float, note: str, u_act) -> tuple[str, str]:
        """The mode of this cycle and its reason (before the controller runs; ``u_act``: the actual inputs)."""
        if x_est is None:
            return "hold", note
        if t_h - self.est_start_h < self.warmup_h:
            return "warmup", f"estimator warm-up {t_h - self.est_start_h:.3g} of {self.warmup_h:g} h"
        if not auto:
            return "manual", f"mode {self.raw_mode!r} is not {self.tags.mode.auto_value!r}: the controller " \
                             "tracks the actual inputs, nothing written"
        if self.setpoints_refused is not None:  # it stayed in auto, the plant told all was well
            since, which = self.setpoints_refused
            return "hold", (f"the server refused the setpoint writes {which} at {since:.3f} h: holding, nothing "
                            "written; check the tag map's setpoint nodes and their access, then restart the service")
        if note:
            return "hold", note
        p80_bad = self._bad_for_h("p80_um", t_h)
        if p80_bad > self.tags.fallback.p80_hold_after_h:
            return "hold", f"P80 unusable for {p80_bad:.3g} h (> {self.tags.fallback.p80_hold_after_h:g} h)"
        far = "" if self._continuing() else self._outside_bounds(u_act)
        if far:
            return "hold", far
        return "auto", f"on the model: P80 unusable for {p80_bad:.3g} h" if "p80_um" in self.bad_since else ""

    def _solve(self, mode: str, x_est, d_est, preview, u_act, row: dict):
        """The controller's step (not in warm-up or without an estimate); ``(u, result, failure note)``."""
        u_prev = u_act if u_act is not None else self.u_written
        if mode == "warmup" or x_est is None or u_prev is None:
            return None, None, ""
        D = np.vstack([np.array(preview, float).T, np.full(self.n_stages, float(d_est[-1]))])
        t1, c1 = time.perf_counter(), time.process_time()
        try:
            # its warm start and fallback plan move on by the samples since its last step (an outage, an overrun):
            # by one, a failed step after an outage longer than the horizon applied a move of the expired plan
            res = self.parts.controller.make_step(x_est, D, u_prev, y_meas=self.p80_held,
                                                  p80_bias_um=self.parts.estimator.controller_p80_bias_um(
                                                      self.parts.controller.settings.target_p80_um),
                                                  samples=max(self.samples_unsolved, 1))
            self.samples_unsolved = 0
        except NUMERIC_ERRORS as exc:
            log.exception("the controller failed")
            return None, None, f"the controller failed: {type(exc).__name__}: {exc}"
        finally:
            row["solve_s"], row["solve_cpu_s"] = time.perf_counter() - t1, time.process_time() - c1
        return np.asarray(res.u_applied, float), res, ""

    def _continuing(self) -> bool:
        """True while the service stays in auto on its own setpoints; False when it takes over from the actual inputs
        (after manual, hold or a start)."""
        return self.mode == "auto" and self.u_written is not None

    def _outside_bounds(self, u_act) -> str:
        """Why the service may not take over from the actual inputs ('' if it may): an input outside its setpoint's
        bounds by more than a sample's rate limit would be stepped into them at once, the bounds winning over the
        rate limit (a feed in kg/s of 18 t/h read 5, and the first move wrote the bound, 8 t/h: 10 t/h at once)."""
        far = []
        for i, name in enumerate(INPUTS):
            lim, value = self.limits[name], float(u_act[i])
            step, gap = lim.rate_max_per_h * self.dt_h, max(lim.min - value, value - lim.max)
            if gap > step * (1 + 1e-9):
                far.append(f"the actual {name} {value:.4g} lies {gap:.4g} {'below' if value < lim.min else 'above'} "
                           f"its bounds [{lim.min:g}, {lim.max:g}], beyond the rate limit ({step:.4g} a sample)")
        if not far:
            return ""
        return ("; ".join(far) + ": taking over would step its setpoint into the bounds at once; holding, nothing "
                "written (bring it within the bounds in manual, or check the reading's units: kg/s? kg/h?)")

    def _moves(self, mode: str, u_prop, u_act) -> tuple[dict, str]:
        """The setpoints to write in auto, limited at the writer; ``({name: value}, notes)``."""
        if mode != "auto" or u_prop is None:
            return {}, ""
        out, notes = {}, []
        # the rate limit is on the setpoint: from the one this service wrote while it stays in auto (from the
        # actual reading, a lagging or mis-scaled actual let a write jump: 23.6 to 20 t/h against 1 t/h a
        # sample), from the actual input when it takes over (bumpless)
        continuing = self._continuing()
        for i, name in enumerate(INPUTS):
            ref = (self.u_written[i] if continuing else u_act[i] if u_act is not None
                   else self.u_written[i] if self.u_written is not None else None)
            value, n = limit_move(float(u_prop[i]), ref, self.dt_h, self.limits[name])
            notes += n
            if value is None:
                return {}, "; ".join(notes)
            out[name] = value
        return out, "; ".join(notes)

    def _in_time(self, values: dict, t_h: float, row: dict) -> tuple[dict, str]:
        """``(values, note)``: the moves, or none when they are ready only once the next sample has begun, a sample
        after the cycle read its readings (a solve that overran): such a move, computed for a sample that is over,
        was written into the next one. The plant keeps the last written setpoints; the row (``move_late``), the
        log (when late moves start and end) and :attr:`late_moves` say so."""
        late_h = self.clock.hours_since(self.start_monotonic) - t_h
        row["move_late"] = late = bool(values) and late_h >= self.dt_h
        note = (f"the move was ready {late_h:.3g} h after its sample's readings: the next sample had begun, the move "
                f"is discarded (solve {row.get('solve_s', math.nan):.3g} s) and the setpoints stay at "
                f"{self._last_written_text()}")
        self._condition("late moves", late, t_h, note)
        if not late:
            return values, ""
        self.late_moves += 1
        return {}, note

    # ------------------------------------------------------------------ write, soft sensor, audit
    def _set_mode(self, mode: str, reason: str) -> None:
        if mode != self.mode:
            level = logging.INFO if mode in ("auto", "warmup", "manual") else logging.WARNING
            log.log(level, "mode %s -> %s%s", self.mode, mode, f": {reason}" if reason else "")
            if mode == "auto" and self.mode in ("manual", "hold") and self.last_u is not None:
                log.info("back in auto from the actual inputs (feed %.4g t/h, speed %.4g): bumpless", *self.last_u)
            self.mode = mode

    async def _write(self, values: dict, mode: str, reason: str, t_h: float, row: dict) -> None:
        self.heartbeat = (self.heartbeat + 1) % 2**31
        items = {f"setpoints.{k}": (v, ua.StatusCodes.Good) for k, v in values.items()}
        items["heartbeat"] = (self.heartbeat, ua.StatusCodes.Good)
        if self.tags.status is not None:
            items["status"] = ((f"{mode}: {reason}" if reason else mode)[:STATUS_MAX_CHARS], ua.StatusCodes.Good)
        row["feed_sp_tph"], row["speed_sp_frac_critical"] = (values.get(n, math.nan) for n in INPUTS)
        t1, c1 = time.perf_counter(), time.process_time()
        results = await self.conn.write(items, self.clock.now())
        row["write_s"], row["write_cpu_s"] = time.perf_counter() - t1, time.process_time() - c1
        # a setpoint's refusal comes once (the service holds from the next cycle); the heartbeat's and the status's
        # would come every cycle, logged when they start and end
        refused = self._refused("heartbeat or status write", {r: c for r, c in results.items()
                                                              if not r.startswith("setpoints.")}, t_h,
                                "the plant's watchdog may shed the service and the operator's screen keeps an older "
                                "status")
        setpoints = {r: status_name(c) for r, c in results.items() if r.startswith("setpoints.") and
                     c != ua.StatusCodes.Good}
        if setpoints:
            log.error("the server refused setpoint writes: %s", setpoints)
        refused |= setpoints
        if refused:
            row["write_refused"] = f"the server refused writes: {refused}"
        accepted = [i for i, n in enumerate(INPUTS) if n in values and f"setpoints.{n}" not in refused]
        if accepted:  # each setpoint on its own: a refused feed write discarded the speed's, which was applied
            known = self.u_written if self.u_written is not None else self.last_u  # the refused one's stays
            u = np.array(known, float) if known is not None else np.array([values.get(n, math.nan) for n in INPUTS])
            u[accepted] = [values[INPUTS[i]] for i in accepted]
            self.u_written, self.t_written_h = u, t_h
        for i, n in enumerate(INPUTS):
            row[f"{n}_written"] = i in accepted
        row["written"] = bool(values) and len(accepted) == len(INPUTS)
        if any(r.startswith("setpoints.") for r in refused):  # held from the next cycle on (see _decide)
            self.setpoints_refused = (t_h, {r: c for r, c in refused.items() if r.startswith("setpoints.")})

    async def _soft_sensor(self, u_act, row: dict) -> None:
        """Publish the soft sensor's predictions for the ore on the belt at the actual inputs."""
        soft, tags = self.parts.soft_sensor, self.tags.soft_sensor
        if soft is None or tags is None or u_act is None or not self.belt:
            return
        t1 = time.perf_counter()
        p = soft.predict(self.belt[-1][1], float(u_act[0]), float(u_act[1]))
        pairs = {"p80_um": (p.p80_um, p.status), "specific_energy_kwh_t": (p.specific_energy_kwh_t, p.status),
                 "surrogate_p80_um": (p.surrogate_p80_um, p.surrogate_status),
                 "surrogate_specific_energy_kwh_t": (p.surrogate_specific_energy_kwh_t, p.surrogate_status)}
        items = {f"soft_sensor.{k}": (None if val is None or not math.isfinite(val) else val, code)
                 for k, (val, code) in pairs.items() if getattr(tags, k) is not None and code is not None}
        self._condition("soft sensor", p.status != ua.StatusCodes.Good, row["service_time_h"],
                        f"soft sensor {status_name(p.status)}: {p.reason}")
        results = await self.conn.write(items, self.clock.now())
        # a refused node kept its last prediction on the operator's screen, and nothing said so
        refused = self._refused("soft sensor's write", results, row["service_time_h"], "those nodes keep older values")
        if refused:
            row["reason"] = "; ".join(n for n in (row["reason"], f"the server refused the soft sensor's writes: "
                                                                 f"{refused}") if n)
        row.update(soft_p80_um=p.p80_um, soft_specific_energy_kwh_t=p.specific_energy_kwh_t,
                   soft_status=status_name(p.status), soft_s=time.perf_counter() - t1)

    def _row_values(self, v: dict, u_act, u_prop, x_est, d_est, res) -> dict:
        out = {"p80_um": v["p80_um"].value, "p80_new": bool(v["p80_um"].new),
               "feed_actual_tph": math.nan if u_act is None else float(u_act[0]),
               "speed_actual_frac_critical": math.nan if u_act is None else float(u_act[1]),
               "feed_proposed_tph": math.nan if u_prop is None else float(u_prop[0]),
               "speed_proposed_frac_critical": math.nan if u_prop is None else float(u_prop[1]),
               "hardness_est": math.nan if d_est is None else float(d_est[-1]),
               "p80_bias_est_um": self.parts.estimator.p80_bias_um,
               "operator_mode": str(self.raw_mode)}
        if res is not None:
            out |= {"controller_status": res.status, "controller_success": bool(res.success),
                    "fallback": res.fallback_used or ""}
        return out

    # ------------------------------------------------------------------ run and stop
    async def run(self, install_signal_handlers: bool = True) -> None:
        """Cycle every sample period, or on the trigger's new values, until stopped (SIGTERM,
        SIGINT, ``duration_h``)."""
        loop = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        signals = self.stop_on_signals(loop, install_signal_handlers)
        period = self.clock.wall_seconds(self.dt_h)
        try:
            self._start_reconnect()
            next_t = loop.time()
            while self.stop_reason is None:
                started, triggered = loop.time(), self.new_data
                self._wake.clear()
                self.new_data = False
                row = await self.cycle(f"new {self.tags.cycle.on_new}" if triggered else TIMER)
                if self.s.duration_h is not None and row["service_time_h"] >= self.s.duration_h:
                    self.request_stop(f"duration {self.s.duration_h:g} h reached")
                next_t = self._next_cycle(loop, next_t, started, triggered, period, row["service_time_h"])
                await sleep_until(next_t, self._wake)
        finally:
            try:
                await self.shutdown(self.stop_reason or "ended")
            finally:  # only now: a second signal while stopping must not cut the stop short (it asks again)
                for sig in signals:
                    loop.remove_signal_handler(sig)

    def _next_cycle(self, loop, next_t: float, started: float, triggered: bool, period: float, t_h: float) -> float:
        """The loop time at which the timer starts the next cycle: a period on (overruns skip
        whole samples); after a cycle the trigger started, ``timeout_samples`` periods after it."""
        cyc = self.tags.cycle
        if cyc.on_new is not None:
            self._condition("cycle trigger", not triggered and self.conn is not None, t_h,
                            f"no new {cyc.on_new} within {cyc.timeout_samples:g} samples: the timer starts the cycles")
            if triggered:
                return started + cyc.timeout_samples * period
        next_t += period
        late = loop.time() - next_t
        if late > 0:
            skipped = math.ceil(late / period)
            log.warning("cycle overran its period by %.3f s: %d sample(s) skipped", late, skipped)
            next_t += skipped * period
        return next_t

    async def shutdown(self, reason: str) -> None:
        """Stop: write nothing but the status, flush the audit, report the setpoints left."""
        self.stop_reason = self.stop_reason or reason
        if self._reconnect_task is not None:
            self._reconnect_task.cancel()
        left = f"setpoints left at {self._last_written_text()}"
        if self.conn is not None and self.tags.status is not None:
            try:
                await self.conn.write({"status": (f"stopped ({reason}): {left}"[:STATUS_MAX_CHARS],
                                                  ua.StatusCodes.Good)}, self.clock.now())
            except CONNECTION_ERRORS as exc:
                log.warning("could not write the final status: %s", exc)
        if self.conn is not None:
            await self.conn.close()
            self.conn = None
        self.audit.record({"wall_time_utc": self.clock.now(), "service_time_h": self.clock.hours_since(
            self.start_monotonic), "cycle": self.k, "mode": "stopped", "written": False,
            "reason": f"stopped ({reason}): {left}"})
        self.audit.flush()
        log.info("stopped (%s): %s; %d late move(s) discarded", reason, left, self.late_moves)
