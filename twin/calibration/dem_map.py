"""The DEM breakage map: breakage parameters of *any* ore from laws fitted across the reference
ores' virtual tests (twin.calibration.dem_link runs the tests).

Units: SI in the DEM part (J/kg, kg, m, W); the twin's units (um, t/kWh) in BreakageParams.

1. Fracture energy: a scaling law, not an interpolation
-------------------------------------------------------
The bonded-particle DEM is self-similar in (bond modulus, bond strength): with the sphere
packing, the stiffness and strength ratios and the local damping fixed (dem_link section 2),
scaling the modulus E and the bond strength sigma_b scales forces as sigma_b d^2 and
displacements as (sigma_b / E) d, so the specific energy absorbed to fracture scales as
``sigma_b^2 / (E rho)`` (Potyondy & Cundall 2004, s3.2 for the force part). The bond strength is
calibrated to the peak force F (dem_link section 1), so at one particle size

    E50(M) = E50_B Pi^c1,   Pi = (F / F_B)^2 (E_B / E) (rho_B / rho)

with F = F(M) the mineralogy's strength index, E its Voigt-Reuss-Hill modulus and rho its
density (twin.ore). With section 1's F = F_B sqrt((E/E_B)(H/H_B)) this is
Pi = (H/H_B) / (rho/rho_B): fracture energy per unit mass follows hardness per unit density.
Dimensional analysis gives c1 = 1; the fit across the reference ores' particles measures it
(the steel platens, Hertz contacts after the first bond failures and the finite platen speed
break the self-similarity a little). The law is a regression of ln e_ij (particle j of ore i)
on ln Pi_i: the maximum-likelihood fit of log-normal fracture energies with a common width
sigma (Tavares & King 1998), which is the DEM's particle-to-particle scatter; the two
coefficients and sigma come with their standard errors.
Extrapolation: the law holds for any (F, E, rho) as far as the DEM stays self-similar (it is a
property of the bonded model, not of the four ores); what is not tested beyond the reference
ores is the strength index F(M) itself (dem_link section 1).

2. Selection function from the drum
-----------------------------------
For an ore, S^E(d) follows from the drum DEM's collision spectrum and the law's E50, sigma
and the ore's density by the capture model of dem_link section 4 (:func:`selection_energy_specific`);
Austin's form is fitted to it over ``sizes_um`` (:func:`fit_austin_selection`). So S^E_1 and its
size dependence (alpha, mu, Lambda) are computed per ore, for any ore.

3. Breakage function: pooled across ores at each impact energy
--------------------------------------------------------------
The self-similar DEM breaks every ore alike at the same multiple of its E50, so the drop-weight
fragments of all reference ores at one multiple are pooled and Austin's B fitted to them
(gamma, phi; beta fixed). An ore's B is the one at the multiple of its E50 that the mill's
typical collision delivers (energy-weighted mean collision energy over the captured mass at
1 mm), interpolated in ln(multiple) between the tested multiples and held at the end values
outside them (stated extrapolation: B is taken as saturated beyond the highest multiple).
"""

from __future__ import annotations

import json
import math

import numpy as np
import scipy.optimize

from ..breakage import BreakageParams
from ..ore.fracture_energy import breakage_probability
from ..ore.mineralogy import Mineralogy
from .breakage_map import AUSTIN_SHAPE
from .fitted import on_bound
from .strength import REFERENCE_ORE, energy_group

#: Porosity of the particle bed a ball pair captures (a loose random packing; Austin et al. 1984).
BED_POROSITY = 0.4
# ---------------------------------------------------------------------- 1. fracture energy
def fit_energy_law(ln_pi: np.ndarray, energies: list) -> dict:
    """ln e_ij = c0 + c1 ln Pi_i + eps, eps ~ N(0, sigma^2): maximum likelihood (ordinary least
    squares, sigma with ddof 0 as twin.ore.fracture_energy) over all particles of all ores.
    ``energies[i]`` are ore i's specific fracture energies [J/kg]. With one ore, c1 is fixed at
    the dimensional value 1 (module s1)."""
    x = np.concatenate([np.full(len(e), v) for v, e in zip(ln_pi, energies)])
    y = np.log(np.concatenate([np.asarray(e, float) for e in energies]))
    if np.ptp(x) > 0:
        A = np.column_stack([np.ones_like(x), x])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    else:
        A = np.ones((x.size, 1))
        coef = np.array([float(np.mean(y - x)), 1.0])
    resid = y - coef[0] - coef[1] * x
    sigma = float(np.sqrt(np.mean(resid ** 2)))
    cov = sigma ** 2 * np.linalg.inv(A.T @ A)
    se = np.sqrt(np.diag(cov))
    return {"c0": float(coef[0]), "c1": float(coef[1]), "c0_se": float(se[0]),
            "c1_se": float(se[1]) if se.size > 1 else 0.0, "sigma": sigma,
            "sigma_se": sigma / math.sqrt(2 * y.size), "n_particles": int(y.size),
            "per_ore_mean_residual": [float(np.mean(np.log(np.asarray(e, float)) - coef[0] - coef[1] * v))
                                      for v, e in zip(ln_pi, energies)]}


def law_e50_j_kg(law: dict, ore: Mineralogy) -> float:
    """E50 of an ore by the law (module s1)."""
    e = law["energy"]
    return math.exp(e["c0"] + e["c1"] * math.log(energy_group(ore, law["reference"])))


# ---------------------------------------------------------------------- 2. selection
def captured_mass_kg(d_m, density_kg_m3: float, ball_diameter_m: float):
    """m_c = rho_s (1 - eps) pi R_ball d^2 (dem_link section 4)."""
    return density_kg_m3 * (1.0 - BED_POROSITY) * math.pi * 0.5 * ball_diameter_m * np.asarray(d_m) ** 2


def selection_energy_specific(size_um, drum: dict, e50_j_kg: float, sigma: float, density_kg_m3: float):
    """S^E(d) [t/kWh] = 3.6 sum_k f_k m_c P(E_k/m_c) / P_kW (per-collision capture model)."""
    d = np.asarray(size_um, float) * 1e-6
    e = np.asarray(drum["energy_mid_J"])
    f = np.asarray(drum["collisions_per_s_by_class"])
    mc = captured_mass_kg(d, density_kg_m3, drum["ball_diameter_m"])
    p = breakage_probability(e[None, :] / mc[:, None], e50_j_kg, sigma)
    kg_per_s = np.sum(f[None, :] * mc[:, None] * p, axis=1)
    return kg_per_s * 3.6 / (drum["power_W"] / 1000.0)   # (kg/s * 3600 / 1000) t/h per kW


def fit_austin_selection(size_um, se_t_kwh) -> dict:
    """S^E = S1 (d/1000)^alpha / (1 + (d/mu)^Lambda), least squares on ln S^E."""
    x = np.asarray(size_um, float)
    y = np.log(np.asarray(se_t_kwh, float))

    def model(q):
        ls1, alpha, lmu, lam = q
        return ls1 + alpha * np.log(x / 1000.0) - np.log1p((x / math.exp(lmu)) ** lam)

    best = None
    for lmu0 in (math.log(300.0), math.log(1000.0), math.log(3000.0)):
        sol = scipy.optimize.least_squares(lambda q: model(q) - y, [y.max(), 1.5, lmu0, 3.0],
                                           bounds=([-30, 0.0, math.log(10.0), 0.05], [30, 5.0, math.log(1e6), 20.0]))
        if best is None or sol.cost < best.cost:
            best = sol
    ls1, alpha, lmu, lam = best.x
    return {"se_1mm_t_kwh": float(math.exp(ls1)), "alpha": float(alpha), "mu_um": float(math.exp(lmu)),
            "Lambda": float(lam), "rmse_ln": float(np.sqrt(np.mean(best.fun ** 2)))}


def typical_specific_energy_j_kg(drum: dict, density_kg_m3: float) -> float:
    """The mill's typical specific collision energy: energy-weighted mean collision energy over
    the mass captured at 1 mm (module s3)."""
    e = np.asarray(drum["energy_mid_J"])
    f = np.asarray(drum["collisions_per_s_by_class"])
    return float(np.sum(e * e * f) / np.sum(e * f)) / float(captured_mass_kg(1e-3, density_kg_m3,
                                                                               drum["ball_diameter_m"]))


# ---------------------------------------------------------------------- 3. breakage function
#: The box Austin's gamma and phi are fitted in: gamma in [0.3, 3] around the 0.5-1.5 Austin,
#: Klimpel & Luckie (1984) report, phi a mass share in [0.01, 1]. A fit that ends on it
#: (``at_bounds``) says the tests ask for a value outside the box: the bound is then the number
#: used, not one the tests determine (README, limitations).
AUSTIN_B_BOUNDS = {"gamma": (0.3, 3.0), "phi": (0.01, 1.0)}


def _austin_B(y, gamma, phi, beta):
    return phi * y ** gamma + (1.0 - phi) * y ** beta


def fit_austin_B(y, passing, beta: float = AUSTIN_SHAPE["beta"]) -> dict:
    """gamma, phi of Austin's B to a product size distribution (beta fixed).

    ``y`` = sieve size / parent size, ``passing`` = cumulative mass fraction finer. Austin's B
    describes the fragments that *left* the parent's size class (twin.breakage's convention:
    B = 1 at the parent's lower size, sizes relative to it), so the product is renormalised by
    the mass passing the first sieve below the parent, y0 = 1/sqrt(2):
    ``B(r) = passing(y) / passing(y0)``, ``r = y / y0``, and ``t10 = passing(y0) B(0.1 / y0)``.
    In the box :data:`AUSTIN_B_BOUNDS`."""
    y = np.asarray(y, float)
    p = np.asarray(passing, float)
    y0 = 2.0 ** -0.5
    top = np.isclose(y, y0)
    p0 = float(np.mean(p[top])) if np.any(top) else float("nan")
    below = y < y0 * (1 - 1e-9)
    if not (p0 > 1e-6) or not np.any(below):
        return {"gamma": float("nan"), "phi": float("nan"), "beta": float(beta), "rmse": float("nan"),
                "passing_y0": p0 if np.isfinite(p0) else 0.0, "t10": 0.0}
    r = y[below] / y0
    b = np.clip(p[below] / p0, 0.0, 1.0)

    def res(q):
        return _austin_B(r, q[0], q[1], beta) - b

    (g_lo, g_hi), (p_lo, p_hi) = AUSTIN_B_BOUNDS["gamma"], AUSTIN_B_BOUNDS["phi"]
    sol = scipy.optimize.least_squares(res, [1.0, 0.5], bounds=([g_lo, p_lo], [g_hi, p_hi]))
    g, ph = sol.x
    return {"gamma": float(g), "phi": float(ph), "beta": float(beta),
            "rmse": float(np.sqrt(np.mean(sol.fun ** 2))), "passing_y0": p0,
            "t10": float(p0 * _austin_B(0.1 / y0, g, ph, beta))}


def fit_breakage_function_law(tests_by_ore: list, multiples) -> dict:
    """Austin's B pooled over the ores' drop-weight tests at each multiple of E50 (module s3), and at
    each the parameters the fit left on a bound of :data:`AUSTIN_B_BOUNDS` (``at_bounds``).
    ``tests_by_ore[i]``: ore i's test rows (``energy_multiple``, ``sieve_size_rel``,
    ``passing_frac``)."""
    gamma, phi, n, at = [], [], [], []
    for m in multiples:
        rows = [t for tests in tests_by_ore for t in tests if math.isclose(t["energy_multiple"], m)]
        fit = fit_austin_B(np.concatenate([t["sieve_size_rel"] for t in rows] or [[]]),
                           np.concatenate([t["passing_frac"] for t in rows] or [[]]))
        gamma.append(fit["gamma"])
        phi.append(fit["phi"])
        n.append(len(rows))
        at.append([k for k in ("gamma", "phi") if np.isfinite(fit[k]) and on_bound(fit[k], *AUSTIN_B_BOUNDS[k])])
    ok = [i for i in range(len(multiples)) if np.isfinite(gamma[i])]
    return {"energy_multiple": [float(multiples[i]) for i in ok], "gamma": [gamma[i] for i in ok],
            "phi": [phi[i] for i in ok], "n_tests": [n[i] for i in ok], "beta": AUSTIN_SHAPE["beta"],
            "bounds": {k: list(v) for k, v in AUSTIN_B_BOUNDS.items()}, "at_bounds": [at[i] for i in ok]}


def breakage_function_at(law: dict, multiple: float) -> tuple[float, float]:
    """(gamma, phi) at a multiple of E50: interpolated in ln(multiple), held outside (module s3)."""
    b = law["breakage_function"]
    x = np.log(b["energy_multiple"])
    xi = math.log(multiple)
    return float(np.interp(xi, x, b["gamma"])), float(np.interp(xi, x, b["phi"]))


# ---------------------------------------------------------------------- the law and the map
def fit_law(ores: dict, drum: dict, sizes_um, multiples) -> dict:
    """The map's laws from the reference ores' DEM records (``ores[name]``: properties,
    ``specific_fracture_energy_J_kg``, ``drop_weight.tests``); ``drum`` the drum spectrum;
    ``sizes_um`` the sizes of the Austin fit."""
    names = list(ores)
    ref_name = REFERENCE_ORE if REFERENCE_ORE in ores else names[0]
    ref = {k: ores[ref_name][k] for k in ("target_peak_force_N", "youngs_gpa", "density_t_m3",
                                          "hardness_index_gpa")}
    ln_pi = [math.log((ores[n]["target_peak_force_N"] / ref["target_peak_force_N"]) ** 2
                      * ref["youngs_gpa"] / ores[n]["youngs_gpa"] * ref["density_t_m3"] / ores[n]["density_t_m3"])
             for n in names]
    energy = fit_energy_law(np.array(ln_pi), [ores[n]["specific_fracture_energy_J_kg"] for n in names])
    bf = fit_breakage_function_law([ores[n]["drop_weight"]["tests"] for n in names], multiples)
    return {"fitted_on": names, "reference": {"ore": ref_name, **ref}, "ln_energy_group": dict(zip(names, ln_pi)),
            "energy": energy, "breakage_function": bf, "sizes_um": [float(s) for s in sizes_um],
            "drum": {k: drum[k] for k in ("power_W", "energy_mid_J", "collisions_per_s_by_class",
                                          "ball_diameter_m")}}


#: dem_breakage's answers by (ore, law, capture scale): a pure function whose fit of Austin's
#: selection costs ~10 ms, asked again by every twin of the same ore (a sizing builds hundreds).
_BREAKAGE_MEMO: dict = {}
_BREAKAGE_MEMO_MAX = 256


def dem_breakage(ore: Mineralogy, law: dict, capture_scale: float = 1.0) -> BreakageParams:
    """Breakage parameters of any ore from the law (module docstring); ``capture_scale``
    multiplies S^E (the fitted fraction of the captured mass that is nipped)."""
    if not isinstance(capture_scale, (int, float)):  # a symbol: nothing to remember it by
        return _dem_breakage(ore, law, capture_scale)
    key = (type(ore), tuple(sorted(ore.wt_pct.items())), ore.texture, ore.name, json.dumps(law, sort_keys=True),
           float(capture_scale))
    if key not in _BREAKAGE_MEMO:
        if len(_BREAKAGE_MEMO) >= _BREAKAGE_MEMO_MAX:
            _BREAKAGE_MEMO.clear()
        _BREAKAGE_MEMO[key] = _dem_breakage(ore, law, capture_scale)
    return _BREAKAGE_MEMO[key]


def _dem_breakage(ore: Mineralogy, law: dict, capture_scale) -> BreakageParams:
    e50 = law_e50_j_kg(law, ore)
    sigma = law["energy"]["sigma"]
    rho = ore.density_t_m3 * 1000.0
    drum = law["drum"]
    sel = fit_austin_selection(law["sizes_um"], selection_energy_specific(law["sizes_um"], drum, e50, sigma, rho))
    gamma, phi = breakage_function_at(law, typical_specific_energy_j_kg(drum, rho) / e50)
    return BreakageParams(se_1mm_t_kwh=sel["se_1mm_t_kwh"] * float(capture_scale), alpha=sel["alpha"],
                          mu_um=sel["mu_um"], Lambda=sel["Lambda"], gamma=gamma,
                          beta=law["breakage_function"]["beta"], phi=phi, delta=0.0,
                          source="DEM laws (twin.calibration.dem_map)")
