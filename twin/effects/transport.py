"""Continuous flow through N perfect mixers in series (Austin, Klimpel & Luckie 1984, ch. 9:
residence-time distribution of a ball mill as a few fully mixed reactors in series), of equal
volume or of the shares ``ModelSpec.mixer_fracs`` (Whiten's one large and two small mixers:
Whiten 1974, in Napier-Munn et al. 1996, JKMRC Monograph 2, ch. 10; Austin et al. 1984 ch. 9
report industrial ball mills as one large mixer of ~0.7 of the mean residence time and two
small ones).

Fresh feed [t/h] (or what arrives of it through ``feed_inventory``) enters mixer 0 split by the
blend fractions, each component with the feed size distribution (in a reverse circuit it joins
the mill discharge at the classifier instead); mixer k discharges ``r_k m_k`` into mixer k+1;
the last mixer's discharge
(times the class factor of a grate, if listed) is the mill discharge, split by a classifier
into product and recycle when one is listed. Without ``holdup`` the rate is fixed by the
nominal mean residence time tau = H_nom / Q_nom (Q_nom the mill's free discharge at nominal
hold-up with the circuit's flow multiplier, :meth:`twin.mill.Mill.free_discharge_tph`: a volume
flow, so tau does not depend on the solids density). The product's size distribution gives
the product P80 (a smooth interpolation, :func:`twin.sizes.smooth_pxx`)."""

from __future__ import annotations

import casadi as ca

from ..sizes import smooth_pxx
from .base import Effect, EffectContext


class Transport(Effect):
    name = "transport"
    uses = ("discharge_rate_law", "discharge_class_factor", "product_split", "flow_multiplier", "feed_arrival_tph",
            "feed_to_classifier")
    outputs = ("product_tph", "throughput_tph", "discharge_tph", "p80_um", "psd_frac", "ore_product_tph")
    source = "Austin, Klimpel & Luckie (1984), ch. 9 (mixers in series)"
    summary = "feed in, discharge out, N mixers in series; product P80"

    def apply(self, ctx: EffectContext) -> None:
        spec = ctx.spec
        n_mix = ctx.n_mixers
        q_mill = spec.mill.free_discharge_tph(spec.solids_density_t_m3, ctx.get("flow_multiplier", 1.0))
        tau_h = ctx.param("residence_time_nominal_h", spec.holdup_nominal_t / q_mill,
                          "h", "H_nom / mill through-flow at nominal")
        fracs = spec.mixer_fracs
        rate = ctx.get("discharge_rate_law", lambda k: 1.0 / (fracs[k] * tau_h))
        class_factor = ctx.get("discharge_class_factor")
        feed = ca.DM(spec.feed_frac)
        arrival_tph = ctx.get("feed_arrival_tph", ctx.feed_tph)  # the fresh feed, or through an inventory
        to_classifier = ctx.get("feed_to_classifier", False)  # a reverse circuit: fresh feed to the cyclones
        discharge, fresh = [], []
        for c in range(ctx.n_components):
            fresh.append(arrival_tph * ctx.blend(c) * feed)
            inflow = 0.0 * feed if to_classifier else fresh[c]
            for k in range(n_mix):
                out = rate(k) * ctx.mass[c][k]
                if k == n_mix - 1 and class_factor is not None:
                    cf = class_factor[c] if isinstance(class_factor, list) else class_factor  # per ore, or one
                    out = out * (cf if isinstance(cf, ca.SX) else ca.DM(cf))
                ctx.add_rhs(ctx.mass[c][k], inflow - out)
                inflow = out
            discharge.append(inflow)
        split = ctx.get("product_split")
        if split is not None:
            product, recycle = split(discharge, fresh if to_classifier else None)
            for c in range(ctx.n_components):
                ctx.add_rhs(ctx.mass[c][0], recycle[c])
        else:
            product = discharge
        product_tph = sum(product)
        ctx.output("product_tph", product_tph)  # per size class
        ctx.output("ore_product_tph", ca.horzcat(*product))  # per size class (rows) and ore (columns)
        ctx.output("throughput_tph", ca.sum1(product_tph))
        ctx.output("discharge_tph", ca.sum1(sum(discharge)))
        ctx.output("p80_um", smooth_pxx(spec.grid, product_tph))
        ctx.output("psd_frac", product_tph / (ca.sum1(product_tph) + 1e-12 * spec.holdup_nominal_t))
        ctx.note(f"{n_mix} mixer(s) in series; feed, inter-mixer flow, discharge, product P80")
