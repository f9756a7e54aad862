"""What a process engineer scripting the twin's Python API gets for a plausible mistake: a clear
error naming the parameter, the value and what is allowed, before any work, never a wrong number
returned in silence or a traceback from deep inside."""

import math

import numpy as np
import pytest

from twin import GatesGaudinSchuhmann, RosinRammler, SizeGrid, TabulatedPSD, Twin, TwinInputError, discretise
from twin.mill import LAB

GRID = SizeGrid(top_um=6700.0, count=16)


# ---------------------------------------------------------------- feed size distributions

@pytest.mark.parametrize("kwargs, field", [(dict(feed_p80_um=math.nan), "p80_um"),
                                           (dict(feed_p80_um=-3200.0), "p80_um"),
                                           (dict(feed_modulus=0.0), "m"), (dict(feed_modulus=80.0), "m")])
def test_a_feed_p80_or_modulus_that_is_no_distribution_is_refused(kwargs, field):
    # NaN or a negative P80 made every feed class fraction NaN without an error; a modulus of 0
    # divided by zero; 80 (for 0.80) a feed of one size
    with pytest.raises(TwinInputError, match=f"'{field}' parameter .*feed_p80_um and feed_modulus"):
        Twin("B", grid=GRID, **kwargs)


@pytest.mark.parametrize("make", [lambda: GatesGaudinSchuhmann(-1.0, 0.8),
                                  lambda: GatesGaudinSchuhmann(4000.0, math.nan), lambda: RosinRammler(math.nan, 1.0),
                                  lambda: RosinRammler(200.0, 0.0),
                                  lambda: RosinRammler.from_p80(200.0, 0.0)])
def test_distributions_refuse_sizes_and_moduli_that_give_nan(make):
    with pytest.raises(TwinInputError, match="must be a float in"):
        make()


@pytest.mark.parametrize("sizes, passing", [((100.0, math.nan, 300.0), (0.3, 0.5, 1.0)),
                                            ((100.0, 200.0, 300.0), (0.3, math.nan, 1.0)),
                                            ((100.0, 200.0, 300.0), (0.3, 0.5, math.nan))])
def test_a_screen_analysis_with_nan_is_refused(sizes, passing):
    with pytest.raises(TwinInputError, match="TabulatedPSD"):
        TabulatedPSD(sizes, passing)
    with pytest.raises(TwinInputError, match="TabulatedPSD"):
        TabulatedPSD.from_sieves(sizes, [100 * p for p in passing])


def test_a_screen_analysis_given_as_fractions_is_refused_not_read_as_percent():
    # read as 0.94 % passing 4 mm, 99 % of the feed sat just above the coarsest sieve: a P80 of ~250 um
    # came out of the twin for a feed whose analysis says 94 % passes 4 mm
    with pytest.raises(TwinInputError, match=r"'passing_pct'.*94.43, not 0.9443"):
        TabulatedPSD.from_sieves([1000, 2000, 4000], [0.3, 0.5, 0.94])
    assert TabulatedPSD.from_sieves([1000, 2000, 4000], [30, 50, 94]).passing(4000.0) == pytest.approx(0.94)


def test_a_screen_analysis_as_a_table_is_refused_clearly():
    with pytest.raises(TwinInputError, match="'sizes_um'.*flat sequence"):
        TabulatedPSD.from_sieves([[100, 200]], [[30, 100]])


class _PercentPSD:
    """A user's own distribution whose passing is in percent."""

    def passing(self, x_um):
        return 100.0 * np.minimum(1.0, np.asarray(x_um, float) / 4000.0) ** 0.8


class _NanPSD:
    def passing(self, x_um):
        return np.full(np.shape(x_um), math.nan)


@pytest.mark.parametrize("psd", [_PercentPSD(), _NanPSD()])
def test_a_distribution_object_in_percent_or_nan_is_refused(psd):
    # percent was clipped and renormalised: the top class's mass vanished; NaN went into the model
    with pytest.raises(TwinInputError, match=r"fraction passing \(0.8, not 80\)"):
        discretise(GRID, psd)
    with pytest.raises(TwinInputError, match="passing"):
        Twin("B", grid=GRID, feed_psd=psd)


@pytest.mark.parametrize("count", [1, 2, 16.0])
def test_a_spanning_grid_names_its_count(count):
    with pytest.raises(TwinInputError, match="'count' parameter of SizeGrid.spanning"):
        SizeGrid.spanning(1000.0, 10.0, count)


# ---------------------------------------------------------------- mills

@pytest.mark.parametrize("changes, field", [(dict(ball_density_t_m3=7800.0), "ball_density_t_m3"),
                                            (dict(ball_density_t_m3=math.nan), "ball_density_t_m3"),
                                            (dict(ball_size_mm=0.025), "ball_size_mm"),
                                            (dict(stable_band=1.2), "stable_band")])
def test_a_mill_in_the_wrong_units_is_refused(changes, field):
    # kg/m3 for t/m3 drew 335 kW from the 0.5 m lab mill; NaN made the power NaN; a ball size in m
    # scaled the breakage rates by Austin's ball-size rule; a scalar band failed on unpacking
    with pytest.raises(TwinInputError, match=f"'{field}' parameter of Mill 'lab'"):
        LAB.with_(**changes)


def test_a_mistyped_mill_field_is_named_with_the_right_one():
    with pytest.raises(TwinInputError, match="no field 'diameter'.*Did you mean 'diameter_m'"):
        LAB.with_(diameter=0.6)


# ---------------------------------------------------------------- open-loop runs

@pytest.fixture(scope="module")
def lab_twin():
    return Twin("B", mill="lab", grid=GRID)


@pytest.mark.parametrize("duration_h, dt_h, field", [(0.12, 0.05, "duration_h"), (0.01, 0.05, "dt_h"),
                                                     (math.inf, 0.05, "duration_h"), (1.0, math.inf, "dt_h")])
def test_a_run_off_its_sample_grid_is_refused(lab_twin, duration_h, dt_h, field):
    # 0.12 h at 0.05 h ran 0.1 h and returned it as asked; a sample longer than the run, or an
    # infinite one, failed on a reshape or an integer conversion
    with pytest.raises(TwinInputError, match=f"'{field}' parameter of simulate"):
        lab_twin.simulate(duration_h, dt_h)


def test_a_run_on_its_grid_ends_where_asked(lab_twin):
    assert lab_twin.simulate(0.15, 0.05).frame["time_h"].iloc[-1] == pytest.approx(0.15)


@pytest.mark.parametrize("kwargs, field", [(dict(rtol=-1.0), "rtol"), (dict(atol_rel=0.0), "atol_rel")])
def test_integrator_tolerances_are_checked_before_casadi_sees_them(lab_twin, kwargs, field):
    with pytest.raises(TwinInputError, match=f"'{field}' parameter of simulate"):
        lab_twin.simulate(0.1, 0.05, **kwargs)


def test_an_initial_state_of_the_wrong_length_or_negative_is_the_users_error(lab_twin):
    x0 = lab_twin.model.initial_state(lab_twin.nominal_blend)
    with pytest.raises(TwinInputError, match=f"'x0' parameter of simulate must be a state vector of {x0.size}"):
        lab_twin.simulate(0.1, 0.05, x0=x0[:3])
    with pytest.raises(TwinInputError, match="'x0'.*non-negative masses"):  # was a SolverError
        lab_twin.simulate(0.1, 0.05, x0=-x0)
    with pytest.raises(TwinInputError, match="'x0'.*finite"):
        lab_twin.simulate(0.1, 0.05, x0=np.full(x0.size, math.nan))
    assert lab_twin.simulate(0.1, 0.05, x0=list(x0)).states.shape == (3, x0.size)


# ---------------------------------------------------------------- ores and blends

def test_a_blend_takes_ores_by_name_as_the_twin_does():
    from twin.ore import Blend, load_ore
    # was AttributeError: 'str' object has no attribute 'name'
    blend = Blend(("B", "D"), (0.6, 0.4))
    assert blend.ores == (load_ore("B"), load_ore("D")) and blend.fractions == (0.6, 0.4)
    assert blend.density_t_m3 == pytest.approx(Blend((load_ore("B"), load_ore("D")), (0.6, 0.4)).density_t_m3)
    with pytest.raises(TwinInputError, match="fraction of ore 'B' in Blend must be a float in \\[0, 1\\]. Got '0.6'"):
        Blend(("B", "D"), ("0.6", 0.4))  # was a TypeError from '<='


def test_a_mineralogy_names_a_texture_that_is_no_texture():
    from twin.ore import Mineralogy
    with pytest.raises(TwinInputError, match="'texture' parameter of Mineralogy"):  # failed later on .textural_index
        Mineralogy({"quartz": 100.0}, texture=150.0)
    with pytest.raises(TwinInputError, match="Unknown mineral 1"):  # was a TypeError in the suggestion
        Mineralogy({1: 100.0})


# ---------------------------------------------------------------- effects and their options

@pytest.mark.parametrize("option", [{"circulating_load_nominal": 3.0}, {"cyclone": {"count": 2}}])
def test_hydrocyclone_options_given_with_a_grate_are_refused_not_ignored(option):
    from twin import ModelError
    # the grate (the default kind) reads neither: the twin was built and ran as if they were not there
    with pytest.raises(ModelError, match=f"{next(iter(option))!r} is an option of kind = 'hydrocyclone'"):
        Twin("B", grid=GRID, effect_options={"classification": option})


def test_effect_options_and_effects_of_the_wrong_shape_are_named():
    from twin import ModelError
    from twin.effects.registry import resolve
    with pytest.raises(ModelError, match="options of effect 'classification' must be a table"):  # was AttributeError
        Twin("B", grid=GRID, effect_options={"classification": "grate"})
    with pytest.raises(ModelError, match="list of effect names, not one string"):  # was "Unknown effect 'b'"
        resolve("breakage")


def test_inputs_that_are_not_one_number_are_named():
    """feed_tph and speed take one number: a one-element list failed with a TypeError from inside,
    and text was read as a number; a blend is a Blend, a dict by ore or fractions in the twin's
    order, and effects a list (one string was read letter by letter)."""
    t = Twin(["B", "D"], mill="lab", grid=GRID)
    for bad in ([0.03], np.array([0.03, 0.02]), "0.03", True):
        with pytest.raises(TwinInputError, match="'feed_tph' parameter of Twin must be one number"):
            t.steady(feed_tph=bad)
    with pytest.raises(TwinInputError, match="'speed_frac_critical' parameter of Twin must be one number"):
        t.steady(feed_tph=0.03, speed_frac_critical=[0.7])
    by_dict = t.steady(feed_tph=0.03, blend={"B": 0.6, "D": 0.4})
    assert by_dict.p80_um == t.steady(feed_tph=0.03, blend=[0.6, 0.4]).p80_um
    assert t.steady(feed_tph=0.03, blend={"B": 1.0}).p80_um == t.steady(feed_tph=0.03, blend=[1.0, 0.0]).p80_um
    with pytest.raises(TwinInputError, match=r"Blend ores \['E'\] are not components"):
        t.steady(feed_tph=0.03, blend={"B": 0.6, "E": 0.4})
    with pytest.raises(TwinInputError, match="'blend' parameter of Twin must be a Blend, a dict"):
        t.steady(feed_tph=0.03, blend="B=0.6,D=0.4")
    with pytest.raises(TwinInputError, match=r"must be 2 fractions, of \['B', 'D'\]"):
        t.steady(feed_tph=0.03, blend=[0.6, 0.3, 0.1])
    with pytest.raises(TwinInputError, match="'effects' parameter of Twin must be a list of effect names"):
        Twin("B", mill="lab", grid=GRID, effects="breakage")


def test_a_feed_whose_p80_lies_below_the_grid_is_refused():
    """feed_p80_um = 3.2 (mm written for um) put the feed in the sink class, and the twin returned a
    product P80 (34 um) coarser than its feed without a word; a feed whose P80 is on the grid runs."""
    with pytest.raises(TwinInputError, match=r"feed_p80_um 3.2 puts 100.0% of the feed below the size grid's "
                                             r"finest sieve \(.* um\): its P80 is not on the grid"):
        Twin("B", mill="lab", grid=GRID, feed_p80_um=3.2)
    sink_heavy = np.r_[np.zeros(GRID.count - 1), 1.0]
    with pytest.raises(TwinInputError, match="the feed_psd puts 100.0% of the feed below"):
        Twin("B", mill="lab", grid=GRID, feed_psd=sink_heavy)
    fine = Twin("B", mill="lab", grid=GRID, feed_p80_um=400.0).steady(feed_tph=0.03)
    assert fine.p80_um < 400.0


def test_a_feed_p80_in_mm_on_a_fine_grid_is_refused():
    """On the default grid (finest sieve 1.6 um) feed_p80_um = 3.2 put 47 % of the feed in the sink,
    under the 80 % rule, and the twin answered a product P80 of 3.19 um at 13.4 kWh/t."""
    from twin.twin import FEED_P80_MIN_UM

    with pytest.raises(TwinInputError, match=r"feed_p80_um 3.2 has a P80 of 3.19 um, finer than any ball mill's feed "
                                             rf"\(allowed: at least {FEED_P80_MIN_UM:g} um\)"):
        Twin("B", feed_p80_um=3.2)
    assert Twin("B", feed_p80_um=3200.0).steady(feed_tph=0.031).p80_um < 3200.0


def test_a_blend_ore_of_a_components_name_but_another_mineralogy_is_refused():
    """steady(blend=Blend) matched ores by name: a user's ore named B (100 % pyrite) was answered as the
    twin's own B (P80 216.6 um, the twin built with it gives 165.2), without a word."""
    from twin import Blend, Mineralogy, Texture, load_ore

    tw = Twin(["B", "D"], mill="lab", grid=GRID)
    other = Mineralogy({"pyrite": 100.0}, Texture(100.0), name="B")
    with pytest.raises(TwinInputError, match=r"Blend ore 'B' is not this twin's component 'B' \(another mineralogy"):
        tw.steady(feed_tph=0.031, blend=Blend((other, load_ore("D")), (0.6, 0.4)))
    same = Blend((load_ore("B"), load_ore("D")), (0.6, 0.4))
    assert tw.steady(feed_tph=0.031, blend=same).p80_um == tw.steady(feed_tph=0.031, blend=[0.6, 0.4]).p80_um


def test_a_reference_ores_wt_pct_cannot_be_changed_in_place():
    """`load_ore("B").wt_pct["pyrite"] += 15` changed B for the whole process, past the sum check
    (26 wt% pyrite, hardness index 10.1 GPa against 8.0) and with it the DEM law's reference ore."""
    import copy
    import json
    import pickle

    from twin import load_ore

    b = load_ore("B")
    before = dict(b.wt_pct)
    for edit in (lambda w: w.__setitem__("pyrite", 26.0), lambda w: w.update(pyrite=26.0), lambda w: w.pop("quartz")):
        with pytest.raises(TwinInputError, match="A Mineralogy's wt_pct is read-only"):
            edit(b.wt_pct)
    assert load_ore("B").wt_pct == before
    assert json.loads(json.dumps(b.wt_pct)) == before  # still a dict to JSON, pickle and copies
    assert pickle.loads(pickle.dumps(b)) == b == copy.deepcopy(b)


def test_an_ore_given_as_a_dict_and_a_misspelt_mineral_are_named():
    """Twin({"B": 0.6, "D": 0.4}) raised a bare TypeError (a path expected); fraction("qartz") read 0."""
    from twin import load_ore

    for ores in ({"B": 0.6, "D": 0.4}, 5, None):
        with pytest.raises(TwinInputError, match=r"The 'ores' parameter of Twin must be an ore .* or a Blend"):
            Twin(ores)
    with pytest.raises(TwinInputError, match=r"Unknown mineral 'qartz'. Did you mean 'quartz'"):
        load_ore("B").fraction("qartz")
    assert load_ore("B").fraction("magnetite") == 0.0 and load_ore("B").fraction("quartz") == pytest.approx(0.40)
