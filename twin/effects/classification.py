"""Size-dependent discharge: a grate at the mill's discharge end, or a closed circuit with a
hydrocyclone whose underflow returns to the mill feed (the industrial configuration).

- Grate: discharge factor c_i = 1 / (1 + (x_i / d50)^k) (Austin, Klimpel & Luckie 1984, ch. 9,
  internal classification of grate-discharge mills), d50 and k from the mill.
- Both cut sizes are multiplied by the assembly's ``cut_size_factor`` (1 unless ``rheology``
  is listed).
- Hydrocyclone: Plitt (1976, CIM Bull. 69, 114-123) with the corrections of Flintoff, Plitt &
  Turak (1987, CIM Bull. 80, 39-50): corrected cut size d50c, sharpness m and volumetric flow
  split from the cyclone geometry and feed; corrected efficiency E_c = 1 - exp(-0.693 (d/d50c)^m)
  and actual partition to underflow E = R_f + (1 - R_f) E_c, R_f the water (and fine solids)
  bypass. The cut size follows the cyclone feed as d50c ~ Q^-0.45 (Plitt), the feed being
  diluted at the sump to a fixed solids content."""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.constants import g as G_M_S2

from ..errors import ModelError
from .base import Effect, EffectContext, Option, smooth_max


@dataclass(frozen=True)
class Hydrocyclone:
    """Cyclone geometry [cm], count, and the sump's feed solids [% by volume] and viscosity."""

    diameter_cm: float = 38.0
    inlet_cm: float = 11.0
    vortex_finder_cm: float = 13.0
    apex_cm: float = 7.5
    free_vortex_height_cm: float = 120.0
    count: int = 2
    feed_solids_vol_pct: float = 30.0
    viscosity_cp: float = 1.0

    def plitt(self, slurry_flow_m3_h: float, solids_density_t_m3: float) -> dict:
        """Plitt's d50c [um], sharpness m, pressure [kPa], volumetric split S = Qu/Qo and water
        bypass R_f = S/(1+S), for the total slurry flow shared by ``count`` cyclones."""
        q = slurry_flow_m3_h * 1000.0 / 60.0 / self.count  # L/min per cyclone
        dc, di, do, du, h = (self.diameter_cm, self.inlet_cm, self.vortex_finder_cm,
                             self.apex_cm, self.free_vortex_height_cm)
        phi = self.feed_solids_vol_pct
        d50c = (39.7 * dc ** 0.46 * di ** 0.6 * do ** 1.21 * self.viscosity_cp ** 0.5
                * math.exp(0.063 * phi)
                / (du ** 0.71 * h ** 0.38 * q ** 0.45 * (solids_density_t_m3 - 1.0) ** 0.5))
        p_kpa = 1.88 * q ** 1.78 * math.exp(0.0055 * phi) / (
            dc ** 0.37 * di ** 0.94 * h ** 0.28 * (du ** 2 + do ** 2) ** 0.87)
        rho_slurry = 1.0 + phi / 100.0 * (solids_density_t_m3 - 1.0)
        head_m = p_kpa / (G_M_S2 * rho_slurry)
        split = (1.9 * (du / do) ** 3.31 * h ** 0.54 * (du ** 2 + do ** 2) ** 0.36
                 * math.exp(0.0054 * phi) / (head_m ** 0.24 * dc ** 1.11))
        m = 1.94 * math.exp(-1.58 * split / (1 + split)) * (dc ** 2 * h / q) ** 0.15
        return {"d50c_um": d50c, "sharpness_m": m, "pressure_kpa": p_kpa,
                "volume_split": split, "water_bypass_frac": split / (1.0 + split)}


def grate_factor(size_um: np.ndarray, d50_um: float, sharpness: float) -> np.ndarray:
    return 1.0 / (1.0 + (np.asarray(size_um) / d50_um) ** sharpness)


class Classification(Effect):
    name = "classification"
    requires = ("transport",)
    provides = ("discharge_class_factor", "product_split", "flow_multiplier")
    outputs = ("cyclone_d50c_um", "circulating_load_frac", "cyclone_feed_tph", "cyclone_underflow_tph")
    uses = ("cut_size_factor",)
    source = "Austin et al. (1984) ch. 9 (grate); Plitt (1976), Flintoff et al. (1987) (hydrocyclone)"
    summary = "grate discharge factor, or hydrocyclone closed circuit with recycle to the feed"
    options = {
        "kind": Option("grate", "'grate' (internal classification at the discharge) or 'hydrocyclone' "
                       "(closed circuit, underflow to the mill feed)", choices=("grate", "hydrocyclone")),
        "circulating_load_nominal": Option(2.5, "underflow / fresh feed at nominal (hydrocyclone)", float,
                                           lo=0.0, hi=50.0),
        "cyclone": Option(Hydrocyclone(), "hydrocyclone geometry and feed (hydrocyclone): a Hydrocyclone or a "
                          "table of its fields", (Hydrocyclone, dict)),
    }

    def apply(self, ctx: EffectContext) -> None:
        if self.settings["kind"] == "grate":
            self._grate(ctx)
        else:
            self._hydrocyclone(ctx)

    def _grate(self, ctx: EffectContext) -> None:
        spec = ctx.spec
        x = spec.grid.mid_um
        d50 = ctx.param("grate_d50_um", spec.mill.grate_d50_um, "um", "mill")
        k = ctx.param("grate_sharpness", spec.mill.grate_sharpness, "-", "mill")
        cut = ctx.get("cut_size_factor", 1.0)
        if isinstance(cut, float):
            c = grate_factor(x, d50 * cut, k)
        else:  # a cut size that moves with the states (rheology)
            c = 1.0 / (1.0 + ca.DM((x / d50) ** k) * cut ** -k)
        c[-1] = 1.0
        ctx.provide("discharge_class_factor", c)
        ctx.note(f"grate factor on the last mixer's discharge, d50 {d50:g} um")

    def _hydrocyclone(self, ctx: EffectContext) -> None:
        spec = ctx.spec
        cl = self.settings["circulating_load_nominal"]
        cyc = self.settings["cyclone"]
        if isinstance(cyc, dict):
            try:
                cyc = Hydrocyclone(**cyc)
            except TypeError as exc:
                raise ModelError(f"The 'cyclone' option of effect 'classification': {exc}. Fields: "
                                 f"{', '.join(Hydrocyclone.__dataclass_fields__)}.") from None
        rho = spec.solids_density_t_m3
        solids_nom = spec.feed_nominal_tph * (1.0 + cl)  # cyclone feed solids at nominal
        phi = cyc.feed_solids_vol_pct / 100.0
        slurry_nom = solids_nom / rho / phi  # m3/h
        plitt = cyc.plitt(slurry_nom, rho)
        for key, val in plitt.items():
            ctx.param(f"cyclone_{key}", val, "", "Plitt (1976) at nominal cyclone feed")
        ctx.provide("flow_multiplier", 1.0 + cl)
        rf, m, d50_nom = plitt["water_bypass_frac"], plitt["sharpness_m"], plitt["d50c_um"]
        xs = ca.DM(spec.grid.mid_um)
        cut = ctx.get("cut_size_factor", 1.0)

        def split(discharge):
            total = sum(ca.sum1(dc) for dc in discharge)
            q_ratio = smooth_max(total / solids_nom, 1e-3, 1e-3)
            d50 = d50_nom * q_ratio ** -0.45 * cut
            e = rf + (1.0 - rf) * (1.0 - ca.exp(-0.693 * (xs / d50) ** m))
            under = [e * dc for dc in discharge]
            over = [dc - uc for dc, uc in zip(discharge, under)]
            ctx.output("cyclone_d50c_um", d50)
            ctx.output("cyclone_feed_tph", sum(discharge))  # per size class, as the underflow below
            ctx.output("cyclone_underflow_tph", sum(under))
            ctx.output("circulating_load_frac", sum(ca.sum1(u) for u in under) / smooth_max(
                ctx.feed_tph, 1e-6 * spec.feed_nominal_tph, 1e-6 * spec.feed_nominal_tph))
            return over, under

        ctx.provide("product_split", split)
        ctx.note(f"hydrocyclone (Plitt): d50c {d50_nom:.0f} um, m {m:.2f}, bypass {rf:.2f} at nominal; "
                 "underflow to mixer 0")
