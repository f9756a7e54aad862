"""Ore data a user gives through the Python API: nothing dropped or rescaled unsaid."""

import pytest

from twin import Mineralogy, TwinInputError
from twin.ore import load_ore


def test_a_blend_of_mineralogies_needs_fractions_summing_to_one():
    # (0.6, 0.397) was named 'A0.60+D0.40' with its wt% rescaled to 60.4/39.6 % and its grain size not rescaled
    a, d = load_ore("A"), load_ore("D")
    with pytest.raises(TwinInputError, match=r"'fractions' parameter of Mineralogy.blend must be mass fractions "
                                             r"summing to 1 within 1e-06 \(sum 0.997\)"):
        Mineralogy.blend((a, d), (0.6, 0.397))
    assert Mineralogy.blend((a, d), (0.6, 0.4)).wt_pct == a.mix(d, 0.6).wt_pct

