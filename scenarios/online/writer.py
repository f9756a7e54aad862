"""Bounds and rate limits enforced again where the setpoints leave the service, whatever the
controller asked for: a non-finite move is refused, a move is clipped to the rate limit around
the reference (the actual input, else the last written setpoint), then to the bounds."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Limit:
    """Limits of one setpoint (units of the setpoint; rate per plant hour)."""

    name: str
    min: float
    max: float
    rate_max_per_h: float = math.inf

    @classmethod
    def of(cls, name: str, setpoint) -> "Limit":
        """From a completed tag map entry (:class:`scenarios.online.tags.Setpoint`)."""
        return cls(name, float(setpoint.min), float(setpoint.max), float(setpoint.rate_max_per_h))


def limit_move(proposed: float, reference: float | None, dt_h: float, lim: Limit) -> tuple[float | None, list[str]]:
    """``(value to write or None, notes)``: None when nothing may be written (a non-finite
    move with no reference to hold)."""
    notes = []
    has_ref = reference is not None and math.isfinite(reference)
    if not math.isfinite(proposed):
        if not has_ref:
            return None, [f"{lim.name}: non-finite move {proposed!r} refused, nothing to hold"]
        return reference, [f"{lim.name}: non-finite move {proposed!r} refused, held at {reference:.6g}"]
    value = proposed
    if has_ref and math.isfinite(lim.rate_max_per_h):
        step = lim.rate_max_per_h * dt_h
        clipped = min(max(value, reference - step), reference + step)
        if clipped != value:
            notes.append(f"{lim.name}: move {value - reference:+.4g} clipped to the rate limit "
                         f"{lim.rate_max_per_h:g}/h ({step:.4g} a sample)")
        value = clipped
    bounded = min(max(value, lim.min), lim.max)
    if bounded != value:
        notes.append(f"{lim.name}: {value:.6g} clipped to the bound [{lim.min:g}, {lim.max:g}]")
        if has_ref and math.isfinite(lim.rate_max_per_h) and abs(bounded - reference) > lim.rate_max_per_h * dt_h:
            # the bounds win over the rate limit: a setpoint left outside them (a manual period) comes back at once
            notes.append(f"{lim.name}: the move {bounded - reference:+.4g} from {reference:.6g}, outside the bounds, "
                         f"exceeds the rate limit ({lim.rate_max_per_h * dt_h:.4g} a sample): the bounds come first")
    return bounded, notes
