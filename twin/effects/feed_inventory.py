"""Feed inventory ahead of the grinding: the fresh feed reaches the mill's size classes through a
perfectly mixed inventory of time constant tau, dI/dt = F - I / tau, arriving at I / tau [t/h]
(a first-order lag in the feed; Seborg et al. 2011, Process Dynamics and Control, 3rd ed.,
sec. 5.3: a mixed tank). It stands for a charge the twin's feed does not hold: a run-of-mine mill
keeps rocks above its grate size and a slurry charge whose slow mode sets how fast a feed change
reaches the product (le Roux et al. 2013, Minerals Engineering 43-44: its rock and slurry charge
respond in ~1.3 h, while the twin's charge of fine feed turns over in minutes). tau is a property
of the circuit, identified from a feed step test (mpc.plants.leroux.matched_twin), not of the ore.
The inventory is outside the mill's hold-up (``holdup_t``); its mass is ``feed_inventory_t``."""

from __future__ import annotations

from .base import Effect, EffectContext, Option


class FeedInventory(Effect):
    name = "feed_inventory"
    provides = ("feed_arrival_tph",)
    outputs = ("feed_inventory_t",)
    source = "mixed-tank lag (Seborg et al. 2011 sec. 5.3); le Roux et al. (2013) rock and slurry charge"
    summary = "feed reaches the mill through a mixed inventory: dI/dt = F - I/tau"
    options = {"time_constant_h": Option(1.0, "time constant of the inventory [h]", float, lo=0.0, hi=100.0)}

    def apply(self, ctx: EffectContext) -> None:
        tau = ctx.param("feed_inventory_time_constant_h", float(self.settings["time_constant_h"]), "h",
                        "identified from a feed step test")
        inv = ctx.add_state("feed_inventory_t", 1, tau * ctx.spec.feed_nominal_tph)
        ctx.add_rhs(inv, ctx.feed_tph - inv / tau)
        ctx.provide("feed_arrival_tph", inv[0] / tau)
        ctx.output("feed_inventory_t", inv[0])
        ctx.note(f"1 inventory state, time constant {tau:.3g} h")
