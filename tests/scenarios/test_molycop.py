"""The Moly-Cop Tools BallSim_Direct base case as a shipped scene: the twin, from the published
inputs, against the published results (scenarios/data/molycop_ballsim_published.toml)."""

import tomllib
from pathlib import Path

import numpy as np
import pytest

from scenarios.run.models import build_models
from scenarios.scene import load_scene, read_toml, scene_from_dict

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenarios" / "molycop_ballsim.toml"
PUBLISHED = tomllib.loads((ROOT / "scenarios" / "data" / "molycop_ballsim_published.toml").read_text())


def _steady(scene):
    twin = build_models(scene).plant
    ss = twin.steady(feed_tph=scene.feed.feed_tph, speed_frac_critical=scene.feed.speed_frac_critical)
    up = twin.grid.upper_um
    cum = twin.grid.cumulative_passing(ss.psd)
    passing = 100 * np.interp(np.log(PUBLISHED["sieves_um"]), np.log(up[::-1]), cum[::-1], right=1.0)
    return ss, passing


@pytest.fixture(scope="module")
def shipped():
    return _steady(load_scene(SCENE))


def test_overflow_p80_and_circulating_load_within_five_percent_of_published(shipped):
    ss, _ = shipped
    goal = PUBLISHED["goal_rel"]
    assert ss.p80_um == pytest.approx(PUBLISHED["overflow_p80_um"], rel=goal)
    assert ss.outputs["circulating_load_frac"] == pytest.approx(PUBLISHED["circulating_load_frac"], rel=goal)


def test_net_specific_energy_is_the_given_power_per_fresh_feed(shipped):
    ss, _ = shipped
    assert ss.outputs["specific_energy_kwh_t"] == pytest.approx(PUBLISHED["net_specific_energy_kwh_t"],
                                                                rel=PUBLISHED["goal_rel"])
    assert ss.outputs["specific_energy_kwh_t"] == pytest.approx(PUBLISHED["net_power_kw"] / 504.0, rel=1e-9)


def test_overflow_passing_within_two_points_on_every_sieve(shipped):
    _, passing = shipped
    diff = np.abs(passing - np.asarray(PUBLISHED["overflow_passing_pct"]))
    assert diff.max() <= PUBLISHED["goal_passing_points"], diff


def test_water_balance_closes_and_matches_the_published_stream_solids(shipped):
    ss, _ = shipped
    o = ss.outputs
    assert o["underflow_solids_frac"] == pytest.approx(PUBLISHED["underflow_solids_frac"], abs=0.01)
    assert o["overflow_solids_frac"] == pytest.approx(PUBLISHED["overflow_solids_frac"], abs=0.01)
    # the overflow carries the fresh feed's solids (steady state) in the water the cyclone does not bypass
    over_solids = o["throughput_tph"]
    assert over_solids / (over_solids + o["overflow_water_m3_h"]) == pytest.approx(o["overflow_solids_frac"], rel=1e-9)
    # water in = water out: mill and sump additions leave in the overflow
    assert o["mill_water_m3_h"] + o["sump_water_m3_h"] == pytest.approx(o["overflow_water_m3_h"], rel=1e-9)


def test_the_first_order_discretisation_misses_the_published_case():
    """The test can fail: Austin's classical discrete form on the same sieves, same parameters,
    is 15-26 % off (benchmarks/results/twin_molycop.md), outside the goal."""
    raw = read_toml(SCENE)
    raw["mill"]["size_classes"]["scheme"] = "austin"
    ss, _ = _steady(scene_from_dict(raw, SCENE))
    assert abs(ss.outputs["circulating_load_frac"] / PUBLISHED["circulating_load_frac"] - 1) > PUBLISHED["goal_rel"]
