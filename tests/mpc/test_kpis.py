"""mpc.kpis: the trapezoid rule against exact integrals, and refusals where a wrong number was
silent."""

import math

import numpy as np
import pytest

from mpc.kpis import cumulative, integral, outside_band_frac, p80_iae_um_h, within_band_frac


def test_the_trapezoid_rule_is_exact_for_piecewise_linear_rates():
    t = np.array([0.0, 0.5, 2.0, 3.0])
    assert integral(t, 2.0 * t + 1.0) == pytest.approx(3.0 ** 2 + 3.0)  # int_0^3 (2t + 1) dt
    assert integral(t, 4.0) == pytest.approx(12.0)
    np.testing.assert_allclose(cumulative(t, 2.0 * t), t ** 2)
    # |P80 - target| crossing zero between samples: the trapezoid of the absolute samples
    assert p80_iae_um_h([0.0, 1.0], [200.0, 220.0], 210.0) == pytest.approx(10.0)


def test_a_rate_of_another_length_or_shuffled_times_are_refused():
    """[0, 1, 2] h with two rates gave 3.0, and shuffled times a wrong integral, silently."""
    with pytest.raises(ValueError, match="3 times and 2 rates"):
        integral([0, 1, 2], [1, 2])
    with pytest.raises(ValueError, match="strictly increasing"):
        integral([0, 2, 1], [1, 1, 1])


def test_a_missing_sample_counts_as_outside_every_band():
    """within_band counted a NaN P80 outside and outside_band counted a NaN load inside."""
    assert within_band_frac([200.0, math.nan, 205.0, 210.0], 210.0) == 0.75
    assert outside_band_frac([1.0, math.nan, 0.5], (0.8, 1.2)) == pytest.approx(2.0 / 3.0)
