"""Slurry rheology: clay thickens the mill slurry, which carries coarser particles out of it and
draws less power from the mill.

- Viscosity: the relative viscosity of the mill slurry follows Thomas's (1965, J. Colloid Sci.
  20, 267-277) equation for suspensions,
  mu_r = 1 + 2.5 phi + 10.05 phi^2 + 0.00273 exp(16.6 phi),
  at an effective solids volume fraction phi = phi_v (1 + k_clay w_clay): thin, charged clay
  platelets (kaolinite, illite) crowd a suspension far more than their solid volume, their
  intrinsic viscosity being many times a sphere's 2.5 (Simha 1940 for oblate spheroids; Shi &
  Napier-Munn 2002, as in twin.effects.cushioning, on clay in grinding slurries).
  w_clay is the clay mass fraction of the hold-up (from the states: a clay-rich component
  thickens the slurry a hard one grinds in); phi_v the mill slurry's solids volume fraction;
  k_clay comes from the calibration, bounded so that no ore of the deposit (clay up to 40 %)
  is crowded past jamming (:data:`CLAY_CROWDING_MAX`).
- Transport: a particle leaves with the slurry when its settling velocity is below the slurry's
  through-flow; Stokes' law, v_s = g d^2 (rho_s - rho) / (18 mu), makes the cut size grow as
  sqrt(mu). Relative to a clay-free slurry of the same solids, the grate's d50 (and a
  hydrocyclone's d50c, which Flintoff, Plitt & Turak 1987 also scale as mu^0.5) is multiplied by
  sqrt(mu_r(phi) / mu_r(phi_v)). So clay ore leaves the mill coarser and faster at the same
  load, the throughput rise at constant load of MISSION.md's soft ores.
- Power: a viscous slurry damps the charge's motion (it pools at the toe and is carried less
  high), and the mill draws less power: Morrell (2016, Minerals Engineering 89, 148-156)
  models the slurry phase's share of the power draw and the fall of ball-mill power as slurry
  fills the charge; viscous, clay-rich slurry pooling lowers the draw in practice (Shi &
  Napier-Munn 2002). No closed form links the draw to the viscosity, so the power factor is the
  hyperbolic 1 / (1 + k (mu_r / mu_r0 - 1)) (mu_r0 the clay-free slurry's; a resistance in
  series with the charge's, the form the cushioning of the rates has), 1 for a clay-free
  slurry, k from the calibration. The form was chosen over a power law (mu_r / mu_r0)^-n, which
  fits the table and predicts the left-out ores worse (README, 'Calibrations').
  Only clay counts: kaolinite and illite, fine platelets with charged edges, build the
  suspension's structure (yield stress; Ndlovu et al. 2014, Minerals Engineering 55, 190-200,
  rheological classification of the phyllosilicates), while coarse mica flakes crowd it little;
  the table agrees (ores A and B draw the same power with 2 % and 18 % biotite), and
  micas cushion the breakage instead (twin.effects.cushioning)."""

from __future__ import annotations

import math

import casadi as ca

from .base import Effect, EffectContext

#: Solids volume fraction of the mill slurry: ball-mill pulps run at 65-75 wt % solids (Wills &
#: Finch 2016, Mineral Processing Technology, 8th ed., ch. 7); 70 wt % at 2.7 t/m3 is 0.46.
SLURRY_SOLIDS_VOL_FRAC = 0.46
#: Stokes' law: the cut size grows as the square root of the carrier's viscosity.
STOKES_CUT_EXPONENT = 0.5
#: Solids volume fraction at which a suspension of spheres jams (random close packing, 0.637:
#: Scott & Kilgour 1969, J. Phys. D 2, 863): beyond it a slurry does not flow and a viscosity
#: equation describes nothing.
JAMMING_VOL_FRAC = 0.64
#: The most clay an ore of the deposit carries (MISSION.md: clay ~0-40 % over the deposit).
DEPOSIT_MAX_CLAY_FRAC = 0.40
#: The largest clay-crowding coefficient that keeps every ore of the deposit's slurry below
#: jamming: phi_v (1 + k w_clay,max) = JAMMING_VOL_FRAC. Calibrations fit k within it.
CLAY_CROWDING_MAX = (JAMMING_VOL_FRAC / SLURRY_SOLIDS_VOL_FRAC - 1.0) / DEPOSIT_MAX_CLAY_FRAC


def jamming_clay_frac(clay_crowding_coeff: float) -> float:
    """Clay mass fraction of the hold-up at which the mill slurry's effective solids fraction
    phi_v (1 + k w_clay) reaches :data:`JAMMING_VOL_FRAC` (0.40 at :data:`CLAY_CROWDING_MAX`;
    infinite without crowding, k = 0: then clay never jams the slurry)."""
    if not clay_crowding_coeff > 0.0:
        return math.inf
    return (JAMMING_VOL_FRAC / SLURRY_SOLIDS_VOL_FRAC - 1.0) / clay_crowding_coeff


def jamming_note(clay_frac: float, clay_crowding_coeff: float) -> str | None:
    """A note when a hold-up's clay fraction puts the slurry past jamming, else None: beyond it
    the slurry does not flow and Thomas's equation describes nothing, so the twin's viscosity,
    power and cut size there are an extrapolation (the ores of the deposit stay below it)."""
    limit = jamming_clay_frac(clay_crowding_coeff)
    if not clay_frac > limit:
        return None
    return (f"the mill slurry holds {clay_frac:.0%} clay, past the {limit:.0%} at which it jams (effective solids "
            f"{SLURRY_SOLIDS_VOL_FRAC * (1.0 + clay_crowding_coeff * clay_frac):.2f} > {JAMMING_VOL_FRAC}): such a "
            "slurry does not flow, and the twin's viscosity, power and cut size there extrapolate Thomas's equation "
            "beyond what it describes")


def thomas_relative_viscosity(phi):
    """Thomas (1965): relative viscosity of a suspension at solids volume fraction phi.
    Works on floats and CasADi expressions."""
    return 1.0 + 2.5 * phi + 10.05 * phi ** 2 + 0.00273 * ca.exp(16.6 * phi)


def slurry_power_factor(thickening, coeff):
    """The mill's power over its power in a clay-free slurry, 1 / (1 + k (thickening - 1)), with
    thickening the relative viscosity over a clay-free slurry's (module docstring). Floats and
    CasADi expressions."""
    return 1.0 / (1.0 + coeff * (thickening - 1.0))


class Rheology(Effect):
    name = "rheology"
    requires = ("classification",)
    provides = ("cut_size_factor", "cut_size_factor_at")
    contributes = ("power_factor",)
    outputs = ("clay_frac", "slurry_relative_viscosity")
    source = ("Thomas (1965) viscosity; Stokes settling cut size; Morrell (2016) slurry and power; coefficients from "
              "the calibration")
    summary = ("cut size x sqrt(mu_r(clay) / mu_r(no clay)); power / (1 + k (mu_r(clay) / mu_r(no clay) - 1)); "
               "mu_r by Thomas at phi_v (1 + k w_clay)")

    def apply(self, ctx: EffectContext) -> None:
        spec = ctx.spec
        k_clay = ctx.param("clay_crowding_coeff", spec.coefficients["clay_crowding_coeff"], "-", "calibration")
        phi_v = ctx.param("slurry_solids_vol_frac", SLURRY_SOLIDS_VOL_FRAC, "-", "Wills & Finch 2016 ch. 7")
        w_clay = ctx.holdup_fraction("clay_mass_t", spec.clay_frac)
        k_power = ctx.param("slurry_power_coeff", spec.coefficients["slurry_power_coeff"], "-", "calibration")
        mu_r = thomas_relative_viscosity(phi_v * (1.0 + k_clay * w_clay))
        clay_free = float(thomas_relative_viscosity(phi_v))
        thickening = mu_r / clay_free  # against a clay-free slurry
        ctx.provide("cut_size_factor", thickening ** STOKES_CUT_EXPONENT)
        # the factor of a slurry of solids with clay fraction w (a classifier calibrated on such a slurry)
        ctx.provide("cut_size_factor_at", lambda w: (thomas_relative_viscosity(phi_v * (1.0 + k_clay * w))
                                                     / clay_free) ** STOKES_CUT_EXPONENT)
        ctx.contribute("power_factor", slurry_power_factor(thickening, k_power))
        ctx.output("clay_frac", w_clay)
        ctx.output("slurry_relative_viscosity", mu_r)
        ctx.note("classification cut size x sqrt(relative slurry viscosity), power / (1 + k (relative "
                 "viscosity - 1)), from the hold-up's clay")
