"""The slow charge between a change of breakage rate and the product: a fraction ``a`` of a change
in the breakage rate the inputs set (mill speed, ore hardness) reaches the mill's content at
once, the rest through a first-order lag of the charge's time constant ``tau`` (a mixed tank,
Seborg et al. 2011, Process Dynamics and Control, 3rd ed., sec. 5.3). In log rate, with
``r = f(speed) / hardness`` the factor the ``speed`` effect and the hardness scale give:

    ln r_eff = a ln r + (1 - a) L,    dL/dt = (ln r - L) / tau,

so the steady state is unchanged and, linearised, every speed or hardness -> output transfer
function is the twin's times ``a + (1 - a) / (1 + tau s)``. Why: in le Roux et al.'s (2013,
Minerals Engineering 43-44) run-of-mine circuit fines are made at the rate the power allows,
FP = P / (D_S phi_f), whatever the charge holds, so a change of speed or hardness moves the
product partly at once and partly as the rock and slurry charge fills or drains over its slow
mode (~1.3 h); the twin's charge of fine feed turns over in minutes and answers at once. Rate
factors the mill's own content sets (hold-up, fines, clay) stay immediate. ``a`` and ``tau`` are
properties of the circuit, identified from step tests (mpc.plants.leroux.matched_twin)."""

from __future__ import annotations

import casadi as ca

from .base import Effect, EffectContext, Option


class ChargeLag(Effect):
    name = "charge_lag"
    requires = ("breakage",)
    uses = ("speed_rate_factor",)
    contributes = ("selection_rate_factor",)
    source = "mixed-tank lag (Seborg et al. 2011 sec. 5.3); le Roux et al. (2013) fines production and charge"
    summary = "ln r_eff = a ln r + (1 - a) L, dL/dt = (ln r - L)/tau, r = speed factor / hardness"
    options = {"fast_frac": Option(0.5, "fraction a of a speed or hardness change that acts at once", float,
                                   lo=0.0, hi=1.0, lo_closed=True, hi_closed=True),
               "time_constant_h": Option(1.0, "time constant tau of the charge [h]", float, lo=0.0, hi=100.0)}

    def apply(self, ctx: EffectContext) -> None:
        a = ctx.param("charge_fast_frac", float(self.settings["fast_frac"]), "-", "identified from a speed step test")
        tau = ctx.param("charge_time_constant_h", float(self.settings["time_constant_h"]), "h",
                        "identified from a feed step test")
        ln_r = ca.log(ctx.get("speed_rate_factor", 1.0)) - ca.log(ctx.hardness_scale)
        lag = ctx.add_state("charge_lag_ln_rate", 1, 0.0)
        ctx.add_rhs(lag, (ln_r - lag[0]) / tau)
        ctx.contribute("selection_rate_factor", ca.exp((1.0 - a) * (lag[0] - ln_r)))
        ctx.note(f"1 lag state (log rate), {a:.3g} of a speed or hardness change at once, the rest in {tau:.3g} h")
