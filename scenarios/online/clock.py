"""Plant time on the wall clock: ``speedup`` plant seconds pass per wall-clock second (1 on a
real plant; more on a virtual plant run faster than real time). Time stamps are the wall clock's
(UTC, which NTP or an operator may step); elapsed time is the monotonic clock's, which no one sets."""

from __future__ import annotations

import asyncio
import logging
import math
import signal
import time
from datetime import datetime, timedelta, timezone


class Clock:
    """Wall-clock time (UTC) and its conversion to plant hours at a speed-up factor."""

    def __init__(self, speedup: float = 1.0):
        if not (isinstance(speedup, (int, float)) and math.isfinite(speedup) and speedup > 0):
            raise ValueError(f"The 'speedup' of Clock must be a float > 0. Got {speedup!r}.")
        self.speedup = float(speedup)

    def now(self) -> datetime:
        return datetime.now(timezone.utc)

    def monotonic(self) -> float:
        """Seconds on a clock that is never set (a wall-clock step does not move it); any origin."""
        return time.monotonic()

    def hours_since(self, monotonic_s: float) -> float:
        """Plant hours since :meth:`monotonic` read ``monotonic_s``."""
        return (self.monotonic() - monotonic_s) * self.speedup / 3600.0

    def hours_between(self, start: datetime, end: datetime) -> float:
        """Plant hours from ``start`` to ``end`` (both aware datetimes)."""
        return (end - start).total_seconds() * self.speedup / 3600.0

    def wall_seconds(self, plant_h: float) -> float:
        """Wall-clock seconds that ``plant_h`` plant hours take."""
        return plant_h * 3600.0 / self.speedup


class ManualClock(Clock):
    """A clock that moves only when told to (lock-step tests and benchmarks)."""

    def __init__(self, speedup: float = 1.0, start: datetime | None = None):
        super().__init__(speedup)
        self._now = start or datetime.now(timezone.utc)
        self._monotonic = 0.0

    def now(self) -> datetime:
        return self._now

    def monotonic(self) -> float:
        return self._monotonic

    def advance(self, plant_h: float) -> None:
        self._now += timedelta(seconds=self.wall_seconds(plant_h))
        self._monotonic += self.wall_seconds(plant_h)

    def step_wall(self, plant_h: float) -> None:
        """Set the wall clock on (or back, ``plant_h`` < 0) alone, as NTP or an operator does: no time passes."""
        self._now += timedelta(seconds=self.wall_seconds(plant_h))


async def sleep_until(loop_time: float, wake: asyncio.Event) -> bool:
    """Sleep until the event loop's time reaches ``loop_time``; True if ``wake`` was set first."""
    delay = loop_time - asyncio.get_running_loop().time()
    if wake.is_set():
        return True
    if delay <= 0:
        return False
    try:
        await asyncio.wait_for(wake.wait(), timeout=delay)
        return True
    except asyncio.TimeoutError:
        return False


class Stoppable:
    """A long-running asyncio service's stop: ``request_stop`` (from a signal, a time limit or a
    test) records the first reason and wakes the sleeping loop; ``stop_on_signals`` installs it
    for SIGTERM and SIGINT and returns the signals to remove at the end."""

    stop_reason: str | None = None
    _wake: asyncio.Event | None = None
    log_name = "grindtwin.online"  #: the logger the stop is logged to

    def request_stop(self, reason: str) -> None:
        """End the service after the running cycle (signal handlers call this)."""
        if self.stop_reason is None:
            self.stop_reason = reason
            logging.getLogger(self.log_name).info("stop requested: %s", reason)
        if self._wake is not None:
            self._wake.set()

    def stop_on_signals(self, loop, install: bool) -> tuple:
        signals = (signal.SIGTERM, signal.SIGINT) if install else ()
        for sig in signals:
            loop.add_signal_handler(sig, self.request_stop, sig.name)
        return signals
