"""Selection rates as a smooth function of mill speed: Austin's speed factor
(Austin, Klimpel & Luckie 1984, eq. 8.4), normalised at the mill's nominal speed. The drum DEM
calibration replaces it by collision-spectrum rates when it lands."""

from __future__ import annotations

from ..breakage import austin_speed_factor
from .base import Assembly, Effect


class Speed(Effect):
    name = "speed"
    source = "Austin, Klimpel & Luckie (1984), eq. 8.4"
    summary = "S x f(phi_c)/f(phi_c,nom), f = (phi_c - 0.1)/(1 + exp(15.7 (phi_c - 0.94)))"

    def apply(self, asm: Assembly) -> None:
        nominal = asm.spec.mill.speed_nominal_frac_critical
        asm.rate_factors.append(austin_speed_factor(asm.speed) / austin_speed_factor(nominal))
        asm.note(self.name, f"selection factor from speed, normalised at {nominal:.2f} of critical")
