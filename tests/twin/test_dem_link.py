"""The DEM -> twin link (twin.calibration.dem_link): targets, the shipped DEM calibration, the fits made from
the DEM samples, the DEM breakage map, and the --fast path against the shipped file."""

import math

import numpy as np
import pytest

from twin.calibration import dem_link
from twin.breakage import austin_selection, breakage_matrix, cumulative_breakage
from twin.errors import TwinInputError
from twin.ore.fracture_energy import fit_fracture_energy
from twin.ore.mineralogy import Mineralogy, Texture
from twin.ore.ores import load_ore
from twin.sizes import SizeGrid

#: the --fast path (3 particles, 1 drop particle per energy, short drum) against the shipped full run
#: (10 particles). Peak forces scatter ~20 % from particle to particle (peak_force_cv_pct), so the
#: mean of 3 is known to ~12 % (1 s.d.): bond strength and E50 within 25 %; the per-size S^E
#: (the drum spectrum x P_break, 0.1-2 mm) within a factor 1.5.
FAST_TOL_STRENGTH = 0.25
FAST_TOL_E50 = 0.25
FAST_FACTOR_SE = 1.5


@pytest.fixture(scope="module")
def shipped():
    return dem_link.shipped_dem_calibration()


def test_targets_follow_the_mineralogy_in_the_order_A_B_C_D():
    t = dem_link.targets()
    assert t["B"]["target_peak_force_N"] == pytest.approx(4200.0)
    f = [t[o]["target_peak_force_N"] for o in "ABCD"]
    assert f[0] > f[1] > f[2] > f[3]
    # the derivation: geometric mean of the modulus and hardness ratios
    a, b = load_ore("A"), load_ore("B")
    assert f[0] == pytest.approx(4200.0 * math.sqrt(a.youngs_gpa / b.youngs_gpa
                                                     * a.hardness_index_gpa / b.hardness_index_gpa))


def test_shipped_file_records_provenance_and_calibration_errors(shipped):
    prov = shipped["provenance"]
    assert prov["command"].startswith("python -m twin.calibration --dem")
    for key in ("seed", "numba", "numpy", "scipy", "python", "created"):
        assert key in prov
    assert prov["fast"] is False
    for o in "ABCD":
        rec = shipped["ores"][o]
        assert rec["n_particles"] >= 10
        assert rec["calibration_error_pct"] < 6.0
        assert abs(rec["mean_peak_force_N"] / rec["target_peak_force_N"] - 1) * 100 == pytest.approx(
            rec["calibration_error_pct"], rel=1e-9)


def test_fitted_strengths_and_stiffnesses_follow_A_B_C_D(shipped):
    s = [shipped["ores"][o]["bond"]["tensile_strength_MPa"] for o in "ABCD"]
    k = [shipped["ores"][o]["bond"]["kn_GPa_m"] for o in "ABCD"]
    e50 = [shipped["ores"][o]["fracture_energy"]["e50_j_kg"] for o in "ABCD"]
    assert s[0] > s[1] > s[2] > s[3]
    assert k[0] > k[1] > k[2] > k[3]
    assert e50[0] > e50[1] > e50[2] > e50[3]


def test_fracture_energy_fit_matches_the_dem_samples(shipped):
    for o in "ABCD":
        rec = shipped["ores"][o]
        e = np.array(rec["specific_fracture_energy_J_kg"])
        fit = fit_fracture_energy(e)
        assert fit.e50_j_kg == pytest.approx(rec["fracture_energy"]["e50_j_kg"], rel=1e-9)
        assert fit.sigma == pytest.approx(rec["fracture_energy"]["sigma"], rel=1e-9)
        assert e.min() < fit.e50_j_kg < e.max()
        assert 0.01 < fit.sigma < 1.0
        # roughly half the samples below the median
        assert 0.2 <= np.mean(e < fit.e50_j_kg) <= 0.8


def test_t10_fit_is_sane_against_the_dem_samples(shipped):
    for o in "ABCD":
        dw = shipped["ores"][o]["drop_weight"]
        e = np.array([p["specific_energy_kwh_t"] for p in dw["per_energy"]])
        t10 = np.array([p["t10"] for p in dw["per_energy"]])
        fit = dw["t10_fit"]
        assert 0 < fit["A_pct"] <= 100 and fit["b_t_kwh"] > 0
        pred = fit["A_pct"] / 100 * (1 - np.exp(-fit["b_t_kwh"] * e))
        assert np.sqrt(np.mean((pred - t10) ** 2)) == pytest.approx(fit["rmse"], rel=1e-6)
        assert fit["rmse"] < 0.1
        # more energy, more fines (on the fitted curve and, at the ends, in the samples)
        assert t10[-1] > t10[0]
        # the refit from the stored samples gives the stored parameters back
        again = dem_link.fit_t10(e, t10)
        assert again["A_pct"] == pytest.approx(fit["A_pct"], rel=1e-3)


def test_t10_fit_recovers_known_parameters():
    e = np.array([0.01, 0.03, 0.1, 0.3, 1.0])
    t = 0.4 * (1 - np.exp(-2.5 * e))
    fit = dem_link.fit_t10(e, t)
    assert fit["A_pct"] == pytest.approx(40.0, rel=1e-4)
    assert fit["b_t_kwh"] == pytest.approx(2.5, rel=1e-4)


def test_dem_map_gives_mass_conserving_b_and_positive_selection(shipped):
    grid = SizeGrid()
    for o in "ABCD":
        p = dem_link.dem_breakage(load_ore(o), {"dem_capture_scale": 1.0})
        b = breakage_matrix(cumulative_breakage(grid, p.gamma, p.beta, p.phi, p.delta))  # checks sums
        assert np.allclose(b[:, :-1].sum(axis=0), 1.0)
        s = austin_selection(grid, p.se_1mm_t_kwh, p.alpha, p.mu_um, p.Lambda)
        assert np.all(s[:-1] > 0)
        # at the reference ores the map returns the DEM's own numbers
        assert p.se_1mm_t_kwh == pytest.approx(shipped["ores"][o]["selection"]["se_1mm_t_kwh"], rel=1e-9)
    # harder ore, fewer breakages from the same collisions
    se = [dem_link.dem_breakage(load_ore(o), {}).se_1mm_t_kwh for o in "ABCD"]
    assert se[0] < se[1] < se[3]


def test_dem_map_interpolates_a_blend_and_refuses_an_ore_outside_the_reference_span():
    mid = load_ore("B").mix(load_ore("C"), 0.5)
    p = dem_link.dem_breakage(mid, {})
    lo, hi = sorted([dem_link.dem_breakage(load_ore(o), {}).se_1mm_t_kwh for o in "BC"])
    assert lo <= p.se_1mm_t_kwh <= hi
    soft = Mineralogy({"kaolinite": 90.0, "quartz": 10.0}, Texture(20.0), name="kaolin")
    with pytest.raises(TwinInputError, match="outside the DEM-calibrated reference ores"):
        dem_link.dem_breakage(soft, {})


def test_fast_path_lands_near_the_shipped_calibration(shipped):
    rec = dem_link.calibrate_from_dem(fast=True, seed=shipped["provenance"]["seed"], ores=("B",),
                                      table_fit=False, out=None, verbose=False)
    fast, full = rec["ores"]["B"], shipped["ores"]["B"]
    assert fast["calibration_error_pct"] < 6.0
    assert fast["bond"]["tensile_strength_MPa"] == pytest.approx(full["bond"]["tensile_strength_MPa"],
                                                                 rel=FAST_TOL_STRENGTH)
    assert fast["fracture_energy"]["e50_j_kg"] == pytest.approx(full["fracture_energy"]["e50_j_kg"],
                                                               rel=FAST_TOL_E50)
    x = np.array(full["selection"]["sizes_um"])
    ratio = np.array(fast["selection"]["se_t_kwh_per_size"]) / np.array(full["selection"]["se_t_kwh_per_size"])
    sel = (x >= 100) & (x <= 2000)
    assert np.all((1 / FAST_FACTOR_SE < ratio[sel]) & (ratio[sel] < FAST_FACTOR_SE)), ratio


def test_twin_with_the_dem_map_reproduces_the_recorded_table_fit(shipped):
    from twin import Twin

    tf = shipped["table_fit"]
    ss = Twin("B", mill="lab", breakage_map=dem_link.dem_breakage,
              calibration=dem_link.dem_twin_calibration()).steady_at_constant_load(speed_frac_critical=0.70)
    assert ss.p80_um == pytest.approx(tf["predicted"]["B"]["p80_um"], rel=1e-6)
    assert ss.feed_tph * 1000 == pytest.approx(tf["predicted"]["B"]["throughput_kg_h"], rel=1e-6)
    assert set(tf["parameters_fitted"]) == {"dem_capture_scale", "cushioning_rate_coeff", "cushioning_power_coeff",
                                            "clay_crowding_coeff", "lab_power_factor", "lab_grate_d50_um",
                                            "lab_grate_sharpness", "lab_discharge_factor"}
