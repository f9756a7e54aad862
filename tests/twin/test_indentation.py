"""Oliver-Pharr analysis recovers E and H from synthesised curves.

All curves here are synthesised with the same relations the analysis inverts, so these are
consistency checks of the implementation (fit, stiffness, contact depth, area, moduli), not
validation against measured data.
"""

import numpy as np
import pandas as pd
import pytest

from twin.errors import TwinInputError
from twin.ore.indentation import (AreaFunction, Indenter, analyse_curves, oliver_pharr, read_curves,
                              reduced_modulus_gpa, synthesize_curve, youngs_from_reduced_gpa)


@pytest.mark.parametrize("E, H, nu, m", [
    (94.5, 11.8, 0.08, 1.3),     # quartz-like
    (3.2, 0.25, 0.30, 1.6),      # kaolinite-like, soft and deep
    (305.9, 14.9, 0.15, 1.4),    # pyrite-like, stiff and shallow
    (33.8, 1.1, 0.25, 1.5),      # biotite-like
])
def test_recovers_known_modulus_and_hardness_within_one_percent(E, H, nu, m):
    c = synthesize_curve(E, H, sample_poisson=nu, m=m, hold_points=10, hold_creep_nm=2.0)
    r = oliver_pharr(c.load_mn, c.depth_nm, sample_poisson=nu)
    assert r.youngs_gpa == pytest.approx(E, rel=0.01)
    assert r.hardness_gpa == pytest.approx(H, rel=0.01)
    assert r.m == pytest.approx(m, rel=1e-3)
    assert r.reduced_modulus_gpa == pytest.approx(reduced_modulus_gpa(E, nu), rel=0.01)


def test_fused_silica_reference_values():
    """Consistency check with the published fused-silica values (O&P 1992: E = 72 GPa,
    nu = 0.17, H ~ 9 GPa; diamond E_i = 1141 GPa, nu_i = 0.07): E_r must be ~69.6 GPa."""
    c = synthesize_curve(72.0, 9.0, sample_poisson=0.17, p_max_mn=10.0)
    r = oliver_pharr(c.load_mn, c.depth_nm, sample_poisson=0.17)
    assert r.reduced_modulus_gpa == pytest.approx(69.6, abs=0.05)
    assert r.youngs_gpa == pytest.approx(72.0, rel=0.01)
    assert r.hardness_gpa == pytest.approx(9.0, rel=0.01)
    assert 0.3 < r.h_f_nm / r.h_max_nm < 0.5       # fused silica recovers much of its depth


def test_noisy_curves_stay_close():
    """0.05 % load noise and 0.1 nm depth noise: each curve within 2 %, mean of 8 within 1 %."""
    E_hat, H_hat = [], []
    for seed in range(8):
        c = synthesize_curve(72.0, 9.0, sample_poisson=0.17, noise_mn=0.005, noise_nm=0.1,
                             n_unload=200, random_state=seed)
        r = oliver_pharr(c.load_mn, c.depth_nm, sample_poisson=0.17)
        E_hat.append(r.youngs_gpa)
        H_hat.append(r.hardness_gpa)
    assert np.max(np.abs(np.array(E_hat) / 72.0 - 1)) < 0.02
    assert np.max(np.abs(np.array(H_hat) / 9.0 - 1)) < 0.02
    assert np.mean(E_hat) == pytest.approx(72.0, rel=0.01)
    assert np.mean(H_hat) == pytest.approx(9.0, rel=0.01)


def test_calibrated_area_function_and_beta_matter():
    blunt = AreaFunction(24.5, (800.0, 3000.0))
    c = synthesize_curve(72.0, 9.0, sample_poisson=0.17, area=blunt, beta=1.034)
    good = oliver_pharr(c.load_mn, c.depth_nm, sample_poisson=0.17, area=blunt, beta=1.034)
    assert good.youngs_gpa == pytest.approx(72.0, rel=0.01) and good.hardness_gpa == pytest.approx(9.0, rel=0.01)
    naive = oliver_pharr(c.load_mn, c.depth_nm, sample_poisson=0.17)   # ideal tip, beta = 1
    assert naive.hardness_gpa > 9.0 * 1.05 and naive.youngs_gpa > 72.0 * 1.05
    assert blunt.contact_depth_nm(float(blunt.area_nm2(123.0))) == pytest.approx(123.0)


def test_youngs_from_reduced_round_trip_and_limit():
    d = Indenter()
    assert youngs_from_reduced_gpa(reduced_modulus_gpa(200.0, 0.3, d), 0.3, d) == pytest.approx(200.0)
    with pytest.raises(TwinInputError, match="reduced modulus"):
        youngs_from_reduced_gpa(2000.0, 0.2, d)


def test_read_and_analyse_csv(tmp_path):
    a = synthesize_curve(72.0, 9.0, sample_poisson=0.25)
    b = synthesize_curve(94.5, 11.8, sample_poisson=0.25)
    a["curve_id"], b["curve_id"] = "fs-1", "qz-1"
    p = tmp_path / "curves.csv"
    text = "# synthetic curves\n" + pd.concat([a, b])[["curve_id", "depth_nm", "load_mn"]].to_csv(index=False)
    p.write_text(text)
    res = analyse_curves(p, sample_poisson=0.25)
    assert list(res.curve_id) == ["fs-1", "qz-1"]
    assert res.youngs_gpa.tolist() == pytest.approx([72.0, 94.5], rel=0.01)
    bad = tmp_path / "bad.csv"
    bad.write_text(text + "qz-1,12.0,oops\n")
    with pytest.raises(TwinInputError, match=r"row \d+ \(curve_id='qz-1'\): column 'load_mn'.*'oops'"):
        read_curves(bad)
    # a curve's id again after another curve: grouped by id, the two were analysed as one curve of two cycles
    twice = tmp_path / "twice.csv"
    c = a.assign(curve_id="fs-1")
    twice.write_text(pd.concat([a, b, c])[["curve_id", "depth_nm", "load_mn"]].to_csv(index=False))
    with pytest.raises(TwinInputError, match=rf"curve_id 'fs-1' starts again at row {len(a) + len(b) + 1}, after"):
        read_curves(twice)


def test_bad_inputs_named():
    c = synthesize_curve(72.0, 9.0)
    with pytest.raises(TwinInputError, match="fit_range"):
        oliver_pharr(c.load_mn, c.depth_nm, fit_range=(0.9, 0.5))
    with pytest.raises(TwinInputError, match="'hardness_gpa'"):
        synthesize_curve(72.0, -1.0)
