"""feed.start: an open-loop scene runs at its own feed rate unless it says "target"; with
"target" it starts at (and holds) the feed rate whose steady state holds the controller's target,
where the closed loops start; "target" without a target is refused with its key path."""

import re
from pathlib import Path

import pytest

from scenarios.errors import SceneError
from scenarios.run import run_scene
from scenarios.scene import load_scene

from .conftest import BASE_BOUNDS, open_loop

OPEN = (open_loop().replace("duration_h = 8.0", "duration_h = 0.5")
        .replace("sample_period_h = 0.25", "sample_period_h = 0.05")
        .replace("at_h = 2.0", "at_h = 0.25").replace("ramp_h = 1.0", "ramp_h = 0.25"))


def test_open_loop_default_runs_at_its_own_feed_rate(write_scene):
    res = run_scene(load_scene(write_scene(OPEN)), progress=False, plots=False)
    assert res.kpis["start_feed_tph"] == pytest.approx(30.0)
    assert res.frame["feed_tph"].eq(30.0).all()


def test_start_target_starts_and_holds_the_target_feed_rate(write_scene):
    scene = OPEN.replace("feed_tph = 30.0", 'feed_tph = 30.0\nstart = "target"')
    res = run_scene(load_scene(write_scene(scene)), progress=False, plots=False)
    k = res.kpis
    assert k["start_feed_tph"] != pytest.approx(30.0, rel=1e-3)  # moved: the test can fail
    assert res.frame["feed_tph"].nunique() == 1  # held
    assert k["start_p80_um"] == pytest.approx(210.0, abs=0.5)  # on target, as a closed loop starts
    assert any("feed.start" in n for n in res.summary["notes"])


def test_start_target_without_a_target_is_refused(write_scene):
    scene = OPEN.replace("feed_tph = 30.0", 'feed_tph = 30.0\nstart = "target"').replace("target_p80_um = 210.0\n", "")
    with pytest.raises(SceneError, match=r"feed\.start"):
        load_scene(write_scene(scene))


def test_a_sweep_over_the_controller_starts_every_case_where_the_scene_says(write_scene):
    """feed.start = "target": the no-control baseline of a sweep starts at the closed loop's
    steady state, and the table says so (start_p80_um: the P80 at t = 0, of the start state;
    start_feed_tph: the start state's feed rate)."""
    from scenarios.cli.commands import sweep_case
    from scenarios.run import run_sweep

    # bounds that hold the start (14.5 t/h): a start outside them is refused (the PI case's; the sweep's file is
    # the open loop's with them)
    scene = OPEN.replace("feed_tph = 30.0", 'feed_tph = 30.0\nstart = "target"') + BASE_BOUNDS.replace("20.0", "10.0")
    table = run_sweep(write_scene(scene), {"controller.kind": ["none", "pi"]}, sweep_case, workers=1,
                      progress=False).set_index("controller.kind")
    assert table["error"].isna().all()
    # the same state: within 0.1 um (the open loop's P80 column comes from the twin's run, 0.07 um
    # below the steady state's own p80_um at the same state; the closed loop's from the model output)
    assert table.loc["none", "start_p80_um"] == pytest.approx(table.loc["pi", "start_p80_um"], abs=0.1)
    assert table.loc["none", "start_p80_um"] == pytest.approx(210.0, abs=0.5)


def test_start_target_finds_the_laboratory_mills_feed_too(write_scene):
    """The target's feed was searched in 5-60 t/h whatever the mill: a laboratory scene (0.031 t/h
    nominal) with start = "target" failed ("no feed rate in 5-60 t/h holds the target"). The range
    now follows the mill's nominal feed; the found feed holds the target."""
    scene = (OPEN.replace('preset = "industrial"', 'preset = "lab"')
             .replace("feed_tph = 30.0", 'feed_tph = 0.03\nstart = "target"')
             .replace("feed_tph_min = 20.0", "feed_tph_min = 0.02")
             .replace("feed_tph_max = 45.0", "feed_tph_max = 0.045"))
    assert 'preset = "lab"' in scene
    res = run_scene(load_scene(write_scene(scene)), progress=False, plots=False)
    k = res.kpis
    assert 0.0062 <= k["start_feed_tph"] <= 0.062  # 0.2-2x the lab mill's 0.031 t/h
    assert k["start_p80_um"] == pytest.approx(210.0, rel=1e-3)


def test_a_start_target_no_feed_holds_is_refused_as_a_scene_problem_naming_its_keys(write_scene):
    """A target no feed rate holds at the start failed as a run error (exit 1) naming no key: it is
    the scene's problem (exit 2), and the message names the target, the speed and the way out."""
    scene = OPEN.replace("feed_tph = 30.0", 'feed_tph = 30.0\nstart = "target"').replace(
        "target_p80_um = 210.0", "target_p80_um = 20.0")
    assert "target_p80_um = 20.0" in scene
    with pytest.raises(SceneError) as info:
        run_scene(load_scene(write_scene(scene)), progress=False, plots=False)
    msg = str(info.value)
    assert "controller.target_p80_um = 20 um cannot be the start" in msg and "feed.speed_frac_critical = 0.7" in msg
    assert 'feed.start = "scene"' in msg


#: the reference scene's [controller] keys only its NMPC reads
NMPC_ONLY = ("horizon_steps", "move_block", "rk4_substeps", "preview_lead_h", "solver", "qpsol", "disturbance_model",
             "[controller.weights]", "p80 =", "du_feed", "du_speed", "energy", "speed_min", "speed_max", "speed_rate")
REFERENCE = (Path(__file__).resolve().parents[2] / "scenarios" / "reference_transition.toml").read_text(encoding="utf-8")


@pytest.mark.parametrize("kind", ["nmpc", "pi"])
def test_the_bounds_are_checked_against_the_feed_a_closed_loop_starts_at(write_scene, kind):
    """The scene's feed_tph (30 t/h) was checked against the bounds, while a closed loop starts at the feed that
    holds its target (23.6 t/h): bounds of [20, 28] were refused, and [25, 45] ran, its first move jumping
    1.4 t/h in one sample (27.6 t/h per h against a limit of 20), with a note on one row only."""
    from scenarios.run.preflight import check_scene

    assert "feed_tph_max = 45.0" in REFERENCE and "feed_tph_min = 20.0" in REFERENCE
    scene = REFERENCE.replace('kind = "nmpc"', f'kind = "{kind}"')
    if kind == "pi":  # the NMPC's keys and model, which a PI file is refused for (read by nothing)
        scene = "\n".join(line for line in scene.splitlines() if not line.startswith(NMPC_ONLY)) + "\n"
        for model in ("n_mixers = 3\n", "size_classes = { top_um = 6700.0, ratio = 2.5, count = 7 }\n",
                      "[effect_options.sensor_delay]\n"):
            assert model in scene
            scene = scene.replace(model, "", 1)
        scene = scene.replace("\ndead_time_h = 0.1", "\n", 1)
    assert check_scene(write_scene(scene.replace("feed_tph_max = 45.0", "feed_tph_max = 28.0"))) == []
    problems = check_scene(write_scene(scene.replace("feed_tph_min = 20.0", "feed_tph_min = 25.0")))
    assert len(problems) == 1 and re.search(
        r"controller.bounds: the closed loop starts at 23\.\d+ t/h, the feed rate that holds controller.target_p80_um "
        r"= 210 um .* outside the feed bounds \[25, 45\] t/h", problems[0]), problems
    # a start at the scene's own feed is checked with the scene, before any model is built
    at_feed = scene.replace('start = "target"', 'start = "scene"')
    assert check_scene(write_scene(at_feed)) == []
    assert any("feed.feed_tph: initial feed outside controller.bounds [20, 28]" in p for p in
               check_scene(write_scene(at_feed.replace("feed_tph_max = 45.0", "feed_tph_max = 28.0"))))


def test_an_nmpc_whose_model_knows_another_analyser_dead_time_says_so(write_scene):
    """sensors.p80_dead_time_h = 0.5 beside sensor_delay's 0.1 ran (IAE 5.40 against 2.81) with no word."""
    from scenarios.run.closed_loop import dead_time_notes

    assert "p80_dead_time_h = 0.1" in REFERENCE and "dead_time_h = 0.1  #" in REFERENCE
    assert dead_time_notes(load_scene(write_scene(REFERENCE))) == []
    slower = REFERENCE.replace("p80_dead_time_h = 0.1", "p80_dead_time_h = 0.5")
    assert dead_time_notes(load_scene(write_scene(slower))) == [
        "the controller's model assumes an analyser dead time of 0.1 h (effect_options.sensor_delay.dead_time_h), "
        "the analyser's is 0.5 h (sensors.p80_dead_time_h)"]
    unknown = REFERENCE.replace(', "sensor_delay"]', "]").replace("[effect_options.sensor_delay]\ndead_time_h = 0.1",
                                                                  "")
    assert "sensor_delay" not in unknown.split("[scene]")[0]
    assert dead_time_notes(load_scene(write_scene(unknown))) == [
        "the controller's model assumes an analyser dead time of 0 h (no sensor_delay effect), the analyser's is "
        "0.1 h (sensors.p80_dead_time_h)"]


def test_an_open_loop_without_a_steady_start_warns():
    """A scene whose own feed had no steady state started from a mill filled with feed, said in a note only;
    the screen showed its start_p80_um as a steady state's."""
    from types import SimpleNamespace

    from scenarios.run.open_loop import start_state
    from twin import SolverError

    def steady(**kwargs):
        raise SolverError("Newton failed")

    twin = SimpleNamespace(steady=steady, model=SimpleNamespace(initial_state=lambda blend: ["filled", *blend]))
    notes, warnings = [], []
    assert start_state(None, twin, (450.0, 0.74), [1.0], notes, warnings) == ["filled", 1.0]
    assert notes == [] and warnings == [
        "no steady state at the initial inputs (feed 450 t/h, speed 0.74): started from the mill filled to its "
        "nominal hold-up with feed, so start_p80_um is that fill's, not a steady state's (Newton failed)"]
