"""Scale-up of breakage parameters from the mill they were calibrated in to another mill.

Rules (Austin, Klimpel & Luckie 1984, *Process Engineering of Size Reduction*, ch. 8 and 10;
Austin, Shoji & Luckie 1976, Powder Technol. 14, 71-79), at the same fractional ball filling and
powder filling:
- mill diameter: the rate constant A of S grows as D^0.5 up to D = 3.81 m and as D^0.3 beyond
  (larger mills lift balls higher: more energetic impacts), and the size of the maximum of S,
  set by mu, as D^0.2;
- ball size: A falls as 1/d (fewer contacts per unit ball mass) and mu grows as d^2 (bigger
  balls break bigger particles: Austin's x_m ~ d^2);
- nominal speed: A follows Austin's speed factor f(phi_c) = (phi_c - 0.1) / (1 + exp(15.7 (phi_c
  - 0.94))) (eq. 8.4) from the calibrated mill's nominal speed to the mill's, as his scale-up
  carries it; a mill at its nominal speed then breaks as the same mill run at that speed
  (twin.effects.speed normalises the factor at the nominal speed).
The twin's rates are energy-specific, S = S^E P / H, so S^E carries Austin's factor on A over the
change of net power per unit hold-up, (P/H)_to / (P/H)_from, of the mills' power models without
their corrections (``power_factor``, a given ``net_power_kw``), each at its mill's nominal speed
(the power's own speed term cancels; Austin's factor above is the speed's effect on S): with
Bond's D^2.3 power, S^E grows as D^0.2 up to 3.81 m and is constant beyond, Rowland's diameter
efficiency factor EF3 = (2.44/D)^0.2 (0.914 from 3.81 m) on Bond's specific energy (Rowland
1982); with Hogg-Fuerstenau's D^2.5, S^E is invariant (Herbst & Fuerstenau's 1980 scale-up
claim). A mill that draws more than its model (a fitted power factor, a measured
power) breaks faster in proportion, as the energy-specific form has it. B does not change.
Austin's rules above hold at the same ball and powder filling; a change of either keeps S^E
(Herbst & Fuerstenau 1980), so S follows the power per hold-up, as the holdup effect has it for
a change of load: S^E carries over the fillings, Austin's factor only the diameter, balls and speed.
"""

from __future__ import annotations

from dataclasses import replace

from .breakage import BreakageParams, austin_speed_factor
from .mill import Mill, power_kw

#: Austin et al. (1984) eq. 10.6-10.8: exponents of the rate constant A on mill diameter below and
#: above the break diameter, of mu on diameter, and of A and mu on ball size.
DIAMETER_EXPONENT_A = 0.5
DIAMETER_EXPONENT_A_LARGE = 0.3
DIAMETER_BREAK_M = 3.81
DIAMETER_EXPONENT_MU = 0.2
BALL_EXPONENT_A = -1.0
BALL_EXPONENT_MU = 2.0


def diameter_factor_a(d_from_m: float, d_to_m: float) -> float:
    """Austin's factor on A from one mill diameter to another (D^0.5 to 3.81 m, D^0.3 beyond)."""
    def level(d):
        if d <= DIAMETER_BREAK_M:
            return d ** DIAMETER_EXPONENT_A
        return DIAMETER_BREAK_M ** DIAMETER_EXPONENT_A * (d / DIAMETER_BREAK_M) ** DIAMETER_EXPONENT_A_LARGE
    return level(d_to_m) / level(d_from_m)


def power_per_holdup(mill: Mill, solids_density_t_m3: float) -> float:
    """Net power of the mill's power model (no power factor, no given power) per tonne of nominal
    hold-up [kW/t] at its nominal speed: the geometric part of the energy input."""
    model = replace(mill, power_factor=1.0, net_power_kw=None)
    return power_kw(model, mill.speed_nominal_frac_critical) / mill.nominal_holdup_t(solids_density_t_m3)


def scale_breakage(params: BreakageParams, from_mill: Mill, to_mill: Mill,
                   solids_density_t_m3: float) -> BreakageParams:
    """``params`` calibrated in ``from_mill``, scaled to ``to_mill`` by the module's rules."""
    same = ("diameter_m", "ball_size_mm", "speed_nominal_frac_critical")
    if all(getattr(from_mill, k) == getattr(to_mill, k) for k in same) and \
            power_per_holdup(from_mill, solids_density_t_m3) == power_per_holdup(to_mill, solids_density_t_m3):
        return params
    ball = to_mill.ball_size_mm / from_mill.ball_size_mm
    speed = austin_speed_factor(to_mill.speed_nominal_frac_critical) / austin_speed_factor(
        from_mill.speed_nominal_frac_critical)
    factor_a = diameter_factor_a(from_mill.diameter_m, to_mill.diameter_m) * ball ** BALL_EXPONENT_A * speed
    # the calibrated mill at the new fillings: their change of P/H reaches S, as S = S^E P / H has it
    filled = replace(from_mill, ball_filling_frac=to_mill.ball_filling_frac,
                     powder_filling_nominal=to_mill.powder_filling_nominal)
    energy = power_per_holdup(filled, solids_density_t_m3) / power_per_holdup(to_mill, solids_density_t_m3)
    mu = params.mu_um * (to_mill.diameter_m / from_mill.diameter_m) ** DIAMETER_EXPONENT_MU * ball ** BALL_EXPONENT_MU
    return replace(params, se_1mm_t_kwh=params.se_1mm_t_kwh * factor_a * energy, mu_um=mu,
                   source=f"{params.source}; scaled from mill {from_mill.name!r} to {to_mill.name!r} (twin.scaleup)")
