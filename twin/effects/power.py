"""Mill power draw and specific energy: Bond's net-power equation for overflow ball mills
(see :func:`twin.mill.bond_power_kw`), times the power factors of other listed effects
(cushioning). Specific energy is power per tonne of fresh feed [kWh/t]."""

from __future__ import annotations

from ..mill import bond_power_kw
from .base import Assembly, Effect, smooth_max


class Power(Effect):
    name = "power"
    source = "Bond (1961) in metric form, Gupta & Yan (2016) eq. 9.28"
    summary = "power_kw(speed) x power factors; specific_energy_kwh_t = power / feed"

    def apply(self, asm: Assembly) -> None:
        spec = asm.spec
        power = bond_power_kw(spec.mill, asm.speed) * asm.power_factor()
        asm.outputs["power_kw"] = power
        feed_floor = 1e-6 * spec.feed_nominal_tph
        asm.outputs["specific_energy_kwh_t"] = power / smooth_max(asm.feed_tph, feed_floor, feed_floor)
        asm.note(self.name, "power and specific-energy outputs (no states)")
