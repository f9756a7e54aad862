"""Unit slips and wrong types that fell inside the twin's ranges and gave a wrong number without a
word: each is refused before any work, naming the field, the value and what is allowed."""

import numpy as np
import pytest

from twin import ModelError, SizeGrid, Twin, TwinInputError
from twin.effects.classification import CycloneSurvey, Hydrocyclone
from twin.mill import LAB, industrial_preset
from twin.ore.mineralogy import Texture
from twin.twin import DEFAULT_EFFECTS

GRID = SizeGrid(top_um=6700.0, count=16)
SURVEY = dict(feed_solids_tph=100.0, feed_water_m3_h=60.0, solids_density_t_m3=2.7, d50c_um=120.0,
              sharpness=2.0, water_bypass_frac=0.3, pressure_kpa=60.0)


def test_a_net_power_in_watts_is_refused_by_the_energy_it_would_spend():
    # 500 (W for the lab mill's 0.5 kW) was taken as a 500 kW draw: 16,000 kWh/t of its 0.031 t/h
    with pytest.raises(TwinInputError, match=r"'net_power_kw' parameter of Mill 'lab' must be at most 15.5 kW, "
                                             r"500 kWh/t of the nominal feed 0.031 t/h \(the net draw in kW, not W\)"
                                             r". Got 500.0"):
        LAB.with_(net_power_kw=500.0)
    assert LAB.with_(net_power_kw=0.5).net_power_kw == 0.5
    # the Moly-Cop scene's published 3885 kW on the industrial mill's stand-in dimensions stays allowed
    assert industrial_preset().with_(net_power_kw=3885.0).net_power_kw == 3885.0


@pytest.mark.parametrize("field", ["power_factor", "discharge_factor", "diameter_m", "net_power_kw",
                                   "powder_filling_nominal", "discharge_exponent"])
def test_true_is_no_number_for_a_mill(field):
    # True passed every range check as 1.0 (a bool is an int): a power factor of 1, a 1 m mill
    with pytest.raises(TwinInputError, match=f"'{field}' parameter of Mill 'lab' must be a number, not a bool. "
                                             "Got True"):
        LAB.with_(**{field: True})


def test_true_is_no_number_for_a_cyclone():
    with pytest.raises(TwinInputError, match="'d50c_factor' parameter of Hydrocyclone must be a number, not a bool"):
        Hydrocyclone(d50c_factor=True)
    with pytest.raises(TwinInputError, match="'sharpness' parameter of CycloneSurvey must be a number, not a bool"):
        CycloneSurvey(**{**SURVEY, "sharpness": True})


def test_a_cyclone_feed_dilution_given_as_a_fraction_is_refused():
    # 0.42 (for 42 % solids by volume) ran the industrial circuit at a cyclone pressure of 1e15 kPa
    # and returned a P80 of 119 um for 202
    with pytest.raises(TwinInputError, match=r"'feed_solids_vol_pct' parameter of Hydrocyclone must be a float in "
                                             r"\[1, 70\). Got 0.42"):
        Hydrocyclone(feed_solids_vol_pct=0.42)


@pytest.fixture(scope="module")
def lab_twin():
    return Twin("B", mill="lab", grid=GRID)


@pytest.mark.parametrize("make, field", [
    (lambda t: t.steady(feed_tph=0.03, hardness_scale=True), "'hardness_scale' parameter of Twin must be one number"),
    (lambda t: Twin("B", mill="lab", grid=GRID, n_mixers=True),  # was one mixer
     r"'n_mixers' parameter of Twin must be an integer in \[1, 20\]"),
    (lambda t: Twin("B", mill="lab", grid=GRID, feed_modulus=True),  # was a GGS modulus of 1
     "'feed_modulus' parameter of Twin must be one number")])
def test_true_is_no_number_for_a_twin(lab_twin, make, field):
    with pytest.raises(TwinInputError, match=f"{field}.*Got True"):
        make(lab_twin)


@pytest.mark.parametrize("changes, allowed", [
    (dict(diameter_m=0.1), r"at most 0.2 of the mill's diameter \(20 mm of diameter_m 0.1\)"),  # 25 mm balls
    (dict(diameter_m=0.02), r"at most 0.2 of the mill's diameter"),  # a ball wider than the mill
    (dict(ball_size_mm=1.0), r"a float in \[10, 200\)")])  # 1 (inch) was a 1 mm ball: 25x the rates
def test_a_ball_too_large_for_its_mill_or_in_inches_is_refused(changes, allowed):
    with pytest.raises(TwinInputError, match=f"'ball_size_mm' parameter of Mill 'lab' must be {allowed}"):
        LAB.with_(**changes)
    assert LAB.with_(ball_size_mm=50.0).ball_size_mm == 50.0  # a fifth of the 0.5 m mill is 100 mm


def test_a_grate_cut_in_mm_is_refused():
    # 0.5 (mm for 500 um) held every class back: a steady hold-up of 2e9 t in a mill holding 0.08 t
    # and a P80 of 69 um, with exit 0
    with pytest.raises(TwinInputError, match=r"'grate_d50_um' parameter of Mill 'lab' must be a float in "
                                             r"\[10, 1e\+06\). Got 0.5"):
        LAB.with_(grate_d50_um=0.5)
    assert LAB.with_(grate_d50_um=10.0).grate_d50_um == 10.0  # the calibrations' own lower bound


def test_a_nominal_speed_where_the_rates_vanish_is_refused():
    # the rates are normalised by Austin's speed factor at the nominal speed: zero at 0.1 of critical,
    # negative below (0.05 made the breakage parameters negative, or a solver failure after 19 h of integration)
    with pytest.raises(TwinInputError, match=r"'speed_nominal_frac_critical' parameter of Mill 'lab' must be a "
                                             r"float in \(0.1, 1\). Got 0.05"):
        LAB.with_(speed_nominal_frac_critical=0.05)


def test_an_analyser_dead_time_in_minutes_is_refused_by_the_mills_residence_time():
    effects = list(DEFAULT_EFFECTS) + ["sensor_delay"]
    # 5 (min for 0.083 h) was a 5 h dead time, 15 residence times of the lab mill, within the option's 24 h
    with pytest.raises(ModelError, match=r"'dead_time_h' option of effect 'sensor_delay' must be at most 10 of the "
                                         r"mill's nominal residence times \(3.\d+ h; one is 0.3\d+ h\), in hours"
                                         r".*Got 5.0"):
        Twin("B", mill="lab", grid=GRID, effects=effects, effect_options={"sensor_delay": {"dead_time_h": 5.0}})
    twin = Twin("B", mill="lab", grid=GRID, effects=effects, effect_options={"sensor_delay": {"dead_time_h": 0.1}})
    assert twin.model.describe().count("analyser_dead_time_h") == 1


@pytest.mark.parametrize("make", [lambda: SizeGrid(count=25, ratio=True), lambda: Texture(True)],
                         ids=["SizeGrid.ratio", "Texture.mean_grain_um"])
def test_true_is_no_number_wherever_a_range_is_checked(make):
    """twin.errors.check_range refuses a bool itself: SizeGrid, Texture and the other callers
    without a field-by-field bool check took True as 1.0."""
    with pytest.raises(TwinInputError, match="not a bool"):
        make()


def test_a_nominal_feed_in_kg_per_hour_given_as_t_per_hour_is_noted():
    """LAB.with_(feed_nominal_tph=31.0) (31 kg/h meant) ran to a P80 of 3 mm with no word: the
    mill then holds its charge under 2 s (twin.validity.residence_note); its design feed, 25 min."""
    from twin.validity import MIN_NOMINAL_RESIDENCE_H

    slip = Twin("B", mill=LAB.with_(feed_nominal_tph=31.0))
    tau_s = 3600.0 * slip.spec.holdup_nominal_t / slip.spec.feed_nominal_tph
    assert tau_s < 3600.0 * MIN_NOMINAL_RESIDENCE_H
    notes = slip.steady(feed_tph=31.0).notes
    assert any("is feed_nominal_tph in kg/h?" in n and f"for {tau_s:.3g} s" in n for n in notes), notes
    assert any("kg/h?" in n for n in slip.simulate(0.1, 0.05, feed_tph=31.0).notes)
    assert not any("kg/h?" in n for n in Twin("B", mill="lab").steady().notes)


def test_a_misspelt_effect_or_mill_is_named_before_the_calibration_is_read(tmp_path):
    """The twin's names are checked before its calibration loads (a second on a fresh interpreter):
    with a calibration file that does not exist, the misspelling is still what is reported."""
    missing = tmp_path / "no_such_calibration.json"
    with pytest.raises(ModelError, match=r"The 'effects' parameter of Twin: Unknown effect 'transprt'\. "
                                         r"Did you mean 'transport'\?"):
        Twin(effects=["breakage", "transprt"], calibration=str(missing))
    with pytest.raises(ModelError, match=r"The 'effect_options' parameter of Twin: Unknown option 'x' of effect"):
        Twin(effect_options={"power": {"x": 1}}, calibration=str(missing))
    with pytest.raises(TwinInputError, match=r"The 'mill' must be one of .*Got 'labb'\. Did you mean 'lab'\?"):
        Twin(mill="labb", calibration=str(missing))
    with pytest.raises(TwinInputError, match="no_such_calibration"):  # the names right: the file is what is wrong
        Twin(calibration=str(missing))


def test_a_steady_state_without_feed_says_which_outputs_are_undefined():
    """Twin.steady(feed_tph=0): the P80 and the per-tonne outputs are NaN, and a note says which
    and why (the CLI said "undefined"; the Python API gave NaN and no word); a fed state has no
    such note."""
    t = Twin()
    ss = t.steady(feed_tph=0.0)
    assert np.isnan(ss.p80_um) and np.isnan(ss.outputs["specific_energy_kwh_t"])
    note = [n for n in ss.notes if "undefined (NaN)" in n]
    assert len(note) == 1 and note[0].startswith("p80_um, specific_energy_kwh_t, ")
    assert note[0].endswith("no feed: the steady mill is empty and makes no product")
    nan = {k for k, v in ss.outputs.items() if isinstance(v, float) and np.isnan(v)}
    assert nan == set(note[0].split(" undefined")[0].split(", "))  # every NaN named, nothing else
    assert not any("undefined" in n for n in t.steady().notes)


def test_a_mill_keeping_another_mills_nominal_feed_is_noted():
    """LAB.with_(diameter_m=3, length_m=4.5) kept the lab mill's 0.031 t/h as its nominal feed, the twin's default:
    its steady state ground to 1.6 um with notes that blamed the breakage rates' units. A note now names the nominal
    feed, the power and the specific energy they mean; the shipped mills have none, nor the big mill given its own."""
    from twin import SPECIFIC_ENERGY_RANGE_KWH_T, power_kw

    big = LAB.with_(diameter_m=3.0, length_m=4.5)
    power = power_kw(big, big.speed_nominal_frac_critical)
    assert power / big.feed_nominal_tph > SPECIFIC_ENERGY_RANGE_KWH_T[1]
    notes = [n for n in Twin("B", mill=big).steady().notes if "nominal feed" in n]
    assert len(notes) == 1 and notes[0].startswith("mill 'lab': its nominal feed 0.031 t/h at its ")
    assert f"is {power / big.feed_nominal_tph:.3g} kWh/t, outside the 0.5-100 kWh/t ball mills draw" in notes[0]
    own = big.with_(feed_nominal_tph=power / 12.0)  # 12 kWh/t
    for mill in ("lab", "industrial", own):
        assert not [n for n in Twin("B", mill=mill).notes if "nominal feed" in n], mill
