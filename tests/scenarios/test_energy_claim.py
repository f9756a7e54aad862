"""MISSION.md: "feed-forward control saves 5-10 % energy and stabilises the product size". A controller
saves energy per tonne only against an operation held to the same product: the reference transition (Type B,
then 60 % B / 40 % D) run by its NMPC, without control at the feed that holds B at the target, and without
control at the one feed that keeps both ores at or finer than the target (mpc.feed_holding_every_blend; the
margin an operator without a controller grinds to). benchmarks/mpc_energy_claim.py tables the same runs and
the one-day replay."""

from pathlib import Path

import numpy as np
import pytest

from mpc import feed_for_target, feed_holding_every_blend, specific_energy_kwh_t
from scenarios.run import run_scene
from scenarios.run.closed_loop import start_feed_bounds_tph
from scenarios.run.models import build_models
from scenarios.scene import load_scene, scene_from_dict
from scenarios.scene.loader import read_toml

SCENE = Path(__file__).resolve().parents[2] / "scenarios" / "reference_transition.toml"
#: The blends at the schedule's ends (B, then the ramp to 60 % B / 40 % D): the ramp's blends lie between.
BLENDS = ([1.0, 0.0], [0.6, 0.4])
#: Out of specification: coarser than the target by more than the KPI's band [um].
SPEC_UM = 10.0
#: The hours of Type B before the ramp (the scene's schedule starts it at 3 h).
FIRST_ORE_H = (0.0, 3.0)


def _run(kind: str, feed_tph: float | None = None):
    data = read_toml(SCENE)
    data["controller"]["kind"] = kind
    if feed_tph is not None:
        data["feed"]["start"] = "scene"
        data["feed"]["feed_tph"] = feed_tph
    res = run_scene(scene_from_dict(data, SCENE), progress=False, plots=False)
    p80 = res.frame["p80_um"].to_numpy(float)
    first = res.frame[res.frame["time_h"].between(*FIRST_ORE_H)]
    return {"kwh_t": res.kpis["specific_energy_kwh_t"], "first_ore_kwh_t": specific_energy_kwh_t(first),
            "coarse": float(np.mean(p80 > res.scene.controller.target_p80_um + SPEC_UM))}


@pytest.fixture(scope="module")
def safe():
    scene = load_scene(SCENE)
    plant, bounds = build_models(scene).plant, start_feed_bounds_tph(scene)
    target, speed = scene.controller.target_p80_um, scene.feed.speed_frac_critical
    return {"plant": plant, "target": target, "speed": speed,
            "feed": feed_holding_every_blend(plant, BLENDS, target, speed, bounds),
            "each": [feed_for_target(plant, b, target, speed, bounds) for b in BLENDS]}


def test_the_safe_feed_keeps_every_blend_at_or_finer_than_the_target(safe):
    """At the least of the blends' target feeds, the blend that set it sits at the target and the other is
    finer (a grate mill's product coarsens with its feed); the clay blend, though softer, needs the lower
    feed (its slurry carries coarser particles through the grate)."""
    assert safe["feed"] == min(safe["each"]) and safe["each"][1] < safe["each"][0]
    p80 = [safe["plant"].steady(feed_tph=safe["feed"], speed_frac_critical=safe["speed"], blend=b).p80_um
           for b in BLENDS]
    assert p80[1] == pytest.approx(safe["target"], abs=0.05) and p80[0] < safe["target"] - 1.0, p80


def test_control_saves_energy_against_the_feed_that_keeps_every_ore_in_specification(safe):
    """No control at B's target feed leaves the specification (the blend coarsens) and draws the least
    energy per tonne: it trades product for energy. The fixed feed that keeps both ores in specification
    grinds B finer than it needs; the NMPC, in specification throughout, draws less energy than it, over
    the run and, on B's hours, by MISSION.md's 5-10 %."""
    nmpc, none, fixed = _run("nmpc"), _run("none"), _run("none", safe["feed"])
    assert none["coarse"] > 0.3 and nmpc["coarse"] == 0.0 and fixed["coarse"] == 0.0, (none, nmpc, fixed)
    assert none["kwh_t"] < nmpc["kwh_t"] < fixed["kwh_t"], (none, nmpc, fixed)
    saving = 1.0 - nmpc["first_ore_kwh_t"] / fixed["first_ore_kwh_t"]
    assert 0.05 <= saving <= 0.10, saving
