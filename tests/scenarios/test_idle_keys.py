"""Keys a scene file gives that no number of its own run reads are refused, naming key, value and why: the
controller keys its kind does not read (an open loop's, a PI loop's, a batch grind's), an open loop's power and
load noise. A program's variant of a file (a sweep over controller.kind) keeps the file's keys."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from scenarios import run_scene
from scenarios.errors import SceneError
from scenarios.run.sweep import expand_cases, validate_cases
from scenarios.scene.loader import check_scene, read_toml, scene_from_dict
from tests.scenarios.conftest import BASE_SCENE

SCENES = Path(__file__).parents[2] / "scenarios"
OPEN_LOOP = BASE_SCENE.replace('kind = "nmpc"', 'kind = "none"', 1).replace(
    "\n[controller.bounds]\nfeed_tph_min = 20.0\nfeed_tph_max = 45.0\n", "")
NMPC_KEYS = '\nhorizon_steps = 10\nsolver = "rti"\n\n[controller.weights]\np80 = 5.0\n'
NOISY = "\n[sensors]\np80_noise_um = 3.0\npower_noise_kw = 5.0\nload_noise_frac = 0.01\n"


def test_an_open_loop_files_power_and_load_noise_are_refused(write_scene):
    """An open loop records the analyser's P80 only: 50 kW of power noise for none changed no number of the run
    (frame and KPIs to the last digit), and the file passed `grindtwin check`. Refused; a controller reads them."""
    data = read_toml(write_scene(OPEN_LOOP + NOISY))
    data["scene"]["duration_h"], data["feed"]["schedule"] = 2.0, []
    runs = []
    for noise in (0.0, 50.0):  # a program's variant of the file keeps the keys: the evidence runs
        case = copy.deepcopy(data)
        case["sensors"]["power_noise_kw"] = noise
        runs.append(run_scene(scene_from_dict(case, "s.toml"), progress=False, plots=False))
    numeric = runs[0].frame.select_dtypes("number").columns
    assert np.array_equal(runs[0].frame[numeric].to_numpy(), runs[1].frame[numeric].to_numpy(), equal_nan=True)
    assert runs[0].kpis == pytest.approx(runs[1].kpis, nan_ok=True)
    messages = check_scene(write_scene(OPEN_LOOP + NOISY, name="open.toml"))
    assert [m.split(": ")[1] for m in messages] == ["sensors.power_noise_kw", "sensors.load_noise_frac"], messages
    assert "read by nothing: an open loop" in messages[0] and messages[0].endswith("(got 5.0)")
    assert check_scene(write_scene(BASE_SCENE + NOISY, name="nmpc.toml")) == []


def test_an_open_loop_files_controller_keys_are_refused_and_change_no_number(write_scene):
    """controller.kind = "none" holds the scene's inputs: its weights and feed bounds changed no number of the run
    (frame and KPIs to the last digit) and the file passed `grindtwin check`; its target and load band are the
    KPIs'."""
    text = OPEN_LOOP.replace("target_p80_um = 210.0", "target_p80_um = 210.0" + NMPC_KEYS, 1)
    data = read_toml(write_scene(text))
    data["scene"]["duration_h"], data["feed"]["schedule"] = 2.0, []
    runs = []
    for weight in (1.0, 2.0):
        case = copy.deepcopy(data)
        case["controller"]["weights"]["p80"] = weight
        case["controller"]["bounds"] = {"feed_tph_min": 20.0 * weight, "feed_tph_max": 45.0 * weight}
        runs.append(run_scene(scene_from_dict(case, "s.toml"), progress=False, plots=False))
    numeric = runs[0].frame.select_dtypes("number").columns
    assert np.array_equal(runs[0].frame[numeric].to_numpy(), runs[1].frame[numeric].to_numpy(), equal_nan=True)
    assert runs[0].kpis == pytest.approx(runs[1].kpis, nan_ok=True)
    messages = check_scene(write_scene(text + "\n[controller.bounds]\nfeed_tph_max = 45.0\n", name="open.toml"))
    assert [m.split(": ")[1] for m in messages] == ["controller.horizon_steps", "controller.solver",
                                                    "controller.weights.p80", "controller.bounds.feed_tph_max"]
    assert 'read by nothing: controller.kind = "none" is an open loop' in messages[0] and messages[0].endswith(
        "(got 10)")
    assert check_scene(write_scene(OPEN_LOOP + "load_band_frac = [0.9, 1.1]\n", name="plain.toml")) == []


def test_a_pi_files_nmpc_keys_are_refused_and_its_own_are_read(write_scene):
    """PI moves the feed alone: an NMPC's horizon, weights, solver and speed bounds are refused, its feed bounds
    and feed-rate limit read."""
    pi = BASE_SCENE.replace('kind = "nmpc"', 'kind = "pi"', 1)
    messages = check_scene(write_scene(pi.replace("target_p80_um = 210.0", "target_p80_um = 210.0" + NMPC_KEYS, 1)
                                       + "speed_max = 0.8\n", name="pi.toml"))
    assert [m.split(": ")[1] for m in messages] == ["controller.horizon_steps", "controller.solver",
                                                    "controller.weights.p80", "controller.bounds.speed_max"]
    assert all('read by nothing: controller.kind = "pi" moves the feed rate alone' in m for m in messages)
    assert check_scene(write_scene(pi + "feed_rate_max_tph_per_h = 20.0\n", name="own.toml")) == []


def test_the_controller_models_keys_a_plant_replaces_are_refused_where_no_nmpc_runs_it(write_scene):
    """Open loop and PI integrate (PI: are tuned on) the plant's twin only: the reference scene as an open loop
    ran the same to the last digit with the controller's model on 7 or 9 classes, 3 or 4 mixers, an analyser lag of
    0.1 or 0.2 h; each refused, naming the plant's own. An NMPC runs that model: the file is the reference."""
    data = read_toml(SCENES / "reference_transition.toml")
    data["controller"] = {"kind": "none", "target_p80_um": 210.0}
    data["scene"]["duration_h"], data["feed"]["schedule"], data["sensors"] = 0.5, [], {}
    runs = []
    for count, mixers, lag in ((7, 3, 0.1), (9, 4, 0.2)):
        case = copy.deepcopy(data)
        case["mill"]["size_classes"]["count"], case["mill"]["n_mixers"] = count, mixers
        case["effect_options"]["sensor_delay"]["dead_time_h"] = lag
        runs.append(run_scene(scene_from_dict(case, SCENES / "s.toml"), progress=False, plots=False))
    numeric = runs[0].frame.select_dtypes("number").columns
    assert np.array_equal(runs[0].frame[numeric].to_numpy(), runs[1].frame[numeric].to_numpy(), equal_nan=True)
    messages = check_scene(write_scene(
        (SCENES / "reference_transition.toml").read_text().split("[controller]")[0]
        + '[controller]\nkind = "none"\ntarget_p80_um = 210.0\n'))
    assert [m.split(": ")[1] for m in messages] == ["mill.size_classes", "mill.n_mixers", "effect_options.sensor_delay"]
    assert 'read by nothing: an open loop (controller.kind = "none") runs no model of its own' in messages[0]
    assert "takes its own plant.size_classes" in messages[0]
    assert "plant.effects, without 'sensor_delay'" in messages[2]


def test_a_batch_files_controller_keys_are_refused(write_scene):
    """A batch grind has no controller and no P80 target KPI: a target or a load band changed no number and
    passed."""
    text = (SCENES / "batch_50B_50D.toml").read_text() + "target_p80_um = 150.0\nload_band_frac = [0.9, 1.1]\n"
    messages = check_scene(write_scene(text))
    assert [m.split(": ")[1] for m in messages] == ["controller.target_p80_um", "controller.load_band_frac"]
    assert "read by nothing: a batch grind" in messages[0] and messages[0].endswith("(got 150.0)")


def test_a_batch_files_start_is_refused(write_scene):
    """A batch grind starts with its charge: feed.start = "scene" changed no number and passed."""
    text = (SCENES / "batch_50B_50D.toml").read_text().replace("p80_um = 3200.0", 'p80_um = 3200.0\nstart = "scene"')
    messages = check_scene(write_scene(text))
    assert len(messages) == 1 and "feed.start: read by nothing: a batch grind" in messages[0], messages


def test_a_pi_scene_is_not_refused_for_the_nmpcs_speed_bounds(write_scene):
    """PI holds the scene's speed and reads no speed bound: a PI scene at 0.88 of critical was refused as outside
    the NMPC's default speed bounds [0.6, 0.85], which it never reads (an NMPC still is)."""
    fast = BASE_SCENE.replace("speed_frac_critical = 0.70", "speed_frac_critical = 0.88")
    assert check_scene(write_scene(fast.replace('kind = "nmpc"', 'kind = "pi"', 1), name="pi.toml")) == []
    messages = check_scene(write_scene(fast, name="nmpc.toml"))
    assert len(messages) == 1 and "feed.speed_frac_critical: initial speed outside controller.bounds" in messages[0]


def test_a_sweep_over_the_controller_kind_keeps_the_files_keys():
    """README's sweep of the reference scene over none, pi and nmpc: each case is the file's table with another kind
    (the file's NMPC keys, power and load noise are read by the nmpc case), validated as a program's variant."""
    path = SCENES / "reference_transition.toml"
    cases = expand_cases(read_toml(path), {"controller.kind": ["none", "pi", "nmpc"]})
    assert len(validate_cases(cases, path)) == 3
    for case, key in zip(cases, ("sensors.power_noise_kw", "controller.horizon_steps")):  # as a file of its own
        with pytest.raises(SceneError, match=f"{key}: read by nothing"):
            scene_from_dict(case.data, path, as_written=True)
