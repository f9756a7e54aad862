"""Python-API slips a user met: a value of the wrong type kept until it failed far away, a keyword that
raised where it should act, a factor read by nothing, messages in the other unit, a case slip with no hint."""

import math

import pytest

from twin import CycloneSurvey, Hydrocyclone, TabulatedPSD, TwinInputError, load_ore
from twin.ore.mineralogy import Texture


def test_a_texture_read_as_text_is_kept_as_the_number_it_was_checked_as():
    # "150" passed the range check and raised TypeError at the textural index, far from the input
    texture = Texture("150", uniformity="0.6", association_entropy="0.5")
    assert (texture.mean_grain_um, texture.uniformity, texture.association_entropy) == (150.0, 0.6, 0.5)
    assert texture.textural_index == Texture(150.0).textural_index
    with pytest.raises(TwinInputError, match="'mean_grain_um' parameter of Texture must be a float in"):
        Texture("fine")


def test_a_load_given_as_a_flag_is_refused(twin_b):
    with pytest.raises(TwinInputError, match="'load_frac' parameter of steady_state_at_load must be a float in "
                                             r"\(0, 10\], not a bool. Got True"):
        twin_b.steady_at_constant_load(0.7, load_frac=True)


def test_simulate_takes_the_hardness_scale_steady_takes(twin_b):
    """simulate(hardness_scale=...) raised TypeError; it now holds the harder ore's steady state from it, and a
    step back to 1 moves the product toward the nominal one."""
    hard = twin_b.steady(hardness_scale=1.3)
    nominal = twin_b.steady()
    assert hard.p80_um > nominal.p80_um * 1.1
    held = twin_b.simulate(1.0, 0.5, x0=hard.x, hardness_scale=1.3).frame["p80_um"]
    assert held.to_numpy() == pytest.approx(hard.p80_um, rel=1e-5)
    stepped = twin_b.simulate(2.0, 0.5, x0=hard.x, hardness_scale=lambda t: 1.3 if t < 1.0 else 1.0).frame["p80_um"]
    assert stepped.iloc[2] == pytest.approx(hard.p80_um, rel=1e-5)
    assert nominal.p80_um < stepped.iloc[-1] < stepped.iloc[3] < hard.p80_um
    with pytest.raises(TwinInputError, match="hardness_scale"):
        twin_b.simulate(1.0, 0.5, hardness_scale=-1.0)


@pytest.mark.parametrize("factor", ["d50c_factor", "sharpness_factor", "split_factor"])
def test_a_plitt_factor_beside_a_cyclone_given_directly_is_refused(factor):
    direct = dict(d50c_um=100.0, sharpness=2.0, water_bypass_frac=0.3)
    with pytest.raises(TwinInputError, match=f"'{factor}' parameter of Hydrocyclone must be 1 for a cyclone given "
                                             r"directly .* Got 1.5"):
        Hydrocyclone(**direct, **{factor: 1.5})
    # the pressure still comes from Plitt's equation for the geometry: its factor is read
    flow = 500.0
    base = Hydrocyclone(**direct).plitt(flow, 2.7)["pressure_kpa"]
    assert Hydrocyclone(**direct, pressure_factor=1.5).plitt(flow, 2.7)["pressure_kpa"] == pytest.approx(1.5 * base)


@pytest.mark.parametrize("sizes, passing", [([100, 200, 300], [90, 50, 20]), ([300, 200, 100], [0, 50, 20])])
def test_a_screen_analysis_out_of_order_is_refused_in_percent(sizes, passing):
    # the fractions' own check answered "fractions passing (0.5, not 50)" to a user who gave percent
    with pytest.raises(TwinInputError, match=r"'passing_pct' parameter of TabulatedPSD must be cumulative % passing, "
                                             "non-decreasing with sieve size and above 0 at the finest sieve") as err:
        TabulatedPSD.from_sieves(sizes, passing)
    assert "0.5, not 50" not in str(err.value)


def test_a_reference_type_in_lower_case_gets_a_hint():
    with pytest.raises(TwinInputError, match="Got 'b'. Did you mean 'B'"):
        load_ore("b")


def test_a_screen_analysis_with_nothing_on_its_finest_sieve_keeps_its_fine_end():
    """Two finest sieves of equal passing made the fine end's GGS line flat: the pan (24 % of the feed) lay at
    size zero, and 24 % of the feed was below 1.6 um (4.8 % with 21 % passing the finest sieve)."""
    sizes = [4750, 3350, 2360, 1700, 1180, 850, 600, 425, 300, 212, 150, 106, 75]
    passing = [100, 96, 88, 78, 68, 59, 51, 44, 38, 33, 28, 24, 21]
    measured = TabulatedPSD.from_sieves(sizes, passing)
    empty_finest = TabulatedPSD.from_sieves(sizes, passing[:-1] + [24])
    # the line through the finest two sieves whose passing differs: 24 % at 106 um and 28 % at 150 um
    assert empty_finest.fine_modulus == pytest.approx(math.log(28 / 24) / math.log(150 / 106))
    assert float(empty_finest.passing(75.0)) == pytest.approx(0.24)
    assert float(empty_finest.passing(1.64)) < float(measured.passing(1.64)) < 0.05
    with pytest.raises(TwinInputError, match="'passing_pct' parameter of TabulatedPSD must be a % passing that "
                                             "rises between some two sieves"):
        TabulatedPSD.from_sieves([75, 106], [100, 100])
    with pytest.raises(TwinInputError, match="'sizes_um' parameter of TabulatedPSD must be a flat sequence of "
                                             r"positive sieve sizes \[um\]. Got \[75.0, nan\]"):
        TabulatedPSD.from_sieves([75, float("nan")], [50, 100])


@pytest.mark.parametrize("make", [
    lambda d50c: CycloneSurvey(feed_solids_tph=100.0, feed_water_m3_h=60.0, solids_density_t_m3=2.7, d50c_um=d50c,
                               sharpness=2.0, water_bypass_frac=0.3, pressure_kpa=60.0),
    lambda d50c: Hydrocyclone(d50c_um=d50c, sharpness=2.0, water_bypass_frac=0.3)])
def test_a_cut_size_in_mm_is_refused(make):
    # a survey's d50c of 0.1833 (mm) passed `check`, its Plitt factor became 0.0008, and steady blamed the feed
    with pytest.raises(TwinInputError, match=r"'d50c_um' parameter of \w+ must be at least 1 um, the finest cut a "
                                             r"hydrocyclone makes \(mm\? um expected\). Got 0.1833"):
        make(0.1833)
    assert make(183.3).d50c_um == 183.3
