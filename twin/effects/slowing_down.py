"""Non-first-order slowing-down of breakage as the charge becomes fine: a bed of fines
cushions impacts and all rates fall (Austin, Klimpel & Luckie 1984, ch. 10; Austin & Bagga
1981, Powder Technol. 28, 83-90). Modelled as S x 1/(1 + k (F - F0)+), F the mass fraction
of the hold-up finer than 75 um, smoothed at F0."""

from __future__ import annotations

import casadi as ca

from .base import Effect, EffectContext, smooth_max

#: Fines fraction below which breakage stays first order, and the slope above it (Austin et al.
#: 1984, ch. 10: in dry batch grinding rates fall by about half as the powder passes ~70 %
#: finer than 75 um, which these two numbers reproduce: 1/(1 + 2.5 (0.7 - 0.3)) = 0.5).
FINES_SIZE_UM = 75.0
ONSET_FINES_FRAC = 0.3
SLOPE = 2.5


class SlowingDown(Effect):
    name = "slowing_down"
    contributes = ("selection_rate_factor",)
    outputs = ("fines_75um_frac",)
    source = "Austin, Klimpel & Luckie (1984) ch. 10; Austin & Bagga (1981)"
    summary = "S / (1 + k max(F75 - F0, 0))"

    def apply(self, ctx: EffectContext) -> None:
        grid = ctx.spec.grid
        w = ca.DM(grid.passing_weights(FINES_SIZE_UM))
        m = ctx.class_mass()
        eps = 1e-9
        fines = ctx.aggregate("fines_mass_t", ca.dot(w, m)) / (ctx.holdup() + eps)
        k = ctx.param("slowing_down_slope", SLOPE, "-", "Austin et al. 1984")
        f0 = ctx.param("slowing_down_onset_frac", ONSET_FINES_FRAC, "-", "Austin et al. 1984")
        ctx.contribute("selection_rate_factor", 1.0 / (1.0 + k * smooth_max(fines - f0, 0.0, 0.02)))
        ctx.output("fines_75um_frac", fines)
        ctx.note("selection factor from the fraction of the hold-up below 75 um")
