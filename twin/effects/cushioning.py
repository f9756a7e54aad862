"""Cushioning by clay and mica (and chlorite): soft, platy phyllosilicates in the charge absorb
impact energy in sliding and deformation, so every component breaks more slowly per unit of
energy (MISSION.md 'physical reasons': a clay-rich charge dissipates energy in sliding instead
of breaking harder grains, and micas add to that; Shi & Napier-Munn 2002, "Effects of slurry
rheology on industrial grinding performance", Int. J. Miner. Process. 65). The energy is still drawn: cushioning
slows the rates, not the power (the power falls with the slurry's viscosity, which clays raise
and micas do not: twin.effects.rheology).

The soft fraction is the mass fraction of clay + mica + chlorite
(twin.ore.CUSHIONING_MINERALS) in the hold-up, computed from the states, so a clay-rich
component slows a hard one in a blend. The coefficient comes from the calibration."""

from __future__ import annotations

from .base import Effect, EffectContext


class Cushioning(Effect):
    name = "cushioning"
    contributes = ("selection_rate_factor",)
    outputs = ("soft_frac",)
    source = "Shi & Napier-Munn (2002); MISSION.md; coefficient from the calibration"
    summary = "S / (1 + k_rate phi_soft)"

    def apply(self, ctx: EffectContext) -> None:
        coef = ctx.spec.coefficients
        k_rate = ctx.param("cushioning_rate_coeff", coef["cushioning_rate_coeff"], "-", "calibration")
        phi_soft = ctx.holdup_fraction("soft_mass_t", ctx.spec.soft_frac)
        ctx.contribute("selection_rate_factor", 1.0 / (1.0 + k_rate * phi_soft))
        ctx.output("soft_frac", phi_soft)
        ctx.note("selection factor from the clay+mica+chlorite fraction of the hold-up")
