"""BondCalibrator: scikit-learn contract and fit to a peak-force target (tiny agglomerates)."""

import numpy as np
import pandas as pd
import pytest

from dem.calibrate import BondCalibrator
from dem.errors import DemInputError


def _cal(**kw):
    args = dict(n_particles=10, particle_diameter_m=0.022, spheres_per_particle=30,
                random_state=3, platen_speed_m_s=0.3, tol_pct=2.0)
    args.update(kw)
    return BondCalibrator(**args)


def test_constructor_only_stores_arguments():
    c = _cal()
    assert c.get_params()["spheres_per_particle"] == 30
    assert not [k for k in vars(c) if k.endswith("_")]


def test_fit_matches_target_peak_force_with_few_simulations():
    c = _cal().fit(2000.0)
    assert c.calibration_error_pct_ <= 2.0
    assert abs(c.mean_peak_force_N_ - 2000.0) / 2000.0 * 100 == pytest.approx(c.calibration_error_pct_)
    assert c.peak_force_N_.shape == (10,)
    assert c.n_iter_ <= 6
    # the returned parameters are those of the best iteration
    assert c.calibration_error_pct_ == pytest.approx(c.history_["peak_error_pct"].min())
    assert 1 <= c.best_iteration_ <= c.n_iter_
    assert c.cohesion_Pa_ == pytest.approx(2.0 * c.tensile_strength_Pa_)
    assert c.ks_Pa_m_ == pytest.approx(0.4 * c.kn_Pa_m_)
    assert np.all(c.fracture_energy_J_ > 0)
    assert len(c.results_frame()) == 10
    # the strength was fitted: far from the starting guess of 10 MPa
    assert c.history_["tensile_strength_Pa"].iloc[-1] != c.history_["tensile_strength_Pa"].iloc[0]
    # reproducible
    c2 = _cal().fit(2000.0)
    assert c2.tensile_strength_Pa_ == c.tensile_strength_Pa_


def test_a_fit_on_two_processes_is_the_fit_on_one():
    """n_jobs runs an iteration's compression tests on several processes: each test is a pure
    function of its packing and bonds, so the fit, every iteration and every particle's numbers
    must be exactly those of one process (a test answered out of order or by a worker's other
    kernel settings would not be)."""
    one = _cal(n_particles=4, max_iter=2).fit(2000.0)
    two = _cal(n_particles=4, max_iter=2, n_jobs=2).fit(2000.0)
    assert two.n_jobs == 2 and two.bond_params_ == one.bond_params_
    np.testing.assert_array_equal(two.peak_force_N_, one.peak_force_N_)
    assert len(set(one.peak_force_N_.tolist())) == 4  # four different packings, in their order
    np.testing.assert_array_equal(two.specific_fracture_energy_J_kg_, one.specific_fracture_energy_J_kg_)
    pd.testing.assert_frame_equal(two.history_, one.history_)


def test_fit_rejects_bad_input():
    with pytest.raises(DemInputError, match="target_peak_force_N"):
        _cal().fit(-1.0)
    with pytest.raises(DemInputError, match="n_jobs"):
        _cal(n_jobs=0).fit(1000.0)
    with pytest.raises(DemInputError, match="n_particles"):
        _cal(n_particles=0).fit(1000.0)
