"""A second Moly-Cop Tools BallSim_Direct base case (v2.0, 425 t/h) as a shipped scene: the twin, from the
published inputs, against the published results (scenarios/data/molycop_ballsim_425_published.toml).

The twin meets the published overflow P80 (+0.6 %) and misses the published circulating load (+23 %,
benchmarks/results/twin_molycop_425.md). The tests hold both: the P80 to the 5 % goal of the first case,
the load to its documented gap, so that a change of the twin that moves it (closing it, or widening it)
fails here and updates README's "Your own circuit" and this file."""

import tomllib
from pathlib import Path

import pytest

from scenarios.run.models import build_models
from scenarios.scene import load_scene, read_toml, scene_from_dict

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenarios" / "molycop_ballsim_425.toml"
PUBLISHED = tomllib.loads((ROOT / "scenarios" / "data" / "molycop_ballsim_425_published.toml").read_text())
#: The first case's goals (issue 13): P80 and circulating load within 5 % of the published.
GOAL_REL = 0.05
#: The twin's circulating load over the published, less 1 (twin_molycop_425.md): the documented gap.
LOAD_GAP_REL = 0.23
#: How far the gap may move before this test asks for the README and the gap to be updated: below the
#: case's own spread from what it leaves open (3 -> 6 mixers: -4.4 %; the derived cut +-5 %: -5.5/+7.8 %).
LOAD_GAP_TOL = 0.03


def _steady(scene):
    twin = build_models(scene).plant
    return twin.steady(feed_tph=scene.feed.feed_tph, speed_frac_critical=scene.feed.speed_frac_critical)


def _edited(edit):
    raw = read_toml(SCENE)
    edit(raw)
    return _steady(scene_from_dict(raw, SCENE))


@pytest.fixture(scope="module")
def shipped():
    return _steady(load_scene(SCENE))


def _load_error(ss):
    return ss.outputs["circulating_load_frac"] / PUBLISHED["circulating_load_frac"] - 1.0


def test_overflow_p80_within_five_percent_of_published(shipped):
    assert shipped.p80_um == pytest.approx(PUBLISHED["overflow_p80_um"], rel=GOAL_REL)


def test_circulating_load_holds_its_documented_gap(shipped):
    """Outside the goal: +23 %, more than the mixers or the derived cut account for."""
    assert abs(_load_error(shipped)) > GOAL_REL
    assert _load_error(shipped) == pytest.approx(LOAD_GAP_REL, abs=LOAD_GAP_TOL)


def test_net_specific_energy_is_the_given_power_per_fresh_feed(shipped):
    assert shipped.outputs["specific_energy_kwh_t"] == pytest.approx(
        PUBLISHED["net_power_kw"] / PUBLISHED["feed_tph"], rel=1e-9)


def test_a_cut_that_meets_the_published_load_misses_the_published_p80(shipped):
    """The gap is not the derived cut (Moly-Cop's correlation; not printed): a cut 20 % coarser brings the
    load within the goal and takes the P80 out of it."""
    coarser = _edited(lambda r: r["effect_options"]["classification"]["cyclone"].update(
        d50c_um=1.2 * r["effect_options"]["classification"]["cyclone"]["d50c_um"]))
    assert abs(_load_error(coarser)) < GOAL_REL
    assert coarser.p80_um / PUBLISHED["overflow_p80_um"] - 1.0 > GOAL_REL


def test_the_first_order_discretisation_misses_the_published_p80():
    """The P80 test can fail: Austin's classical discrete form on the same sieves, same parameters, is
    11 % finer (twin_molycop_425.md), outside the goal."""
    ss = _edited(lambda r: r["mill"]["size_classes"].update(scheme="austin"))
    assert abs(ss.p80_um / PUBLISHED["overflow_p80_um"] - 1.0) > GOAL_REL
