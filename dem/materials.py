"""Materials, Hertz–Mindlin effective properties, damping from restitution, critical time step (SI).

Sources
-------
- Hertz normal force ``F = 4/3 E* sqrt(R*) delta^1.5`` and Mindlin tangential stiffness
  ``S_t = 8 G* sqrt(R* delta)``: K. L. Johnson, *Contact Mechanics* (1985), ch. 4 and 7;
  Mindlin & Deresiewicz (1953).
- Effective moduli ``1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2`` and
  ``1/G* = (2-nu1)/G1 + (2-nu2)/G2``: Johnson (1985); the same convention as EDEM/LIGGGHTS.
- Viscous damping ``F_d = -eta sqrt(m* S) v`` proportional to ``delta^(1/4)``: Tsuji, Tanaka &
  Ishida, Powder Technol. 71 (1992) 239; with it the coefficient of restitution does not
  depend on impact velocity (Antypov & Elliott, EPL 94 (2011) 50004). The usual closed form
  ``eta = -2 sqrt(5/6) ln e / sqrt(ln^2 e + pi^2)`` comes from a *linear* spring and misses the
  target restitution by several per cent for Hertz contacts (Thornton et al., Powder Technol.
  233 (2013) 30). We therefore invert the exact, velocity-independent map ``e(eta)`` of the
  dimensionless damped Hertz equation numerically (:func:`damping_coefficient`).
- Rayleigh time step ``dt_R = pi R sqrt(rho/G) / (0.1631 nu + 0.8766)``: Li, Xu & Thornton,
  Powder Technol. 160 (2005) 219; used with a safety factor (EDEM manual: 20–40 %).
- Bond spring time step ``sqrt(m / sum k)``: Potyondy & Cundall, IJRMMS 41 (2004) 1329, §2.3
  (the critical step of a mass on parallel springs, with an extra margin of 2).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from dem.errors import DemInputError

#: Fraction of the critical time step actually used (EDEM recommends 0.2–0.4 of Rayleigh).
RAYLEIGH_SAFETY_FACTOR = 0.2

#: Coefficient in the Hertz contact duration ``t_c = HERTZ_DURATION_COEF (m*^2/(R* E*^2 v))^(1/5)``
#: (Johnson 1985, eq. 11.24; 2.868 = 2 (15/16)^(2/5) * 1.4716...).
HERTZ_DURATION_COEF = 2.8683


#: Smallest Young's modulus a :class:`Material` takes (Pa): softer than any solid a mill grinds
#: or is lined with; a modulus given in GPa or MPa (30 for 30 GPa) falls below it.
MIN_YOUNGS_MODULUS_PA = 1e4
#: Largest Young's modulus a bond takes (Pa, :mod:`dem.bonds`): diamond's, some 1.1 TPa (Klein &
#: Cardinale, Diamond Relat. Mater. 2 (1993) 918), the stiffest bulk solid; a modulus in kPa or
#: a stiffness per mm lies above it.
MAX_YOUNGS_MODULUS_PA = 1.2e12
#: Smallest restitution a :class:`Material` takes: :func:`damping_coefficient` finds eta on
#: [0, 5], where e(eta) falls to e(5) = 0.028 (:func:`_restitution_of_eta`); 0.05 keeps a margin.
#: Below it the damping is not solved; a near-plastic contact is outside this model.
MIN_RESTITUTION = 0.05
#: Smallest density a :class:`Material` (or :class:`dem.system.System`) takes (kg/m3): a
#: density given in g/cm3 or t/m3 (2.7 for 2700 kg/m3) falls below it.
MIN_DENSITY_KG_M3 = 100.0


def as_real(owner: str, name: str, value) -> float:
    """``value`` as a float if it is a real number; DemInputError naming ``owner`` and ``name`` for a
    bool, text, None, an array or anything else."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise DemInputError(f"The '{name}' parameter of {owner} must be a float. Got {value!r}.")
    return float(value)


def _check_positive(owner: str, name: str, value: float, lo: float = 0.0, hint: str = "") -> float:
    value = as_real(owner, name, value)
    if not math.isfinite(value) or value <= lo:
        raise DemInputError(
            f"The '{name}' parameter of {owner} must be a finite float > {lo:g}{hint}. Got {value!r}."
        )
    return value


def check_float(owner: str, name: str, value: float, lo: float, hi: float,
                lo_open: bool = False, hi_open: bool = False) -> float:
    """``float(value)`` if it is a real number (not a bool, text or an array) in the interval, else
    DemInputError naming ``owner``, ``name``, the interval and the value ("0.2" raised numpy's
    UFuncTypeError deep inside; "abc" a bare ValueError)."""
    value = as_real(owner, name, value)
    ok = math.isfinite(value)
    ok = ok and (value > lo if lo_open else value >= lo)
    ok = ok and (value < hi if hi_open else value <= hi)
    if not ok:
        lb = "(" if lo_open else "["
        rb = ")" if hi_open else "]"
        raise DemInputError(
            f"The '{name}' parameter of {owner} must be a float in {lb}{lo}, {hi}{rb}. Got {value!r}."
        )
    return value


def check_density(owner: str, name: str, value: float) -> float:
    """A density in kg/m3, above :data:`MIN_DENSITY_KG_M3` (a value in g/cm3 is refused)."""
    return _check_positive(owner, name, value, MIN_DENSITY_KG_M3, " kg/m3 (2700 for 2.7 g/cm3)")


def check_restitution(owner: str, value: float) -> float:
    """A restitution in (0, 1] that the damping is solved for: at least :data:`MIN_RESTITUTION`."""
    e = check_float(owner, "restitution", value, 0.0, 1.0, lo_open=True)
    if e < MIN_RESTITUTION:
        raise DemInputError(
            f"The 'restitution' parameter of {owner} must be a float in [{MIN_RESTITUTION}, 1] (the damping "
            f"of a Hertz contact is solved for no lower one). Got {e!r}.")
    return e


@dataclass(frozen=True)
class Material:
    """Elastic and frictional properties of a sphere (or wall) material, SI units.

    Fields
    ------
    youngs_modulus_Pa : Young's modulus E of the solid (Hertz contacts), Pa, at least
        :data:`MIN_YOUNGS_MODULUS_PA` (a modulus in GPa is refused, not run).
    poisson_ratio : nu in [0, 0.5).
    density_kg_m3 : density of the sphere material, kg/m3, at least :data:`MIN_DENSITY_KG_M3`.
    friction_coef : Coulomb friction coefficient mu of contacts (tan of the friction angle).
    restitution : normal coefficient of restitution e in [:data:`MIN_RESTITUTION`, 1] (1 = no
        damping; see :func:`damping_coefficient`).
    """

    youngs_modulus_Pa: float = 30e9
    poisson_ratio: float = 0.25
    density_kg_m3: float = 2700.0
    friction_coef: float = math.tan(math.radians(30.0))
    restitution: float = 0.5

    def __post_init__(self) -> None:
        _check_positive("Material", "youngs_modulus_Pa", self.youngs_modulus_Pa, MIN_YOUNGS_MODULUS_PA,
                        " Pa (30e9 for 30 GPa)")
        check_float("Material", "poisson_ratio", self.poisson_ratio, 0.0, 0.5, hi_open=True)
        check_density("Material", "density_kg_m3", self.density_kg_m3)
        check_float("Material", "friction_coef", self.friction_coef, 0.0, 10.0)
        check_restitution("Material", self.restitution)

    @property
    def shear_modulus_Pa(self) -> float:
        return self.youngs_modulus_Pa / (2.0 * (1.0 + self.poisson_ratio))


#: Steel for platens, drop weights, drum shells and balls.
STEEL = Material(youngs_modulus_Pa=210e9, poisson_ratio=0.3, density_kg_m3=7800.0,
                 friction_coef=0.3, restitution=0.7)


def effective_youngs_Pa(a: Material, b: Material) -> float:
    """E* with ``1/E* = (1-nu_a^2)/E_a + (1-nu_b^2)/E_b`` (Johnson 1985)."""
    return 1.0 / ((1 - a.poisson_ratio**2) / a.youngs_modulus_Pa
                  + (1 - b.poisson_ratio**2) / b.youngs_modulus_Pa)


def effective_shear_Pa(a: Material, b: Material) -> float:
    """G* with ``1/G* = (2-nu_a)/G_a + (2-nu_b)/G_b`` (Mindlin; EDEM convention)."""
    return 1.0 / ((2 - a.poisson_ratio) / a.shear_modulus_Pa
                  + (2 - b.poisson_ratio) / b.shear_modulus_Pa)


def _restitution_of_eta(eta: float) -> float:
    """Restitution of the dimensionless damped Hertz oscillator.

    ``X'' = -X^1.5 - eta sqrt(1.5) X^0.25 X'`` with the total force clamped at >= 0 (no
    attraction), X(0) = 0, X'(0) = 1; e = exit speed at X = 0 (Tsuji et al. 1992 scaling:
    length ``(m* v^2 / (4/3 E* sqrt R*))^(2/5)``, time length/v).
    """
    from scipy.integrate import solve_ivp

    c = eta * math.sqrt(1.5)

    def rhs(_t, y):
        x, v = y
        xp = max(x, 0.0)
        f = xp**1.5 + c * xp**0.25 * v
        return [v, -max(f, 0.0)]

    def exit_(_t, y):
        return y[0]

    exit_.terminal = True
    exit_.direction = -1
    sol = solve_ivp(rhs, (0.0, 50.0), [1e-12, 1.0], events=exit_, rtol=1e-10, atol=1e-12,
                    max_step=0.01)
    if sol.t_events[0].size == 0:
        return 0.0
    return float(-sol.y_events[0][0][1])


@lru_cache(maxsize=64)
def damping_coefficient(restitution: float) -> float:
    """Dimensionless damping eta in ``F_d = -eta sqrt(m* S) v`` that gives restitution e exactly.

    Inverts the velocity-independent map e(eta) of Tsuji et al. (1992) damping on a Hertz
    spring by root finding. e = 1 gives 0.
    """
    from scipy.optimize import brentq

    e = check_restitution("damping_coefficient", restitution)
    if e >= 1.0:
        return 0.0
    return float(brentq(lambda eta: _restitution_of_eta(eta) - e, 0.0, 5.0, xtol=1e-10))


def damping_coefficient_linear_formula(restitution: float) -> float:
    """The common closed form ``-2 sqrt(5/6) ln e / sqrt(ln^2 e + pi^2)`` (Tsuji 1992; EDEM).

    Kept for comparison only; it is exact for a linear spring, not for Hertz.
    """
    ln_e = math.log(restitution)
    return -2.0 * math.sqrt(5.0 / 6.0) * ln_e / math.sqrt(ln_e**2 + math.pi**2)


def hertz_contact_duration_s(m_eff_kg: float, r_eff_m: float, e_eff_Pa: float,
                             impact_speed_m_s: float) -> float:
    """Undamped Hertz contact duration ``2.868 (m*^2 / (R* E*^2 v))^(1/5)`` (Johnson 1985)."""
    return HERTZ_DURATION_COEF * (m_eff_kg**2 / (r_eff_m * e_eff_Pa**2 * impact_speed_m_s)) ** 0.2


def rayleigh_time_step_s(radius_m: float, material: Material) -> float:
    """Rayleigh time step ``pi R sqrt(rho/G) / (0.1631 nu + 0.8766)`` (Li et al. 2005)."""
    nu = material.poisson_ratio
    return math.pi * radius_m * math.sqrt(material.density_kg_m3 / material.shear_modulus_Pa) / (
        0.1631 * nu + 0.8766)


def bond_time_step_s(mass_kg: np.ndarray, inertia_kg_m2: np.ndarray, stiff_sum_N_m: np.ndarray,
                     rot_stiff_sum_Nm_rad: np.ndarray) -> float:
    """Smallest ``sqrt(m / sum k)`` (and rotational ``sqrt(I / sum k_rot)``) over bonded spheres.

    Potyondy & Cundall (2004) §2.3: the critical step of a mass on parallel springs is
    ``2 sqrt(m/k)``; using ``sqrt(m / sum k)`` keeps a factor of 2 in hand.
    """
    out = math.inf
    m = stiff_sum_N_m > 0
    if np.any(m):
        out = min(out, float(np.min(np.sqrt(mass_kg[m] / stiff_sum_N_m[m]))))
    m = rot_stiff_sum_Nm_rad > 0
    if np.any(m):
        out = min(out, float(np.min(np.sqrt(inertia_kg_m2[m] / rot_stiff_sum_Nm_rad[m]))))
    return out
