"""Transformations of a scene that must leave its physical answer unchanged (or shifted in a known way): the
names and order of its ores, one ore given under two names, equal mixers given by count or by shares, a
schedule shifted in time, and a run held at constant inputs against the steady state it settles to."""

import numpy as np
import pytest

from scenarios.run.models import build_models
from scenarios.run.runner import run_scene
from scenarios.scene import load_scene

CIRCUIT = """\
effects = ["breakage", "transport", "holdup", "speed", "cushioning", "rheology", "power", "classification"]
calibration_mismatch_ok = true  # a coarse grid: a quick test
[scene]
name = "metamorphic"
duration_h = DURATION
sample_period_h = 0.1
[mill]
preset = "industrial"
MIXERS
size_classes = { top_um = 6700.0, ratio = 2.0, count = 12 }
ORES
[feed]
blend = BLEND
feed_tph = 30.0
speed_frac_critical = 0.72
SCHEDULE
[effect_options.classification]
kind = "hydrocyclone"
"""

KEYS = ("p80_um", "load_frac", "power_kw", "circulating_load_frac", "holdup_t", "cyclone_pressure_kpa")


def _scene(write_scene, name, ores=("B", "D"), types=None, blend="{ B = 0.6, D = 0.4 }", mixers="n_mixers = 3",
           schedule="", duration=2.0):
    types = types or ores
    text = (CIRCUIT.replace("ORES", "\n".join(f'[ores.{n}]\ntype = "{t}"' for n, t in zip(ores, types)))
            .replace("BLEND", blend).replace("MIXERS", mixers).replace("SCHEDULE", schedule)
            .replace("DURATION", repr(duration)))
    return load_scene(write_scene(text, name=f"{name}.toml"))


def _steady(scene, blend=None):
    plant = build_models(scene).plant
    blend = blend if blend is not None else dict(scene.feed.blend)
    return plant.steady(feed_tph=30.0, speed_frac_critical=0.72, blend=blend).outputs


@pytest.mark.parametrize("variant", [
    dict(ores=("D", "B"), blend="{ D = 0.4, B = 0.6 }"),                        # listed in the other order
    dict(ores=("zeta", "alpha"), types=("B", "D"), blend="{ zeta = 0.6, alpha = 0.4 }"),  # renamed
    dict(ores=("B", "D"), mixers="mixer_volume_fracs = [0.3333333333333333, 0.3333333333333333, "
                                  "0.3333333333333334]"),                          # equal mixers as shares
], ids=["reordered", "renamed", "mixer shares"])
def test_names_order_and_spelling_of_a_scene_leave_its_steady_state(write_scene, variant):
    base = _steady(_scene(write_scene, "base"))
    other = _steady(_scene(write_scene, "other", **variant))
    for key in KEYS:
        assert other[key] == pytest.approx(base[key], rel=1e-9), key


def test_one_ore_given_under_two_names_grinds_as_that_ore(write_scene):
    alone = _steady(_scene(write_scene, "alone", ores=("B",), blend="{ B = 1.0 }"))
    twice = _steady(_scene(write_scene, "twice", ores=("B1", "B2"), types=("B", "B"),
                           blend="{ B1 = 0.3, B2 = 0.7 }"))
    for key in KEYS:
        assert twice[key] == pytest.approx(alone[key], rel=1e-9), key


def test_a_run_at_constant_inputs_settles_to_the_steady_state_and_shifts_with_its_schedule(write_scene):
    """A step from B to the 60/40 blend at 0.2 h: 4 h later the run is the blend's steady state; the same step
    0.5 h later (and the run 0.5 h longer) gives the same run 0.5 h later."""
    step = "[[feed.schedule]]\nat_h = AT\nkind = \"step\"\nblend = { B = 0.6, D = 0.4 }"
    runs = [run_scene(_scene(write_scene, f"run{i}", blend="{ B = 1.0 }", schedule=step.replace("AT", repr(at)),
                             duration=4.0 + shift), progress=False, plots=False).frame
            for i, (at, shift) in enumerate(((0.2, 0.0), (0.7, 0.5)))]
    end = runs[0].iloc[-1]
    settled = _steady(_scene(write_scene, "settled"))
    for key in KEYS:
        assert end[key] == pytest.approx(settled[key], rel=1e-6), key
        late = runs[1][key].to_numpy()[5:]
        assert np.allclose(late, runs[0][key].to_numpy(), rtol=1e-6, atol=0.0), key
