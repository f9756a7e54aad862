"""Python-API slips a user met: a value of the wrong type kept until it failed far away, a keyword that
raised where it should act, a factor read by nothing, messages in the other unit, a case slip with no hint."""

import math

import numpy as np
import pytest

from twin import (BreakageParams, CycloneSurvey, GatesGaudinSchuhmann, Hydrocyclone, Mineralogy, RosinRammler, SizeGrid,
                  TabulatedPSD, Twin, TwinInputError, discretise, load_ore, size_mill)
from twin.ore.mineralogy import Texture


@pytest.mark.parametrize("make, field", [
    (lambda: Texture("150"), "'mean_grain_um' parameter of Texture"),
    (lambda: RosinRammler("500", 1.0), "'x63_um' parameter of RosinRammler"),
    (lambda: GatesGaudinSchuhmann("5000", 0.8), "'x_max_um' parameter of GatesGaudinSchuhmann"),
    (lambda: SizeGrid(top_um="6700"), "'top_um' parameter of SizeGrid"),
    (lambda: Hydrocyclone(diameter_cm="38"), "'diameter_cm' parameter of Hydrocyclone"),
    (lambda: BreakageParams("1.0"), "'se_1mm_t_kwh' parameter of BreakageParams"),
    (lambda: size_mill("B", "31", 210.0), "'feed_tph' parameter of size_mill")])
def test_a_number_given_as_text_is_refused_where_it_is_given(make, field):
    """A number as text passed the range checks (float("150")) and was kept as text: Texture("150") raised
    TypeError at the textural index, SizeGrid(top_um="6700") at its sizes, size_mill("31") mid-sizing."""
    with pytest.raises(TwinInputError, match=f"{field} must be a float in .*, a number, not text. Got '"):
        make()


def test_an_integer_of_numpys_is_an_integer():
    # np.int64(25) was refused as "must be an integer ... Got np.int64(25)"
    assert SizeGrid(count=np.int64(25)) == SizeGrid(count=25) and type(SizeGrid(count=np.int64(25)).count) is int
    assert Hydrocyclone(count=np.int32(3)).count == 3
    with pytest.raises(TwinInputError, match=r"'count' parameter of SizeGrid must be an integer in \[3, 400\]. Got 25.0"):
        SizeGrid(count=25.0)


def test_a_blend_of_mineralogies_needs_a_fraction_per_ore():
    # zip dropped ore D: Mineralogy.blend((A, B, D), (0.5, 0.5)) was A and B half and half
    a, b, d = (load_ore(k) for k in "ABD")
    with pytest.raises(TwinInputError, match=r"'fractions' parameter of Mineralogy.blend must be one per ore "
                                             r"\(3 ores\). Got \[0.5, 0.5\]"):
        Mineralogy.blend((a, b, d), (0.5, 0.5))
    assert Mineralogy.blend((a, b, d), (0.5, 0.5, 0.0)).wt_pct == Mineralogy.blend((a, b), (0.5, 0.5)).wt_pct


def test_a_screen_analysis_with_material_on_its_coarsest_sieve_is_not_made_finer():
    """passing jumped to 1 just above the coarsest sieve: 10 % retained on 1000 um was put at 1000-1189 um, a
    finer feed than measured (the docstring said the rest lies in the top class), and the twin took it."""
    measured = TabulatedPSD.from_sieves([1000, 500, 250, 125], [90, 60, 35, 20])
    assert measured.passing([1189.0, 6700.0]).tolist() == [0.9, 0.9]
    with pytest.raises(TwinInputError, match=r"the feed_psd's coarsest sieve \(1000 um\) passes 90.0%: the 10.0% "
                                             "retained on it has no known size; add the sieve that all of the feed"):
        Twin("B", feed_psd=measured)
    near = TabulatedPSD.from_sieves([1000, 500, 250, 125], [99.5, 60, 35, 20])  # within a sieve analysis's error
    fractions = discretise(SizeGrid(), near)
    assert fractions[0] == pytest.approx(0.005) and fractions.sum() == pytest.approx(1.0)


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
    with pytest.raises(TwinInputError, match="'sizes_um' parameter of TabulatedPSD must be a flat sequence of >= 2 "
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


def test_a_viscosity_in_pa_s_is_refused():
    # 0.001 (water in Pa s) passed `check`, cut Plitt's d50c to a thirtieth (d50c ~ mu^0.5), the mill overloaded
    # and steady blamed the feed
    with pytest.raises(TwinInputError, match=r"'viscosity_cp' parameter of Hydrocyclone must be at least 0.28 cP, "
                                             r"water's near boiling .*Pa s\? 1 cP is 0.001 Pa s\). Got 0.001"):
        Hydrocyclone(viscosity_cp=0.001)
    assert Hydrocyclone(viscosity_cp=0.3).viscosity_cp == 0.3


def test_an_overflow_or_overload_names_cyclones_whose_pressure_at_the_nominal_feed_is_no_grinding_cyclones():
    """Cyclone sizes in inches read as cm put Plitt's pressure at 1049 kPa at the nominal feed (the 34-276 kPa
    grinding cyclones run at); the mill overloaded and only the feed was named. The same cyclones in cm: no note.
    Plitt's pressure goes as D^-0.37 Di^-0.94 h^-0.28 (Du^2 + Do^2)^-0.87: 2.54^3.33 times higher in inches."""
    from twin import get_mill, nominal_pressure_note

    inch = dict(diameter_cm=20.0, inlet_cm=5.1, vortex_finder_cm=7.0, apex_cm=3.9, free_vortex_height_cm=59.0)
    mill = get_mill("industrial").with_(feed_nominal_tph=200.0, diameter_m=4.0, length_m=6.0, power_factor=1.0)
    notes, pressure = {}, {}
    for name, scale in (("inch", 1.0), ("cm", 2.54)):
        cyclone = {"count": 6, "feed_solids_frac": 0.6, **{k: scale * v for k, v in inch.items()}}
        tw = Twin("B", mill=mill, effects=["breakage", "transport", "holdup", "power", "classification"],
                  effect_options={"classification": {"kind": "hydrocyclone", "cyclone": cyclone}})
        notes[name] = nominal_pressure_note(tw.model)
        pressure[name] = tw.model.parameters["cyclone_pressure_kpa"][0]
    assert pressure["inch"] / pressure["cm"] == pytest.approx(2.54 ** 3.33, rel=1e-9)
    assert notes["cm"] == "" and 34.0 < pressure["cm"] < 276.0
    assert notes["inch"] == (f"At the nominal feed the cyclone feed pressure is {pressure['inch']:.4g} kPa, "
                             "outside the "
                             "34-276 kPa (5-40 psi) grinding cyclones run at: are the cyclone's sizes in cm, and a "
                             "survey's pressure in kPa, not psi?")
