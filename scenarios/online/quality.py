"""Data quality of plant readings: OPC UA status codes, stale source timestamps and frozen values.

A reading is usable when its status is Good (or Uncertain where the tag map accepts it), its
source timestamp is younger than the tag's ``max_age_h`` and, for a tag with ``frozen_after_h``,
its value has changed within that time while its timestamps moved on (an analyser that keeps
reporting one number), and its value lies in the tag's :class:`PlausibleRange` (a P80 of -5 um or a
speed of 3 times critical is an instrument or scaling fault, Bad, never a state of the plant).
The first failing check names the verdict: bad, uncertain, stale, frozen.

A reading is a new report when its timestamp moved and, for a tag whose source reports every
``report_period_h``, its value changed or a report period has passed since the last new one: a
gateway that stamps the held value anew at every scan made each cycle take it as a new analysis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime

from scenarios.online.clock import Clock

GOOD, UNCERTAIN, BAD, STALE, FROZEN = "good", "uncertain", "bad", "stale", "frozen"
#: An unchanged value is a new report once this share of its source's period has passed since the last new one
#: (source timestamps of reports a period apart, stamped to the clock's resolution, may fall a little short of it).
REPORT_PERIOD_FRAC = 0.9


def severity(status_code: int) -> str:
    """Good, uncertain or bad from an OPC UA status code: its two top bits, 00 Good, 01
    Uncertain, 10 Bad (OPC 10000-4, 7.39 StatusCode)."""
    top = (int(status_code) >> 30) & 0b11
    return GOOD if top == 0 else UNCERTAIN if top == 1 else BAD


@dataclass(frozen=True)
class Reading:
    """One value as the server returned it."""

    value: object
    status: int = 0
    source_time: datetime | None = None
    server_time: datetime | None = None
    status_name: str = ""

    @property
    def time(self) -> datetime | None:
        """When the value was taken: the source timestamp, else the server's."""
        return self.source_time or self.server_time


@dataclass(frozen=True)
class Verdict:
    """What a reading is worth: ``value`` (nan when not usable), its ``quality``, why (empty
    when good) and whether it is ``new`` (its timestamp moved since the last reading)."""

    value: float
    quality: str
    reason: str = ""
    new: bool = True

    @property
    def ok(self) -> bool:
        return math.isfinite(self.value)


@dataclass(frozen=True)
class PlausibleRange:
    """The values a measurement can take: ``low`` to ``high`` in ``unit``, each end excluded
    (open) or included; a reading outside is Bad."""

    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False
    unit: str = ""

    def __contains__(self, value: float) -> bool:
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return above and below

    def __str__(self) -> str:
        left = "(" if self.low_open or math.isinf(self.low) else "["
        right = ")" if self.high_open or math.isinf(self.high) else "]"
        return f"{left}{self.low:g}, {self.high:g}{right}" + (f" {self.unit}" if self.unit else "")


def raw_number(value) -> float:
    """A reading's value as a float for the audit, used or not (NaN when it is no number)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return math.nan
    return float(value)


def _number(value) -> float | None:
    v = raw_number(value)
    return v if math.isfinite(v) else None


class TagQuality:
    """The quality rules of one tag and what it last saw (for freezes and new samples)."""

    def __init__(self, name: str, max_age_h: float | None, frozen_after_h: float | None = None,
                 freeze_tolerance: float = 0.0, accept_uncertain: bool = False,
                 plausible: PlausibleRange | None = None, report_period_h: float | None = None):
        self.name = name
        self.report_period_h = report_period_h  # None: every moved timestamp is a new report
        self._report: tuple[datetime, float] | None = None  # (time, value) of the last new report
        self.max_age_h, self.frozen_after_h = max_age_h, frozen_after_h
        self.freeze_tolerance, self.accept_uncertain = freeze_tolerance, accept_uncertain
        self.plausible = plausible  # None: no range check
        self._last_time: datetime | None = None
        self._value: float | None = None
        self._since: datetime | None = None

    @classmethod
    def of(cls, name: str, rule, plausible: PlausibleRange | None = None,
           report_period_h: float | None = None) -> "TagQuality":
        """From a tag map entry (a :class:`scenarios.online.tags.Measurement` or the belt analyser),
        the range of its values (:func:`scenarios.online.tags.plausible_range`) and how often its
        source reports (:func:`scenarios.online.tags.source_period_h`)."""
        return cls(name, rule.max_age_h, rule.frozen_after_h, rule.freeze_tolerance,
                   rule.uncertain == "accept", plausible, report_period_h)

    def assess(self, reading: Reading, now: datetime, clock: Clock) -> Verdict:
        """The verdict on ``reading`` at wall-clock ``now``."""
        new = reading.time is not None and reading.time != self._last_time and self._new_report(reading, clock)
        if reading.time is not None:
            self._last_time = reading.time
        sev = severity(reading.status)
        code = reading.status_name or f"0x{int(reading.status):08X}"
        if sev == BAD:
            return Verdict(math.nan, BAD, f"status {code}", new)
        if sev == UNCERTAIN and not self.accept_uncertain:
            return Verdict(math.nan, UNCERTAIN, f"status {code} (the tag map rejects Uncertain)", new)
        value = _number(reading.value)
        if value is None:
            return Verdict(math.nan, BAD, f"not a finite number: {reading.value!r}", new)
        if self.plausible is not None and value not in self.plausible:
            return Verdict(math.nan, BAD, f"{self.name} = {value:g} is outside its plausible range "
                           f"{self.plausible}", new)
        if self.max_age_h is not None:
            if reading.time is None:
                return Verdict(math.nan, STALE, "no timestamp", new)
            age_h = clock.hours_between(reading.time, now)
            if abs(age_h) > self.max_age_h:
                what = "old" if age_h > 0 else "in the future (clock skew)"
                return Verdict(math.nan, STALE, f"source timestamp {abs(age_h):.3g} h {what}, limit "
                               f"{self.max_age_h:g} h", new)
        if self._frozen_for_h(value, reading.time, clock) > (self.frozen_after_h or math.inf):
            return Verdict(math.nan, FROZEN, f"value {value:g} unchanged for more than "
                           f"{self.frozen_after_h:g} h", new)
        return Verdict(value, sev, "" if sev == GOOD else f"status {code} accepted", new)

    def _new_report(self, reading: Reading, clock: Clock) -> bool:
        """A reading whose timestamp moved is a new report unless its value is the last new report's and less than
        :data:`REPORT_PERIOD_FRAC` of a report period has passed since (the held value stamped anew)."""
        value = raw_number(reading.value)
        last = self._report
        if (self.report_period_h is not None and last is not None and value == last[1]
                and clock.hours_between(last[0], reading.time) < REPORT_PERIOD_FRAC * self.report_period_h):
            return False
        self._report = (reading.time, value)
        return True

    def _frozen_for_h(self, value: float, time: datetime | None, clock: Clock) -> float:
        """How long (source time) the value has stayed within ``freeze_tolerance`` of itself."""
        if self._value is None or abs(value - self._value) > self.freeze_tolerance or time is None:
            self._value, self._since = value, time
            return 0.0
        return clock.hours_between(self._since, time) if self._since is not None else 0.0
