"""Particle-size analyser dead time on P80: an Erlang chain of n first-order lags, each with
time constant theta/n, approximating the dead time theta (the chain's delay is exactly theta
in mean; Seborg et al. 2011, Process Dynamics and Control, 3rd ed., sec. 6.2). Sample-and-hold
at the analyser's period happens in the closed loop's sensor, not in the model."""

from __future__ import annotations

import casadi as ca

from ..errors import ModelError
from .base import Effect, EffectContext, Option

#: The longest analyser dead time over the mill's nominal residence time (without recycle): a
#: mill's product answers a step within a few residence times (a chain of mixers, Austin et al.
#: 1984 ch. 9), and on-line analysers report in minutes; ten residence times is a dead time given
#: in minutes where hours are expected (5 for 5 min is 15 residence times of the laboratory mill).
DEAD_TIME_MAX_RESIDENCE_TIMES = 10.0


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
        _check_dead_time(ctx.spec, theta)
        n = int(self.settings["stages"])
        z = ctx.add_state("p80_lag_um", n, ctx.spec.p80_initial_um)
        upstream = ctx.get("p80_um")
        for i in range(n):
            ctx.add_rhs(z, _unit(n, i) * (upstream - z[i]) * n / theta)
            upstream = z[i]
        ctx.output("p80_measured_um", z[n - 1])
        ctx.note(f"{n} lag states, dead time {theta * 60:.1f} min")


def _check_dead_time(spec, theta_h: float) -> None:
    """Refuse a dead time [h] longer than :data:`DEAD_TIME_MAX_RESIDENCE_TIMES` nominal residence
    times of the mill (H_nom over its free discharge, as twin.effects.transport without recycle)."""
    tau_h = spec.holdup_nominal_t / spec.mill.free_discharge_tph(spec.solids_density_t_m3)
    if theta_h > DEAD_TIME_MAX_RESIDENCE_TIMES * tau_h:
        raise ModelError(f"The 'dead_time_h' option of effect 'sensor_delay' must be at most "
                         f"{DEAD_TIME_MAX_RESIDENCE_TIMES:g} of the mill's nominal residence times "
                         f"({DEAD_TIME_MAX_RESIDENCE_TIMES * tau_h:.3g} h; one is {tau_h:.3g} h), in hours "
                         f"(5 min is 0.0833 h). Got {theta_h!r}.")


def _unit(n, i):
    e = ca.DM.zeros(n)
    e[i] = 1.0
    return e
