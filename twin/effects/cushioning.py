"""Cushioning by clay and mica (and chlorite): soft, platy phyllosilicates in the charge absorb
impact energy in sliding and deformation, so every component breaks more slowly, and a
lubricated, viscous charge draws less power (Shi & Napier-Munn 2002, Int. J. Miner. Process.
65, 195-214, mill power and breakage against slurry rheology; MISSION.md 'physical reasons').

The soft fraction is the mass fraction of clay + mica + chlorite
(twin.ore.minerals.CUSHIONING_MINERALS) in the hold-up, computed from the states, so a clay-rich
component slows a hard one in a blend. Coefficients come from the calibration file
(``twin/calibration/files/table.json``)."""

from __future__ import annotations

from .base import Assembly, Effect


class Cushioning(Effect):
    name = "cushioning"
    source = "Shi & Napier-Munn (2002); coefficients from twin/calibration/files/table.json"
    summary = "S / (1 + k_rate phi_soft); power / (1 + k_power phi_soft)"

    def apply(self, asm: Assembly) -> None:
        spec = asm.spec
        k_rate = asm.param("cushioning_rate_coeff", spec.coefficients["cushioning_rate_coeff"], "-",
                           "calibration.json")
        k_power = asm.param("cushioning_power_coeff", spec.coefficients["cushioning_power_coeff"], "-",
                            "calibration.json")
        phi_soft = asm.holdup_fraction("soft_mass_t", spec.soft_frac)
        asm.rate_factors.append(1.0 / (1.0 + k_rate * phi_soft))
        asm.power_factors.append(1.0 / (1.0 + k_power * phi_soft))
        asm.outputs["soft_frac"] = phi_soft
        asm.note(self.name, "selection and power factors from the clay+mica+chlorite fraction of the hold-up")
