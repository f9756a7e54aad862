"""A small valid continuous scene, written to a file, for tests to break one key at a time."""

from __future__ import annotations

from pathlib import Path

import pytest

BASE_SCENE = """\
effects = ["breakage", "transport", "holdup", "cushioning", "power"]
calibration_mismatch_ok = true  # a lean test scene: fewer effects than the calibration was fitted with

[scene]
name = "base"
duration_h = 8.0
sample_period_h = 0.25

[mill]
preset = "industrial"

[ores.B]
type = "B"

[ores.D]
type = "D"

[feed]
blend = { B = 1.0 }
feed_tph = 30.0
speed_frac_critical = 0.70

[[feed.schedule]]
at_h = 2.0
kind = "ramp"
ramp_h = 1.0
blend = { B = 0.6, D = 0.4 }

[controller]
kind = "nmpc"
target_p80_um = 210.0

[controller.bounds]
feed_tph_min = 20.0
feed_tph_max = 45.0
"""

#: BASE_SCENE's controller bounds: an open loop reads none (a scene file giving them is refused)
BASE_BOUNDS = "\n[controller.bounds]\nfeed_tph_min = 20.0\nfeed_tph_max = 45.0\n"
assert BASE_BOUNDS in BASE_SCENE


def open_loop(text: str = BASE_SCENE) -> str:
    """BASE_SCENE (or a text with its controller) as an open loop: kind "none", without the feed bounds."""
    return text.replace('kind = "nmpc"', 'kind = "none"', 1).replace(BASE_BOUNDS, "\n", 1)


@pytest.fixture
def write_scene(tmp_path):
    """``write_scene(text=BASE_SCENE, name="scene.toml") -> Path``."""

    def write(text: str = BASE_SCENE, name: str = "scene.toml") -> Path:
        path = tmp_path / name
        path.write_text(text, encoding="utf-8")
        return path

    return write


@pytest.fixture
def clay_ore(tmp_path) -> Path:
    """An ore file of 90 % kaolinite: its mill slurry is past jamming at the shipped calibration's
    clay crowding (the deposit's ores carry at most 40 % clay)."""
    ore = tmp_path / "clay.toml"
    ore.write_text("[mineralogy]\nkaolinite = 90.0\nquartz = 10.0\n\n[texture]\nmean_grain_um = 20.0\n"
                   "uniformity = 0.6\nassociation_entropy = 0.5\n")
    return ore


@pytest.fixture
def no_run(monkeypatch):
    """Fail the test if a run gets as far as building its models (it should have been refused)."""
    import scenarios.run.runner as runner

    def boom(scene):
        raise AssertionError("the run started although it should have been refused")

    monkeypatch.setattr(runner, "build_models", boom)
