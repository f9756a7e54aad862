import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twin.breakage import (BreakageParams, austin_selection, austin_speed_factor, breakage_matrix, check_breakage_matrix,
                           cumulative_breakage, selection_maximum_um)
from twin.errors import ModelError, TwinInputError
from twin.solve.simulate import batch_exact
from twin.sizes import SizeGrid


def test_selection_maximum_is_where_the_rate_peaks():
    g = SizeGrid(top_um=20000.0, ratio=2 ** 0.125, count=120)
    s = austin_selection(g, 1.0, alpha=1.0, mu_um=3000.0, Lambda=2.5)
    x_peak = g.mid_um[np.argmax(s)]
    assert x_peak == pytest.approx(selection_maximum_um(1.0, 3000.0, 2.5), rel=0.05)


@pytest.mark.parametrize("delta", [0.0, 0.3])
def test_b_conserves_mass_and_is_lower_triangular(delta):
    g = SizeGrid()
    b = breakage_matrix(cumulative_breakage(g, 1.0, 4.0, 0.5, delta))
    assert np.allclose(b[:, :-1].sum(axis=0), 1.0, atol=1e-14)
    assert np.all(np.triu(b) == 0) and np.all(b >= 0)


def test_check_rejects_a_leaky_b():
    g = SizeGrid(count=6)
    b = breakage_matrix(cumulative_breakage(g, 1.0, 4.0, 0.5))
    b[3, 1] *= 0.9
    with pytest.raises(ModelError, match="Column 1 .* must sum to 1"):
        check_breakage_matrix(b)


def test_speed_factor_falls_near_critical():
    assert austin_speed_factor(0.8) > austin_speed_factor(0.7) > austin_speed_factor(0.5)
    assert austin_speed_factor(0.99) < 0.5 * austin_speed_factor(0.8)


@settings(max_examples=40, deadline=None)
@given(log_a=st.floats(-2, 2), alpha=st.floats(0.2, 2.0), gamma=st.floats(0.3, 1.5),
       beta=st.floats(2.0, 6.0), phi=st.floats(0.0, 1.0), t=st.floats(0.01, 100.0))
def test_batch_exact_conserves_mass_and_stays_non_negative(log_a, alpha, gamma, beta, phi, t):
    g = SizeGrid(count=20)
    s = austin_selection(g, 10 ** log_a, alpha, 1e6, 2.5)
    b = breakage_matrix(cumulative_breakage(g, gamma, beta, phi))
    m0 = np.zeros(g.count)
    m0[0] = 1.0
    m = batch_exact(s, b, m0, t)
    assert m.sum() == pytest.approx(1.0, abs=1e-10)
    assert m.min() > -1e-12


@pytest.mark.parametrize("make, field", [
    (lambda: BreakageParams.energy_specific(0.009686, 0.6, 2.5, 7.093, 0.2, 0.25, 3.0), "critical_size_um"),
    (lambda: BreakageParams.austin_rate(0.7, 1.0, 3.0, 3.0, 1.0, 4.0, 0.5, power_kw=1.0, holdup_t=0.01), "mu_um"),
])
def test_a_critical_size_in_mm_is_refused_by_the_api_as_by_a_scene(make, field):
    """Moly-Cop's d_crit 7.093 mm, or Austin's mu 3 mm, given in mm where um are expected: the API took them (a
    scene refused them) and ground nothing, P80 the feed's F80 at 1,900 times the nominal hold-up."""
    from scenarios.scene.schema import OreBreakage
    from twin import CRITICAL_SIZE_MIN_UM

    with pytest.raises(TwinInputError, match=f"'{field}' parameter of BreakageParams.* must be a float in \\[100, "):
        make()
    assert OreBreakage.model_fields[field].metadata[0].ge == CRITICAL_SIZE_MIN_UM  # one bound, scene and API
