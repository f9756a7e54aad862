"""Ore data a user gives through the Python API: nothing dropped or rescaled unsaid."""

import pytest

from twin import Mineralogy, TwinInputError
from twin.ore import from_mineralogies, load_ore


def test_a_blend_of_mineralogies_needs_fractions_summing_to_one():
    # (0.6, 0.397) was named 'A0.60+D0.40' with its wt% rescaled to 60.4/39.6 % and its grain size not rescaled
    a, d = load_ore("A"), load_ore("D")
    with pytest.raises(TwinInputError, match=r"'fractions' parameter of Mineralogy.blend must be mass fractions "
                                             r"summing to 1 within 0.001 \(sum 0.997\)"):
        Mineralogy.blend((a, d), (0.6, 0.397))
    assert Mineralogy.blend((a, d), (0.6, 0.4)).wt_pct == a.mix(d, 0.6).wt_pct


def test_a_sample_table_from_mineralogies_keeps_every_ore():
    # ids=["a"] for three ores gave a table of one row, exit 0
    ores = [load_ore(k) for k in "ABC"]
    with pytest.raises(TwinInputError, match=r"one id per ore \(3 ores\). Got 1 ids"):
        from_mineralogies(ores, ids=["a"])
    assert list(from_mineralogies(ores, ids=["a", "b", "c"]).sample_id) == ["a", "b", "c"]


def test_a_blend_typed_to_three_decimals_is_taken_and_rescaled_to_sum_to_one_everywhere():
    """Thirds typed 0.333 (sum 0.999) were refused by Blend and Twin (within 1e-6) and taken by a scene (1e-3),
    which rescaled them; now each takes them within 5e-4 per ore and rescales them to sum to 1 (the components
    carry the whole feed), and a slip of 0.6 + 0.3 stays refused everywhere."""
    import numpy as np

    from twin import Blend, Twin
    from twin.ore import BLEND_SUM_TOLERANCE_PER_ORE, blend_sum_ok, blend_sum_tolerance

    assert blend_sum_tolerance(3) == 3 * BLEND_SUM_TOLERANCE_PER_ORE
    thirds = (0.333, 0.333, 0.333)
    a, b, c = (load_ore(k) for k in "ABC")
    blend = Blend((a, b, c), thirds)
    assert blend.fractions == pytest.approx((1 / 3,) * 3, abs=1e-15) and sum(blend.fractions) == pytest.approx(1, 1e-15)
    mixed = Mineralogy.blend((a, b, c), thirds)
    assert sum(mixed.wt_pct.values()) == pytest.approx(100.0, rel=1e-12)
    assert mixed.texture == Mineralogy.blend((a, b, c), (1 / 3,) * 3).texture
    twin = Twin(["A", "B", "C"], effects=["breakage", "transport"])
    fr = twin.blend_fractions({"A": 0.333, "B": 0.333, "C": 0.333})
    assert np.allclose(fr, 1 / 3, rtol=0, atol=1e-15)
    assert np.array_equal(twin.blend_fractions(blend), fr)
    assert not blend_sum_ok((0.6, 0.3, 0.0)) and not blend_sum_ok((0.6, 0.397))  # two ores typed: 1e-3 at most
    with pytest.raises(TwinInputError, match="summing to 1 within 0.0015"):
        twin.blend_fractions([0.6, 0.3, 0.0])
    with pytest.raises(TwinInputError, match="must sum to 1 within 0.001"):
        Blend((a, b), (0.6, 0.3))
