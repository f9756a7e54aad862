"""Mill load dynamics: discharge depends on hold-up, breakage rates on the powder filling.

- Discharge: the flow out of a mixer rises with its content, Q = Q_nom (H/H_nom)^n, Q_nom the
  mill's free discharge at nominal hold-up (:meth:`twin.mill.Mill.free_discharge_tph`: a volume
  flow, so its mass grows with the solids density as H_nom does); n = 2 is Morrell & Stephenson's
  grate-discharge law (1996, Powder Technol. 88, 63-69), the flow through a grate rising as the
  square of the mill's slurry hold-up (le Roux et al.'s circuit model, 2013, eq. 9, discharges in
  proportion to the content at a fixed slurry composition).
- Breakage: energy-specific selection S = S^E P / H (Herbst & Fuerstenau 1980): above the
  powder filling where rates saturate, the same power is shared by more ore, so S ~ 1/H;
  below it (U < 0.5, Austin et al. 1984, fig. 8.3, ball-on-ball impacts waste energy) the
  rates stop rising; the powder filling is U_nom x load (U_nom the mill's ``powder_filling_nominal``).
  The smooth maximum keeps the model differentiable near an empty mill.
- Load status from load = H / H_nom by volume (H_nom a volume at the nominal blend's density; the content's
  masses weighed by their own densities): under, stable, over by the mill's stable band."""

from __future__ import annotations

from .base import Effect, EffectContext, smooth_max

#: Powder filling U (fraction of the ball bed's voids) below which selection rates stop rising: Austin et al.
#: (1984), fig. 8.3, rates per unit power level off below a powder filling of ~0.5 of the bed voids.
RATE_SATURATION_POWDER_FILLING = 0.5


class Holdup(Effect):
    name = "holdup"
    requires = ("transport",)
    provides = ("discharge_rate_law",)
    contributes = ("selection_rate_factor",)
    outputs = ("load_frac",)
    uses = ("flow_multiplier",)
    source = "Herbst & Fuerstenau (1980); Morrell & Stephenson (1996); Austin et al. (1984) fig. 8.3"
    summary = "discharge Q_nom (H/H_nom)^n; S ~ H_nom / max(H, H_sat); load status"

    def apply(self, ctx: EffectContext) -> None:
        spec = ctx.spec
        h_nom = spec.holdup_nominal_t
        q_nom = spec.mill.free_discharge_tph(spec.solids_density_t_m3, ctx.get("flow_multiplier", 1.0))
        n = ctx.param("discharge_exponent", spec.mill.discharge_exponent, "-", "Morrell & Stephenson 1996")
        # U = 0.5 is load 0.5 / U_nom: a mill filled to U_nom = 0.5 at nominal saturates at its nominal load
        h_sat = ctx.param("rate_saturation_load", RATE_SATURATION_POWDER_FILLING / spec.mill.powder_filling_nominal,
                          "H/H_nom", "Austin et al. 1984, at U = 0.5")

        fracs = spec.mixer_fracs

        def rate(k):
            # mixer k holds its share f_k of the nominal hold-up (a volume) at nominal flow
            load_k = smooth_max(ctx.packed_holdup(k) / (fracs[k] * h_nom), 0.0, 1e-3)
            return q_nom / (fracs[k] * h_nom) * load_k ** (n - 1.0)

        ctx.provide("discharge_rate_law", rate)
        load = ctx.packed_holdup() / h_nom  # by volume: a denser ore fills the mill at more tonnes
        # S = S^E P / max(H, H_sat): the filling by volume, its mass at the content's density (rho / rho_nom)
        ctx.contribute("selection_rate_factor", 1.0 / (ctx.content_density_ratio() * smooth_max(load, h_sat, 0.05)))
        ctx.output("load_frac", load)
        ctx.note(f"discharge law on every mixer; selection factor 1/max(load, {h_sat:.3g})")
