"""Selection rates as a smooth function of mill speed: Austin's speed factor
(Austin, Klimpel & Luckie 1984, eq. 8.4), normalised at the mill's nominal speed; the factor is
also provided as ``speed_rate_factor`` for ``charge_lag``."""

from __future__ import annotations

from ..breakage import austin_speed_factor
from .base import Effect, EffectContext


class Speed(Effect):
    name = "speed"
    provides = ("speed_rate_factor",)
    contributes = ("selection_rate_factor",)
    source = "Austin, Klimpel & Luckie (1984), eq. 8.4"
    summary = "S x f(phi_c)/f(phi_c,nom), f = (phi_c - 0.1)/(1 + exp(15.7 (phi_c - 0.94)))"

    def apply(self, ctx: EffectContext) -> None:
        nominal = ctx.spec.mill.speed_nominal_frac_critical
        factor = austin_speed_factor(ctx.speed) / austin_speed_factor(nominal)
        ctx.provide("speed_rate_factor", factor)
        ctx.contribute("selection_rate_factor", factor)
        ctx.note(f"selection factor from speed, normalised at {nominal:.2f} of critical")
