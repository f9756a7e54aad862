"""Mill power draw and specific energy: Bond's net-power equation for overflow ball mills
(:func:`twin.mill.bond_power_kw`, the calibrated default) or the torque-arm model of Hogg &
Fuerstenau (:func:`twin.mill.hogg_fuerstenau_power_kw`, option ``model``), times the power
factors of other listed effects (cushioning). Specific energy is power per tonne of fresh
feed [kWh/t]."""

from __future__ import annotations

from ..errors import ModelError
from ..mill import bond_power_kw, hogg_fuerstenau_power_kw
from .base import Assembly, Effect, smooth_max


class Power(Effect):
    name = "power"
    source = "Bond (1961) in metric form, Gupta & Yan (2016) eq. 9.28; Hogg & Fuerstenau (1972)"
    summary = "power_kw(speed) x power factors; specific_energy_kwh_t = power / feed"
    options = {"model": ("bond", "'bond' (calibrated default) or 'hogg_fuerstenau'")}
    MODELS = {"bond": bond_power_kw, "hogg_fuerstenau": hogg_fuerstenau_power_kw}

    def apply(self, asm: Assembly) -> None:
        spec = asm.spec
        name = self.settings["model"]
        if name not in self.MODELS:
            raise ModelError(f"The 'model' option of effect 'power' must be one of {list(self.MODELS)}. "
                             f"Got {name!r}.")
        power = self.MODELS[name](spec.mill, asm.speed) * asm.power_factor()
        asm.outputs["power_kw"] = power
        feed_floor = 1e-6 * spec.feed_nominal_tph
        asm.outputs["specific_energy_kwh_t"] = power / smooth_max(asm.feed_tph, feed_floor, feed_floor)
        asm.note(self.name, f"power ({name}) and specific-energy outputs (no states)")
