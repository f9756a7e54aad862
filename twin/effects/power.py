"""Mill power draw and specific energy: the mill's net-power model (:func:`twin.mill.power_kw`:
Bond's equation for overflow ball mills, the calibrated default, or the torque-arm model of Hogg &
Fuerstenau; a given net power shaped with speed by the model), or the model the ``model`` option
names, times the power factor of other listed effects (the slurry's rheology; a given net power too). Specific energy is net power
per tonne of fresh feed [kWh/t]. The model used is a parameter of the built model (describe())."""

from __future__ import annotations

from dataclasses import replace

from ..mill import POWER_MODELS, power_kw
from .base import Effect, EffectContext, Option, smooth_max


class Power(Effect):
    name = "power"
    uses = ("power_factor",)
    outputs = ("power_kw", "specific_energy_kwh_t")
    source = "Bond (1961) in metric form, Gupta & Yan (2016) eq. 9.28; Hogg & Fuerstenau (1972)"
    summary = "power_kw(speed) x power factor; specific_energy_kwh_t = power / feed"
    options = {"model": Option(None, "net-power model instead of the mill's own (default: the mill's): 'bond' "
                               "(the calibrated default) or 'hogg_fuerstenau'", choices=tuple(POWER_MODELS))}

    def apply(self, ctx: EffectContext) -> None:
        spec = ctx.spec
        mill = spec.mill if self.settings["model"] is None else replace(spec.mill, power_model=self.settings["model"])
        name = mill.power_model + (f", net {mill.net_power_kw:g} kW given at nominal speed"
                                   if mill.net_power_kw is not None else "")
        power = power_kw(mill, ctx.speed) * ctx.factor("power_factor")
        ctx.output("power_kw", power)
        feed_floor = 1e-6 * spec.feed_nominal_tph
        ctx.output("specific_energy_kwh_t", power / smooth_max(ctx.feed_tph, feed_floor, feed_floor))
        ctx.note(f"power ({name}) and specific-energy outputs (no states)")
