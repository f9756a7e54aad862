"""First-order breakage of every ore component in every mixer (MISSION.md eq. 5):
dm_i/dt = -S_i m_i + sum_{j<i} b_ij S_j m_j (Austin, Klimpel & Luckie 1984, eq. 3.3).
Each component breaks by its own S and b; S is the ore's nominal selection times the
selection-rate factor the other listed effects contribute, over the hardness-scale disturbance."""

from __future__ import annotations

import casadi as ca

from .base import Effect, EffectContext


class Breakage(Effect):
    name = "breakage"
    uses = ("selection_rate_factor",)
    source = "Austin, Klimpel & Luckie (1984), Process Engineering of Size Reduction, eq. 3.3"
    summary = "-S_i m_i + sum_j b_ij S_j m_j per ore component and mixer"

    def apply(self, ctx: EffectContext) -> None:
        factor = ctx.factor("selection_rate_factor") / ctx.hardness_scale
        for c, ore in enumerate(ctx.spec.breakage):
            s = ca.DM(ore.selection_per_h)
            b = ca.DM(ore.b)
            for k in range(ctx.n_mixers):
                broken = factor * (s * ctx.mass[c][k])  # t/h leaving each class by breakage
                ctx.add_rhs(ctx.mass[c][k], -broken + ca.mtimes(b, broken))
        ctx.note(f"{ctx.n_components} component(s) x {ctx.n_mixers} mixer(s) x {ctx.spec.grid.count} classes; "
                 "S x selection_rate_factor / hardness_scale")
