"""Particle-size analyser dead time on P80: an Erlang chain of n first-order lags, each with
time constant theta/n, approximating the dead time theta (the chain's delay is exactly theta
in mean; Seborg et al. 2011, Process Dynamics and Control, 3rd ed., sec. 6.2). Sample-and-hold
at the analyser's period happens in the closed loop's sensor, not in the model."""

from __future__ import annotations

import casadi as ca

from .base import Effect, EffectContext, Option


class SensorDelay(Effect):
    name = "sensor_delay"
    needs = ("p80_um",)
    outputs = ("p80_measured_um",)
    source = "Seborg et al. (2011) sec. 6.2 (lag chain for dead time)"
    summary = "p80_measured_um through an n-stage lag chain of total delay theta"
    options = {"dead_time_h": Option(5.0 / 60.0, "analyser dead time [h]", float, lo=0.0, hi=24.0),
               "stages": Option(3, "first-order lags in the chain", int, lo=1, hi=50, lo_closed=True, hi_closed=True)}

    def apply(self, ctx: EffectContext) -> None:
        theta = ctx.param("analyser_dead_time_h", float(self.settings["dead_time_h"]), "h", "scene")
        n = int(self.settings["stages"])
        z = ctx.add_state("p80_lag_um", n, ctx.spec.p80_initial_um)
        upstream = ctx.get("p80_um")
        for i in range(n):
            ctx.add_rhs(z, _unit(n, i) * (upstream - z[i]) * n / theta)
            upstream = z[i]
        ctx.output("p80_measured_um", z[n - 1])
        ctx.note(f"{n} lag states, dead time {theta * 60:.1f} min")


def _unit(n, i):
    e = ca.DM.zeros(n)
    e[i] = 1.0
    return e
