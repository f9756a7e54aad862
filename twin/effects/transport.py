"""Continuous flow through N perfect mixers in series (Austin, Klimpel & Luckie 1984, ch. 9:
residence-time distribution of a ball mill as a few fully mixed reactors in series).

Fresh feed [t/h] enters mixer 0 split by the blend fractions, each component with the feed
size distribution; mixer k discharges ``r_k m_k`` into mixer k+1; the last mixer's discharge
(times the class factor of a grate, if listed) is the mill discharge. Without ``holdup`` the
rate is fixed by the nominal mean residence time tau = H_nom / Q_nom (Q_nom the nominal feed
times the mill's ``discharge_factor``)."""

from __future__ import annotations

import casadi as ca

from .base import Assembly, Effect


class Transport(Effect):
    name = "transport"
    source = "Austin, Klimpel & Luckie (1984), ch. 9 (mixers in series)"
    summary = "feed in, discharge out, N mixers in series"

    def apply(self, asm: Assembly) -> None:
        spec = asm.spec
        n_mix = asm.n_mixers
        q_mill = spec.feed_nominal_tph * asm.flow_multiplier * spec.mill.discharge_factor
        tau_h = asm.param("residence_time_nominal_h", spec.holdup_nominal_t / q_mill,
                          "h", "H_nom / mill through-flow at nominal")
        if asm.discharge_rate is None:
            asm.discharge_rate = lambda k, h_k: n_mix / tau_h
        feed = ca.DM(spec.feed_frac)
        discharge = []
        for c in range(asm.n_components):
            inflow = asm.feed_tph * asm.blend(c) * feed
            for k in range(n_mix):
                rate = asm.discharge_rate(k, asm.holdup(k))
                out = rate * asm.mass[c][k]
                if k == n_mix - 1 and asm.class_factor is not None:
                    out = out * (asm.class_factor if isinstance(asm.class_factor, ca.SX) else ca.DM(asm.class_factor))
                asm.add_rhs(asm.mass[c][k], inflow - out)
                inflow = out
            discharge.append(inflow)
        if asm.product_split is not None:
            product, recycle = asm.product_split(discharge)
            for c in range(asm.n_components):
                asm.add_rhs(asm.mass[c][0], recycle[c])
        else:
            product = discharge
        product_tph = sum(product)
        asm.outputs["product_tph"] = product_tph  # per size class
        asm.outputs["throughput_tph"] = ca.sum1(product_tph)
        asm.outputs["discharge_tph"] = ca.sum1(sum(discharge))
        asm.note(self.name, f"{n_mix} mixer(s) in series; feed, inter-mixer flow, discharge")
