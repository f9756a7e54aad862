"""First-order breakage of every ore component in every mixer (MISSION.md eq. 5):
dm_i/dt = -S_i m_i + sum_{j<i} b_ij S_j m_j (Austin, Klimpel & Luckie 1984, eq. 3.3).
Each component breaks by its own S and b; S is the ore's nominal selection times the rate
factors of the other listed effects and the hardness-scale disturbance."""

from __future__ import annotations

import casadi as ca

from .base import Assembly, Effect


class Breakage(Effect):
    name = "breakage"
    source = "Austin, Klimpel & Luckie (1984), Process Engineering of Size Reduction, eq. 3.3"
    summary = "-S_i m_i + sum_j b_ij S_j m_j per ore component and mixer"

    def apply(self, asm: Assembly) -> None:
        factor = asm.rate_factor() / asm.hardness_scale
        for c, ore in enumerate(asm.spec.breakage):
            s = ca.DM(ore.selection_per_h)
            b = ca.DM(ore.b)
            for k in range(asm.n_mixers):
                broken = factor * (s * asm.mass[c][k])  # t/h leaving each class by breakage
                asm.add_rhs(asm.mass[c][k], -broken + ca.mtimes(b, broken))
        asm.note(self.name, f"{asm.n_components} component(s) x {asm.n_mixers} mixer(s) x "
                            f"{asm.spec.grid.count} classes; S scaled by {len(asm.rate_factors)} "
                            "rate factor(s) / hardness_scale")
