"""A second Moly-Cop Tools BallSim_Direct base case (v2.0, 425 t/h) as a shipped scene: the twin, from the
published inputs, against the published results (scenarios/data/molycop_ballsim_425_published.toml).

The scene runs the mill as Moly-Cop computes it (its discrete form, 3.87 mixers as 4, S^E per kWh the balls draw;
the scene's header). The tests hold the overflow P80 and the circulating load to the first case's 5 % goal, the
energy to the given power, and the scene's mill to Moly-Cop's printed numbers."""

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


def test_circulating_load_within_five_percent_of_published(shipped):
    assert shipped.outputs["circulating_load_frac"] == pytest.approx(PUBLISHED["circulating_load_frac"], rel=GOAL_REL)


def test_the_scenes_mill_is_moly_cops_as_printed():
    """The share of the net power S^E is stated on is the published balls' kW over net kW, whose quotient by the
    published mill feed is Moly-Cop's specific energy per pass (t of its J&T cell, to 0.1 %: the net kW's is 16 %
    above); the mixers are its N to the nearest whole one; the breakage terms its discrete form."""
    raw = read_toml(SCENE)
    mill_feed = PUBLISHED["feed_tph"] * (1.0 + PUBLISHED["circulating_load_frac"])
    assert PUBLISHED["balls_power_kw"] / mill_feed == pytest.approx(
        PUBLISHED["mill_model"]["specific_energy_per_pass_kwh_t"], rel=1e-3)
    assert raw["ores"]["molycop425"]["breakage"]["selection_power_frac"] == pytest.approx(
        PUBLISHED["balls_power_kw"] / PUBLISHED["net_power_kw"], abs=5e-5)
    assert raw["mill"]["n_mixers"] == round(PUBLISHED["mill_model"]["mixers"])
    assert raw["mill"]["size_classes"]["scheme"] == "austin"


@pytest.mark.parametrize("edit, what", [
    (lambda r: r["ores"]["molycop425"]["breakage"].pop("selection_power_frac"), "S^E per net kWh"),
    (lambda r: r["mill"]["size_classes"].update(scheme="cell_average"), "the twin's cell-average reading"),
])
def test_the_load_test_can_fail(edit, what):
    """S^E per net kWh (the load 21 % low) or the twin's own cell-average reading of Moly-Cop's parameters (69 %
    high; twin_molycop_425.md) misses the published circulating load by more than the goal."""
    ss = _edited(edit)
    assert abs(ss.outputs["circulating_load_frac"] / PUBLISHED["circulating_load_frac"] - 1.0) > GOAL_REL, what
