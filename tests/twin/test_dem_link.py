"""The DEM chain (twin.calibration.dem_link: the virtual tests; dem_map: the laws to any ore):
targets, the shipped DEM step, its fits, the laws' physics, the map on ores far from the
reference types, and the --fast DEM path against the shipped file."""

import math
import platform

import numpy as np
import pytest

from twin.breakage import austin_selection, breakage_matrix, cumulative_breakage
from twin.calibration import dem_link, dem_map, law_e50_j_kg, load_calibration
from twin.ore.fracture_energy import fit_fracture_energy
from twin.ore.mineralogy import Mineralogy, Texture
from twin.ore.ores import load_ore
from twin.sizes import SizeGrid

#: MISSION.md / issue goal: E50's standard error below 10 % for every reference ore.
E50_SE_GOAL = 0.10
#: the --fast path (4 particles, short drum) against the shipped full run. Peak forces scatter
#: ~20 % from particle to particle, so the mean of 4 is known to ~10 % (1 s.d.): bond strength
#: and E50 within 25 %. The per-size S^E (drum spectrum x P_break, 0.1-2 mm): the fast drum
#: window reads S^E 20-25 % low (benchmarks/results/dem_drum_accuracy.md), and at the fine end
#: P_break lies in the lognormal's tail, where the sigma of 4 particles (s.e. 1/sqrt(2 x 3) ~ 40 %) moves it by
#: ~25 %: within a factor 0.75 x 0.8 = 1 / 1.7.
FAST_TOL_STRENGTH = 0.25
FAST_TOL_E50 = 0.25
FAST_FACTOR_SE = 1.7


@pytest.fixture(scope="module")
def cal():
    return load_calibration("dem")


def _pyrite_b():
    b = load_ore("B")
    wt = dict(b.wt_pct, pyrite=b.wt_pct["pyrite"] + 15.0, biotite=b.wt_pct["biotite"] - 15.0)
    return Mineralogy(wt, b.texture, name="B_pyrite")


def test_targets_follow_the_mineralogy_in_the_order_A_B_C_D():
    t = dem_link.targets()
    assert t["B"]["target_peak_force_N"] == pytest.approx(4200.0)
    f = [t[o]["target_peak_force_N"] for o in "ABCD"]
    assert f[0] > f[1] > f[2] > f[3]
    a, b = load_ore("A"), load_ore("B")
    assert f[0] == pytest.approx(4200.0 * math.sqrt(a.youngs_gpa / b.youngs_gpa
                                                     * a.hardness_index_gpa / b.hardness_index_gpa))


def test_the_dem_step_records_its_particles_and_calibration_errors(cal):
    dem = cal.record["dem"]
    assert dem["settings"]["fast"] is False
    for o in "ABCD":
        rec = dem["ores"][o]
        assert rec["n_particles"] == dem["settings"]["n_particles"]
        assert len(rec["specific_fracture_energy_J_kg"]) == rec["n_particles"]
        assert rec["calibration_error_pct"] < 6.0
        assert abs(rec["mean_peak_force_N"] / rec["target_peak_force_N"] - 1) * 100 == pytest.approx(
            rec["calibration_error_pct"], rel=1e-9)


#: the shipped calibration was made on x86-64 (AMD EPYC) and reproduced bit for bit on another
#: x86-64 CPU (Intel Xeon); elsewhere the C library's sin, cos and pow may round differently
REPRODUCED_ON = ("x86_64", "AMD64")
RECALIBRATE = ("the shipped DEM calibration's numbers do not come out of today's DEM: after a change of "
               "the kernels' arithmetic, rerun `grindtwin calibrate --out twin/calibration/files/dem.json`")


@pytest.mark.skipif(platform.machine() not in REPRODUCED_ON, reason="bit-for-bit only on x86-64, where it was made")
def test_todays_kernels_reproduce_the_shipped_dem_step_bit_for_bit(cal):
    """Parts of the shipped calibration's DEM step, rerun, give the file's numbers exactly: the
    drum's power and collision spectrum, and ore B's first two packings in their compression
    tests and their lowest-energy drop tests at the fitted bonds, run on two processes. The
    tests are chaotic once bonds break, so a change of the kernels' rounding (fused
    multiply-adds, a reordered sum) moves them and fails here: the file would no longer come
    from its command (checked by mutation: fused multiply-adds in dem.kernels move the drum's
    power by 0.13 % and fail it)."""
    dem = cal.record["dem"]
    s = dem["settings"]
    drum = dem_link.drum_spectrum(s, s["seed"])
    assert drum["power_W"] == dem["drum"]["power_W"], RECALIBRATE
    assert drum["collisions_per_s_by_class"] == dem["drum"]["collisions_per_s_by_class"], RECALIBRATE
    rec = dem["ores"]["B"]
    strength_Pa = rec["bond"]["tensile_strength_MPa"] * 1e6
    # on two processes (the DEM step's default on this machine's cores): their answers are the file's too
    calibrator = dem_link.bond_calibrator(load_ore("B"), s, s["seed"], strength_Pa, workers=2)
    bonds = calibrator.params(rec["bond"]["kn_GPa_m"] * 1e9, strength_Pa)
    runs = calibrator.run([calibrator.particle(0), calibrator.particle(1)], bonds)
    assert [(r.peak_force_N, r.specific_fracture_energy_J_kg) for r in runs] == [
        (rec["peak_force_N"][k], rec["specific_fracture_energy_J_kg"][k]) for k in (0, 1)], RECALIBRATE
    rows = rec["drop_weight"]["tests"][:2]  # energies outer, packings inner: the lowest energy's first two
    lowest = min(s["drop_energy_multiples"])
    assert [(row["particle"], row["energy_multiple"]) for row in rows] == [(0, lowest), (1, lowest)]
    two_lowest = {**s, "drop_particles": 2, "drop_energy_multiples": (lowest,)}
    drops = dem_link.drop_tests(load_ore("B"), bonds, rec["fracture_energy"]["e50_j_kg"], two_lowest, s["seed"],
                                workers=2)["tests"]
    keys = ("particle", "specific_energy_J_kg", "absorbed_energy_J", "n_fragments", "passing_frac")
    assert [{k: d[k] for k in keys} for d in drops] == [{k: row[k] for k in keys} for row in rows], RECALIBRATE


def test_the_shipped_dem_step_ran_on_todays_time_steps(cal):
    """The DEM step records the time steps its virtual tests ran on; a change of the defaults
    (or of the critical step they are fractions of) asks for `grindtwin calibrate` again."""
    from dem import DEFAULT_TIME_STEP_FACTOR

    s = cal.record["dem"]["settings"]
    assert s["time_step_factor"] == DEFAULT_TIME_STEP_FACTOR
    assert s["drop_time_step_factor"] == dem_link.DROP_TIME_STEP_FACTOR


def test_e50_standard_errors_are_stated_and_below_the_goal(cal):
    se = cal.record["bootstrap"]["standard_errors"]["e50"]
    for o in "ABCD":
        assert 0 < se[o]["law_rel_se"] < E50_SE_GOAL, (o, se[o])
        assert 0 < se[o]["own_particles_rel_se"] < E50_SE_GOAL, (o, se[o])


def test_fitted_strengths_and_fracture_energies_follow_A_B_C_D(cal):
    ores = cal.record["dem"]["ores"]
    s = [ores[o]["bond"]["tensile_strength_MPa"] for o in "ABCD"]
    e50 = [law_e50_j_kg(cal.record["law"], load_ore(o)) for o in "ABCD"]
    assert s[0] > s[1] > s[2] > s[3]
    assert e50[0] > e50[1] > e50[2] > e50[3]


def test_fracture_energy_fit_matches_the_dem_samples(cal):
    for o in "ABCD":
        rec = cal.record["dem"]["ores"][o]
        e = np.array(rec["specific_fracture_energy_J_kg"])
        fit = fit_fracture_energy(e)
        assert fit.e50_j_kg == pytest.approx(rec["fracture_energy"]["e50_j_kg"], rel=1e-9)
        assert e.min() < fit.e50_j_kg < e.max() and 0.01 < fit.sigma < 1.0


def test_energy_law_has_the_dimensional_exponent(cal):
    """The bonded model is self-similar in (E, sigma_b): E50 ~ Pi^1 (dem_map s1). The fitted
    exponent must agree within three bootstrap standard errors; a law that ignored the
    mineralogy (exponent 0) or used strength alone (E50 ~ F, exponent ~0.5 in Pi) would not."""
    law, se = cal.record["law"]["energy"], cal.record["bootstrap"]["standard_errors"]
    assert abs(law["c1"] - 1.0) < 3 * se["c1"], (law["c1"], se["c1"])
    assert abs(law["c1"] - 0.5) > 3 * se["c1"] and abs(law["c1"]) > 3 * se["c1"]


def test_energy_law_recovers_a_known_scaling():
    rng = np.random.default_rng(0)
    ln_pi = np.array([0.3, 0.0, -0.4, -0.6])
    energies = [60.0 * math.exp(1.0 * v) * np.exp(0.3 * rng.standard_normal(400)) for v in ln_pi]
    fit = dem_map.fit_energy_law(ln_pi, energies)
    assert fit["c1"] == pytest.approx(1.0, abs=0.05) and math.exp(fit["c0"]) == pytest.approx(60.0, rel=0.03)
    assert fit["sigma"] == pytest.approx(0.3, rel=0.05)


def test_t10_fit_recovers_known_parameters():
    e = np.array([0.01, 0.03, 0.1, 0.3, 1.0])
    fit = dem_link.fit_t10(e, 0.4 * (1 - np.exp(-2.5 * e)))
    assert fit["A_pct"] == pytest.approx(40.0, rel=1e-4) and fit["b_t_kwh"] == pytest.approx(2.5, rel=1e-4)


def test_the_map_reaches_ores_far_from_the_reference_types(cal):
    """The surrogate's random deposit mineralogies and the pyrite-surge ore: finite, mass-
    conserving breakage for all, with no refusal outside the reference span."""
    grid = SizeGrid()
    far = [Mineralogy({"kaolinite": 90.0, "quartz": 10.0}, Texture(20.0), name="kaolin"),
           Mineralogy({"quartz": 100.0}, Texture(1000.0, 1.0, 0.0), name="quartzite"),
           Mineralogy({"pyrite": 60.0, "quartz": 40.0}, Texture(100.0), name="pyritic"), _pyrite_b()]
    for ore in far:
        p = cal.breakage(ore)
        b = breakage_matrix(cumulative_breakage(grid, p.gamma, p.beta, p.phi, p.delta))  # checks the sums
        assert np.allclose(b[:, :-1].sum(axis=0), 1.0)
        assert np.all(austin_selection(grid, p.se_1mm_t_kwh, p.alpha, p.mu_um, p.Lambda)[:-1] > 0)


def test_harder_per_unit_density_breaks_slower(cal):
    """Along a quartz-kaolinite series H/rho rises with quartz, so E50 rises and S^E falls."""
    series = [Mineralogy({"quartz": q, "kaolinite": 100.0 - q}, Texture(100.0), name=f"q{q}") for q in (10, 40, 70, 95)]
    e50 = [law_e50_j_kg(cal.record["law"], o) for o in series]
    se = [cal.breakage(o).se_1mm_t_kwh for o in series]
    assert e50 == sorted(e50) and se == sorted(se, reverse=True)
    assert cal.breakage(_pyrite_b()).se_1mm_t_kwh < cal.breakage(load_ore("B")).se_1mm_t_kwh


def test_fast_path_lands_near_the_shipped_dem_step(cal):
    full = cal.record["dem"]
    fast = dem_link.run_dem(fast=True, seed=full["settings"]["seed"], ores=("B",), progress=False)
    f, s = fast["ores"]["B"], full["ores"]["B"]
    assert f["calibration_error_pct"] < 6.0
    assert f["bond"]["tensile_strength_MPa"] == pytest.approx(s["bond"]["tensile_strength_MPa"], rel=FAST_TOL_STRENGTH)
    assert f["fracture_energy"]["e50_j_kg"] == pytest.approx(s["fracture_energy"]["e50_j_kg"], rel=FAST_TOL_E50)
    sizes = cal.record["law"]["sizes_um"]
    a = dem_link.per_ore_selection(fast, sizes)["B"]["se_t_kwh_per_size"]
    b = dem_link.per_ore_selection(full, sizes)["B"]["se_t_kwh_per_size"]
    ratio, x = np.array(a) / np.array(b), np.array(sizes)
    sel = (x >= 100) & (x <= 2000)
    assert np.all((1 / FAST_FACTOR_SE < ratio[sel]) & (ratio[sel] < FAST_FACTOR_SE)), ratio
