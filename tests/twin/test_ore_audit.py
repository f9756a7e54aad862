"""Ore data a user gives through the Python API: nothing dropped or rescaled unsaid."""

import pytest

from twin import Mineralogy, TwinInputError
from twin.ore import from_mineralogies, load_ore


def test_a_blend_of_mineralogies_needs_fractions_summing_to_one():
    # (0.6, 0.397) was named 'A0.60+D0.40' with its wt% rescaled to 60.4/39.6 % and its grain size not rescaled
    a, d = load_ore("A"), load_ore("D")
    with pytest.raises(TwinInputError, match=r"'fractions' parameter of Mineralogy.blend must be mass fractions "
                                             r"summing to 1 within 1e-06 \(sum 0.997\)"):
        Mineralogy.blend((a, d), (0.6, 0.397))
    assert Mineralogy.blend((a, d), (0.6, 0.4)).wt_pct == a.mix(d, 0.6).wt_pct


def test_a_sample_table_from_mineralogies_keeps_every_ore():
    # ids=["a"] for three ores gave a table of one row, exit 0
    ores = [load_ore(k) for k in "ABC"]
    with pytest.raises(TwinInputError, match=r"one id per ore \(3 ores\). Got 1 ids"):
        from_mineralogies(ores, ids=["a"])
    assert list(from_mineralogies(ores, ids=["a", "b", "c"]).sample_id) == ["a", "b", "c"]
