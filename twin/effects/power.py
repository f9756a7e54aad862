"""Mill power draw and specific energy: Bond's net-power equation for overflow ball mills
(:func:`twin.mill.bond_power_kw`, the calibrated default) or the torque-arm model of Hogg &
Fuerstenau (:func:`twin.mill.hogg_fuerstenau_power_kw`, option ``model``), times the power
factor of other listed effects (cushioning). Specific energy is power per tonne of fresh
feed [kWh/t]."""

from __future__ import annotations

from ..mill import bond_power_kw, hogg_fuerstenau_power_kw
from .base import Effect, EffectContext, Option, smooth_max

MODELS = {"bond": bond_power_kw, "hogg_fuerstenau": hogg_fuerstenau_power_kw}


class Power(Effect):
    name = "power"
    uses = ("power_factor",)
    outputs = ("power_kw", "specific_energy_kwh_t")
    source = "Bond (1961) in metric form, Gupta & Yan (2016) eq. 9.28; Hogg & Fuerstenau (1972)"
    summary = "power_kw(speed) x power factor; specific_energy_kwh_t = power / feed"
    options = {"model": Option("bond", "mill power model: 'bond' (calibrated default) or 'hogg_fuerstenau'",
                               choices=tuple(MODELS))}

    def apply(self, ctx: EffectContext) -> None:
        spec = ctx.spec
        name = self.settings["model"]
        power = MODELS[name](spec.mill, ctx.speed) * ctx.factor("power_factor")
        ctx.output("power_kw", power)
        feed_floor = 1e-6 * spec.feed_nominal_tph
        ctx.output("specific_energy_kwh_t", power / smooth_max(ctx.feed_tph, feed_floor, feed_floor))
        ctx.note(f"power ({name}) and specific-energy outputs (no states)")
