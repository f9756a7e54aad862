"""Particle-size analyser dead time on P80: an Erlang chain of n first-order lags, each with
time constant theta/n, approximating the dead time theta (the chain's delay is exactly theta
in mean; Seborg et al. 2011, Process Dynamics and Control, 3rd ed., sec. 6.2). Sample-and-hold
at the analyser's period happens in the closed loop's sensor, not in the model."""

from __future__ import annotations

from .base import Assembly, Effect


class SensorDelay(Effect):
    name = "sensor_delay"
    source = "Seborg et al. (2011) sec. 6.2 (lag chain for dead time)"
    summary = "p80_measured_um through an n-stage lag chain of total delay theta"
    options = {"dead_time_h": (5.0 / 60.0, "analyser dead time [h]"),
               "stages": (3, "lags in the chain")}
    after_outputs = True

    def apply(self, asm: Assembly) -> None:
        theta = asm.param("analyser_dead_time_h", float(self.settings["dead_time_h"]), "h", "scene")
        n = int(self.settings["stages"])
        p80 = asm.outputs["p80_um"]
        z = asm.add_state("p80_lag_um", n, asm.spec.p80_initial_um)
        upstream = p80
        for i in range(n):
            asm.add_rhs(z, _unit(n, i) * (upstream - z[i]) * n / theta)
            upstream = z[i]
        asm.outputs["p80_measured_um"] = z[n - 1]
        asm.note(self.name, f"{n} lag states, dead time {theta * 60:.1f} min")


def _unit(n, i):
    import casadi as ca

    e = ca.DM.zeros(n)
    e[i] = 1.0
    return e
