"""Fracture-energy distributions: ML fits recover known parameters; goodness of fit can fail."""

import math

import numpy as np
import pandas as pd
import pytest

from twin.errors import TwinInputError
from twin.ore.fracture_energy import (SizeDependence, breakage_probability, fit_by_group,
                                  fit_fracture_energy, fit_size_dependence, read_single_particle,
                                  sample_fracture_energies)


@pytest.mark.parametrize("e50, sigma, n, seed", [(150.0, 0.6, 400, 1), (40.0, 0.35, 100, 2),
                                                 (900.0, 1.0, 30, 3)])
def test_lognormal_fit_recovers_median_and_spread(e50, sigma, n, seed):
    e = sample_fracture_energies(n, e50, sigma, random_state=seed)
    f = fit_fracture_energy(e)
    # tolerance from the sample size: 4 standard errors of the ML estimates
    assert abs(math.log(f.e50_j_kg / e50)) < 4 * sigma / math.sqrt(n)
    assert abs(f.sigma - sigma) < 4 * sigma / math.sqrt(2 * n)
    assert f.breakage_probability(f.e50_j_kg) == pytest.approx(0.5)


def test_median_is_not_the_mean():
    """A fit that returned the arithmetic mean (E50 exp(sigma^2/2)) would fail the test above."""
    e = sample_fracture_energies(400, 150.0, 1.0, random_state=1)
    assert abs(math.log(fit_fracture_energy(e).e50_j_kg / 150.0)) < 4 * 1.0 / math.sqrt(400)
    assert abs(math.log(e.mean() / 150.0)) > 4 * 1.0 / math.sqrt(400)


def test_truncated_lognormal_recovers_upper_limit():
    e = sample_fracture_energies(400, 150.0, 0.7, e_max_j_kg=500.0, random_state=3)
    assert e.max() < 500.0
    ft = fit_fracture_energy(e, model="truncated_lognormal")
    fl = fit_fracture_energy(e, model="lognormal")
    assert ft.e_max_j_kg == pytest.approx(500.0, rel=0.15)
    assert ft.e50_j_kg == pytest.approx(150.0, rel=0.1) and ft.sigma == pytest.approx(0.7, rel=0.1)
    assert ft.log_likelihood > fl.log_likelihood + 5
    assert ft.breakage_probability(ft.e_max_j_kg) == 1.0
    # untruncated data: no evidence of truncation, the log-normal limit is returned
    plain = fit_fracture_energy(sample_fracture_energies(400, 150.0, 0.7, random_state=4),
                                model="truncated_lognormal")
    assert math.isinf(plain.e_max_j_kg) or plain.e_max_j_kg > 20 * 150.0


def test_goodness_of_fit_accepts_lognormal_and_rejects_bimodal():
    good = fit_fracture_energy(sample_fracture_energies(60, 150.0, 0.5, random_state=5),
                               n_boot=200, random_state=0)
    assert good.ks_pvalue > 0.05 and good.ks_pvalue_method.startswith("parametric bootstrap")
    bimodal = np.concatenate([sample_fracture_energies(30, 30.0, 0.1, random_state=6),
                              sample_fracture_energies(30, 600.0, 0.1, random_state=7)])
    bad = fit_fracture_energy(bimodal, n_boot=200, random_state=0)
    assert bad.ks_pvalue < 0.01


def test_breakage_probability_shape():
    e = np.array([1.0, 10.0, 100.0, 1000.0])
    p = breakage_probability(e, 100.0, 0.8)
    assert np.all(np.diff(p) > 0) and p[2] == pytest.approx(0.5)
    assert breakage_probability(0.0, 100.0, 0.8) == 0.0


def test_per_type_and_size_fits_and_size_dependence(tmp_path):
    truth = {"A": SizeDependence(160.0, 6.0, 1.1, 0.0), "D": SizeDependence(40.0, 3.0, 0.9, 0.0)}
    sizes = [3.35, 6.7, 13.4, 21.8]    # mm, geometric means of root-2 / 2:1 classes
    rows = []
    rng = np.random.default_rng(11)
    for t, sd in truth.items():
        for d in sizes:
            for i, e in enumerate(sample_fracture_energies(150, sd.e50_j_kg(d), 0.5, random_state=rng)):
                rows.append({"particle_id": f"{t}-{d}-{i}", "ore_type": t, "size_mm": d,
                             "fracture_energy_j_kg": e})
    p = tmp_path / "spt.csv"
    p.write_text("# synthetic single-particle results\n" + pd.DataFrame(rows).to_csv(index=False))
    fits = fit_by_group(read_single_particle(p))
    assert len(fits) == 8 and set(fits.ore_type) == {"A", "D"}
    for t, sd in truth.items():
        g = fits[fits.ore_type == t]
        assert np.all(np.abs(np.log(g.e50_j_kg / sd.e50_j_kg(g.size_mm))) < 4 * g.ln_e50_se)
        sdf = fit_size_dependence(g.size_mm, g.e50_j_kg, weights=1 / g.ln_e50_se)
        # the curve itself is recovered across the sampled sizes within a few standard errors
        assert np.all(np.abs(np.log(sdf.e50_j_kg(np.array(sizes)) / sd.e50_j_kg(np.array(sizes)))) < 0.1)


def test_size_dependence_parameters_recovered_from_exact_medians():
    sd = SizeDependence(80.0, 5.0, 1.2, 0.0)
    d = np.array([1.0, 2.4, 4.0, 6.7, 11.2, 19.0, 31.5, 63.0])
    f = fit_size_dependence(d, sd.e50_j_kg(d))
    assert f.e_inf_j_kg == pytest.approx(80.0, rel=1e-4)
    assert f.d0_mm == pytest.approx(5.0, rel=1e-4) and f.phi == pytest.approx(1.2, rel=1e-4)


def test_bad_single_particle_rows_reported(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("particle_id,ore_type,size_mm,fracture_energy_j_kg\n"
                 "p1,A,21.8,120.0\np2,A,21.8,-3\np3,A,0,80\n")
    with pytest.raises(TwinInputError) as err:
        read_single_particle(p)
    msg = str(err.value)
    assert "particle_id='p2'" in msg and "fracture_energy_j_kg" in msg and "-3" in msg
    assert "particle_id='p3'" in msg and "size_mm" in msg
    with pytest.raises(TwinInputError, match="energies_j_kg"):
        fit_fracture_energy([1.0, 2.0, 0.0])
    with pytest.raises(TwinInputError, match="'model'"):
        fit_fracture_energy([1.0, 2.0, 3.0], model="weibull")


def test_drop_weight_outcomes_recover_distribution():
    """Particles with log-normal fracture energies, each hit once at one of six set energies."""
    from twin.ore.fracture_energy import fit_breakage_outcomes
    rng = np.random.default_rng(21)
    levels = np.array([40.0, 70.0, 110.0, 170.0, 260.0, 400.0])
    applied = np.repeat(levels, 80)
    strength = sample_fracture_energies(len(applied), 120.0, 0.6, random_state=rng)
    f = fit_breakage_outcomes(applied, strength <= applied)
    assert f.e50_j_kg == pytest.approx(120.0, rel=0.1)
    assert f.sigma == pytest.approx(0.6, rel=0.2)
    with pytest.raises(TwinInputError, match="complete separation"):
        fit_breakage_outcomes([10.0, 20.0, 30.0, 40.0], [False, False, True, True])
