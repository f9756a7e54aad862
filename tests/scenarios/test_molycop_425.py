"""A second Moly-Cop Tools BallSim_Direct base case (v2.0, 425 t/h) as a shipped scene: the twin, from the
published inputs, against the published results (scenarios/data/molycop_ballsim_425_published.toml).

The twin meets the published overflow P80 (+0.6 %) and misses the published circulating load (+23 %; no single
cut meets both, benchmarks/results/twin_molycop_425.md and README's "Your own circuit"). The tests hold the P80
to the first case's 5 % goal and the energy to the given power; the load's miss is documented, not pinned."""

import tomllib
from pathlib import Path

import pytest

from scenarios.run.models import build_models
from scenarios.scene import load_scene, read_toml, scene_from_dict

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenarios" / "molycop_ballsim_425.toml"
PUBLISHED = tomllib.loads((ROOT / "scenarios" / "data" / "molycop_ballsim_425_published.toml").read_text())
#: The first case's goal (issue 13): P80 within 5 % of the published.
GOAL_REL = 0.05


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


def test_overflow_p80_within_five_percent_of_published(shipped):
    assert shipped.p80_um == pytest.approx(PUBLISHED["overflow_p80_um"], rel=GOAL_REL)


def test_net_specific_energy_is_the_given_power_per_fresh_feed(shipped):
    assert shipped.outputs["specific_energy_kwh_t"] == pytest.approx(
        PUBLISHED["net_power_kw"] / PUBLISHED["feed_tph"], rel=1e-9)


def test_the_first_order_discretisation_misses_the_published_p80():
    """The P80 test can fail: Austin's classical discrete form on the same sieves, same parameters, is
    11 % finer (twin_molycop_425.md), outside the goal."""
    ss = _edited(lambda r: r["mill"]["size_classes"].update(scheme="austin"))
    assert abs(ss.p80_um / PUBLISHED["overflow_p80_um"] - 1.0) > GOAL_REL
