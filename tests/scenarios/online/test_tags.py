"""Tag maps are validated as a whole like scenes: every problem at once, each naming the file,
the key path, the value and what is allowed; then checked against the scene and completed."""


import pytest

import scenarios.online as online
from scenarios.errors import SceneError
from scenarios.scene import load_scene

from .conftest import SMALL_TAGS


def _write(tmp_path, text):
    p = tmp_path / "tags.toml"
    p.write_text(text)
    return p


def test_the_shipped_virtual_plant_map_fits_the_reference_scene_and_takes_its_defaults():
    scene = load_scene("scenarios/reference_transition.toml")
    tags = online.load_tags(online.VIRTUAL_PLANT_TAGS, scene)
    # load's max age was omitted: three of the scene's 0.05 h samples
    assert tags.measurements.load_frac.max_age_h == pytest.approx(0.15)
    assert tags.belt_analyser.lead_h == 0.5 == scene.controller.preview_lead_h
    roles = tags.read_roles() | tags.write_roles()
    assert len(set(roles.values())) == len(roles)  # one node per role


def test_defaults_come_from_the_scene(tmp_path, small_scene):
    tags = online.load_tags(_write(tmp_path, SMALL_TAGS), small_scene)
    b = small_scene.controller.bounds
    sp = tags.setpoints.feed_tph
    assert (sp.min, sp.max, sp.rate_max_per_h) == (b.feed_tph_min, b.feed_tph_max, b.feed_rate_max_tph_per_h)
    assert tags.fallback.inputs_hold_after_h == pytest.approx(2 * small_scene.scene.sample_period_h)
    assert tags.belt_analyser.lead_h == small_scene.controller.preview_lead_h


def test_every_schema_problem_is_reported_with_file_key_value_and_allowed(tmp_path, small_scene):
    bad = SMALL_TAGS.replace('node = "ns=2;s=Mill.Power_kW"', 'node = "Mill.Power_kW"')
    bad = bad.replace("max_age_h = 0.15", "max_age_h = -1.0")
    bad = bad.replace("[mode]\n", "[mode]\nauto_valu = 1\n")
    with pytest.raises(online.TagMapError) as e:
        online.load_tags(_write(tmp_path, bad), small_scene)
    msg = str(e.value)
    assert "3 problems in the tag map" in msg
    assert "measurements.power_kw.node: String should match pattern" in msg and "'Mill.Power_kW'" in msg
    assert "measurements.p80_um.max_age_h: Input should be greater than 0 (got -1.0)" in msg
    assert "mode.auto_valu: unknown key 'auto_valu' (did you mean 'auto_value'?); allowed keys: auto_value, node" in msg
    assert msg.count(str(tmp_path / "tags.toml")) >= 4


def test_the_map_is_checked_against_the_scene(tmp_path, small_scene):
    bad = SMALL_TAGS.replace('D = "ns=2;s=Belt.D_frac"', 'C = "ns=2;s=Belt.D_frac"')
    bad = bad.replace("frozen_after_h = 0.2", "frozen_after_h = 0.05")
    bad = bad.replace('node = "ns=2;s=APC.Status"', 'node = "ns=2;s=APC.Heartbeat"')
    with pytest.raises(online.TagMapError) as e:
        online.load_tags(_write(tmp_path, bad), small_scene)
    msg = str(e.value)
    assert "belt_analyser.nodes: must name exactly the scene's ores ['B', 'D'] (got ['B', 'C'])" in msg
    assert "measurements.p80_um.frozen_after_h: must be longer than the analyser's sample period 0.05 h" in msg
    assert "status.node: node 'ns=2;s=APC.Heartbeat' is already the node of heartbeat.node" in msg


def test_set_point_limits_the_controller_cannot_keep_to_are_refused(tmp_path, small_scene):
    """A feed max of 10 t/h under controller bounds of 8-30 t/h (the issue: 20-45, the writer put 10 t/h
    on the plant in one cycle while the controller planned 23.6, exit 0); speed limits in percent
    (the writer wrote 60.0); a negative feed; a min above the scene's max once filled."""
    feed = 'node = "ns=2;s=Mill.Feed.Setpoint_tph"'
    speed = 'node = "ns=2;s=Mill.Speed.Setpoint_frac_critical"'
    cases = [(SMALL_TAGS.replace(feed, feed + "\nmax = 10.0"),
              "setpoints.feed_tph: limits [8, 10] must contain the controller's [8, 30] "
              "(controller.bounds.feed_tph_min, controller.bounds.feed_tph_max)"),
             (SMALL_TAGS.replace(speed, speed + "\nmin = 60.0\nmax = 85.0"),
              "setpoints.speed_frac_critical.min: must be in (0, 1) (a fraction of critical, not percent) (got 60.0)"),
             (SMALL_TAGS.replace(feed, feed + "\nmin = -5.0\nmax = 1e9"),
              "setpoints.feed_tph.min: must be >= 0 t/h (got -5.0)"),
             (SMALL_TAGS.replace(feed, feed + "\nmin = 60.0"),
              "setpoints.feed_tph: min must be below max once the scene's bounds fill the one not given (min 60.0, "
              "max 30.0)")]
    for text, message in cases:
        with pytest.raises(online.TagMapError) as e:
            online.load_tags(_write(tmp_path, text), small_scene)
        assert message in str(e.value), str(e.value)
    wider = online.load_tags(_write(tmp_path, SMALL_TAGS.replace(feed, feed + "\nmin = 0.0\nmax = 60.0")), small_scene)
    assert (wider.setpoints.feed_tph.min, wider.setpoints.feed_tph.max) == (0.0, 60.0)  # the DCS's wider limits


def test_a_missing_file_says_tag_map(tmp_path, small_scene):
    with pytest.raises(SceneError) as e:
        online.load_tags(tmp_path / "none.toml", small_scene)
    assert "tag map not found" in str(e.value)


def test_limits_follow_another_scene(tmp_path):
    """hard_to_soft has ores A and D, its own sample period and its own bounds."""
    scene = load_scene("scenarios/hard_to_soft.toml")
    tags = online.load_tags(_write(tmp_path, SMALL_TAGS.replace("B = ", "A = ")), scene)
    assert (tags.setpoints.feed_tph.min, tags.setpoints.feed_tph.max) == (15.0, 50.0)
    assert tags.measurements.power_kw.max_age_h == pytest.approx(3 * scene.scene.sample_period_h)  # 3 samples
    assert tags.measurements.p80_um.max_age_h == 0.15  # stated in the map


def test_a_cycle_trigger_must_be_a_measurement_the_map_reads(tmp_path, small_scene):
    no_power = SMALL_TAGS.replace('[measurements.power_kw]\nnode = "ns=2;s=Mill.Power_kW"\n', "")
    bad = no_power + '[cycle]\non_new = "power_kw"\n'
    with pytest.raises(online.TagMapError) as e:
        online.load_tags(_write(tmp_path, bad), small_scene)
    assert "cycle.on_new: names a measurement the map reads; [measurements.power_kw] has no node (got 'power_kw')" \
        in str(e.value)
    with pytest.raises(online.TagMapError) as e:
        online.load_tags(_write(tmp_path, SMALL_TAGS + '[cycle]\non_new = "belt"\ntimeout_samples = 1.0\n'), small_scene)
    assert "cycle.on_new" in str(e.value) and "cycle.timeout_samples" in str(e.value)
    ok = online.load_tags(_write(tmp_path, SMALL_TAGS + '[cycle]\non_new = "p80_um"\n'), small_scene)
    assert (ok.cycle.on_new, ok.cycle.timeout_samples) == ("p80_um", 1.5)


def test_each_measurement_gets_its_physical_range_from_the_scene(tmp_path, small_scene):
    from scenarios.online.tags import FEED_MAX_NOMINAL_MULTIPLE, blend_range, physical_range, plausible_range
    from scenarios.scene.physical import POWER_MAX_MODEL_MULTIPLE
    from scenarios.run.models import scene_mill

    tags = online.load_tags(_write(tmp_path, SMALL_TAGS), small_scene)
    got = {name: plausible_range(name, m, small_scene) for name, m in tags.measurements}
    assert got == {name: physical_range(name, small_scene) for name in got}  # nothing narrowed in the map
    top = small_scene.mill.size_classes.top_um
    from scenarios.scene.ranges import nominal_feed_tph

    nominal = nominal_feed_tph(small_scene.mill.preset, small_scene.mill.model_dump())  # the mill's, not feed.feed_tph
    assert str(got["p80_um"]) == f"[1, {top:g}) um"
    from twin import power_kw

    # the power meter: at most twice what the mill's power model draws at critical speed (a reading in W,
    # or with a digit too many, is Bad); it was unbounded
    most = POWER_MAX_MODEL_MULTIPLE * float(power_kw(scene_mill(small_scene), 1.0))
    assert str(got["power_kw"]) == f"[0, {most:g}] kW" and 1000.0 * 300.0 not in got["power_kw"]
    assert float(power_kw(scene_mill(small_scene), 0.7)) in got["power_kw"]  # its draw at the usual speed is
    from scenarios.scene.physical import load_max_frac

    mill = scene_mill(small_scene)  # the load meter reads hold-up over nominal: at most the mill filled to its shell
    full = mill.max_holdup_t(2.7) / mill.nominal_holdup_t(2.7)
    assert load_max_frac(small_scene) == pytest.approx(full, rel=1e-12) and 3.0 < full < 10.0
    assert str(got["load_frac"]) == f"[0, {full:g}] of the nominal hold-up" and 1.1 * full not in got["load_frac"]
    assert str(got["feed_tph"]) == f"[0, {FEED_MAX_NOMINAL_MULTIPLE * nominal:g}] t/h"
    assert str(got["speed_frac_critical"]) == "(0, 1) of critical"
    assert -5.0 not in got["p80_um"] and 1e6 not in got["p80_um"] and 210.0 in got["p80_um"]
    assert 3.0 not in got["speed_frac_critical"] and 0.0 in got["feed_tph"] and -0.1 not in got["feed_tph"]
    belt = blend_range(tags.belt_analyser)  # 1 + sum_tolerance: a larger fraction cannot sum to 1 with the others
    assert str(belt) == f"[0, {1 + tags.belt_analyser.sum_tolerance:g}] of the belt" and -0.01 not in belt


def test_a_map_may_narrow_a_plausible_range_but_not_widen_it(tmp_path, small_scene):
    from scenarios.online.tags import plausible_range

    p80 = '[measurements.p80_um]\nnode = "ns=2;s=Mill.Analyser.P80_um"\n'
    narrow = SMALL_TAGS.replace(p80, p80 + "plausible_min = 20\nplausible_max = 1000.0\n")
    tags = online.load_tags(_write(tmp_path, narrow), small_scene)
    r = plausible_range("p80_um", tags.measurements.p80_um, small_scene)
    assert str(r) == "[20, 1000] um" and 20.0 in r and 19.9 not in r and 1000.5 not in r

    wide = SMALL_TAGS.replace(p80, p80 + "plausible_min = -5.0\n")
    wide = wide.replace('node = "ns=2;s=Mill.Power_kW"', 'node = "ns=2;s=Mill.Power_kW"\nplausible_min = -10.0')
    wide = wide.replace('node = "ns=2;s=Mill.Speed.Actual_frac_critical"',
                        'node = "ns=2;s=Mill.Speed.Actual_frac_critical"\nplausible_min = 0.8\nplausible_max = 0.7')
    wide = wide.replace('node = "ns=2;s=Mill.Load_frac"', 'node = "ns=2;s=Mill.Load_frac"\nplausible_max = nan')
    with pytest.raises(online.TagMapError) as e:
        online.load_tags(_write(tmp_path, wide), small_scene)
    msg = str(e.value)
    assert "measurements.load_frac.plausible_max: Input should be a finite number (got nan)" in msg
    with pytest.raises(online.TagMapError) as e:
        online.load_tags(_write(tmp_path, wide.replace("plausible_max = nan", "")), small_scene)
    msg = str(e.value)
    assert "3 problems in the tag map" in msg
    assert ("measurements.p80_um.plausible_min: must lie in the physical range [1, 6700) um (a size of at least 1 "
            "um, as no mill's product is finer (mm? um expected), and below the top of the coarsest feed class: a "
            "mill only breaks); it may narrow it, not widen it (got -5.0)") in msg
    assert "measurements.power_kw.plausible_min: must lie in the physical range [0, " in msg
    assert "measurements.speed_frac_critical: plausible_min must be below plausible_max (got min 0.8, max 0.7)" in msg


def test_a_p80_in_mm_is_outside_the_physical_range_and_the_shipped_map_has_the_analysers_span(small_scene):
    """A P80 reported in mm (0.21) was judged Good (the physical range began at 0) and drove the feed to its
    bound; README showed the shipped map with the analyser's span, which the file did not have."""
    from pathlib import Path

    import scenarios.online as online
    from scenarios.online.tags import physical_range

    assert 0.21 not in physical_range("p80_um", small_scene) and 1.0 in physical_range("p80_um", small_scene)
    shipped = Path(online.__file__).parent / "data" / "virtual_plant_tags.toml"
    readme = (Path(__file__).resolve().parents[3] / "README.md").read_text(encoding="utf-8")
    text = shipped.read_text(encoding="utf-8")
    for line in ("plausible_min = 20.0", "plausible_max = 1000.0"):
        assert line in text and line in readme


def test_a_max_age_longer_than_the_horizon_is_refused_naming_field_value_and_limit(tmp_path, small_scene):
    """max_age_h had no upper bound: 1e6 h (or inf) passed, and a dead analyser or weightometer, its last value held
    with its old timestamp, was taken for a live one for ever (stale never came, so no fallback started). The small
    scene's NMPC plans 5 samples of 0.05 h: 0.25 h, above its default of 3 samples (0.15 h)."""
    horizon_h = 5 * 0.05
    assert small_scene.controller.horizon_steps * small_scene.scene.sample_period_h == pytest.approx(horizon_h)
    at = SMALL_TAGS.replace("max_age_h = 0.15", f"max_age_h = {horizon_h!r}")
    assert online.load_tags(_write(tmp_path, at), small_scene).measurements.p80_um.max_age_h == horizon_h
    bad = SMALL_TAGS.replace("max_age_h = 0.15", "max_age_h = 1e6").replace(
        '[measurements.feed_tph]\n', '[measurements.feed_tph]\nmax_age_h = 0.2501\n').replace(
        'D = "ns=2;s=Belt.D_frac" }\n', 'D = "ns=2;s=Belt.D_frac" }\nmax_age_h = inf\n')
    with pytest.raises(online.TagMapError) as e:
        online.load_tags(_write(tmp_path, bad), small_scene)
    msg = str(e.value)
    assert "3 problems in the tag map" in msg
    limit = "must be at most 0.25 h, the NMPC's horizon (5 samples of 0.05 h)"
    assert f"measurements.p80_um.max_age_h: {limit}" in msg and "(got 1000000.0)" in msg
    assert f"measurements.feed_tph.max_age_h: {limit}" in msg and "(got 0.2501)" in msg
    assert f"belt_analyser.max_age_h: {limit}" in msg and "(got inf)" in msg


def test_an_analyser_slower_than_the_horizon_keeps_its_default_max_age(tmp_path):
    """An analyser reporting every 0.1 h on a 0.25 h horizon: its default, three reports (0.3 h), is the limit."""
    from .conftest import SMALL_SCENE

    (tmp_path / "scene.toml").write_text(SMALL_SCENE.replace("p80_sample_period_h = 0.05", "p80_sample_period_h = 0.1"))
    scene = load_scene(tmp_path / "scene.toml")
    free = SMALL_TAGS.replace("max_age_h = 0.15\n", "")
    assert online.load_tags(_write(tmp_path, free), scene).measurements.p80_um.max_age_h == pytest.approx(0.3)
    with pytest.raises(online.TagMapError) as e:
        online.load_tags(_write(tmp_path, free.replace("frozen_after_h", "max_age_h = 0.31\nfrozen_after_h")), scene)
    assert "measurements.p80_um.max_age_h: must be at most 0.3 h, 3 of its source's 0.1 h periods, longer than the " \
           "NMPC's horizon 0.25 h" in str(e.value) and "(got 0.31)" in str(e.value)


def test_a_max_age_not_above_its_sources_period_is_refused(tmp_path, small_scene):
    """max_age_h had no lower bound: at 0.01 h on a 0.05-h sample a held reading turned stale between reports, so
    a live analyser and weightometer counted as dead and the fallbacks started. One period is refused too (a held
    value is up to a period old when the next one arrives); just above it passes."""
    bad = SMALL_TAGS.replace("max_age_h = 0.15", "max_age_h = 0.01").replace(
        '[measurements.feed_tph]\n', '[measurements.feed_tph]\nmax_age_h = 0.05\n')
    with pytest.raises(online.TagMapError) as e:
        online.load_tags(_write(tmp_path, bad), small_scene)
    msg = str(e.value)
    assert "2 problems in the tag map" in msg
    assert "measurements.p80_um.max_age_h: must be more than its source's period, 0.05 h" in msg and "(got 0.01)" in msg
    assert "measurements.feed_tph.max_age_h: must be more than its source's period, 0.05 h" in msg \
           and "(got 0.05)" in msg
    ok = SMALL_TAGS.replace("max_age_h = 0.15", "max_age_h = 0.051")
    assert online.load_tags(_write(tmp_path, ok), small_scene).measurements.p80_um.max_age_h == 0.051


def test_a_belt_lead_other_than_the_scenes_preview_is_said(tmp_path, small_scene, caplog):
    """A belt analyser's lead of 30 (minutes given as hours) was taken unsaid: the service took the belt's first
    reading as the mill's feed for 30 h. A lead other than the scene's preview is logged as the map is loaded; the
    scene's own lead (or none given) is not."""
    import logging

    def with_lead(lead: str):
        return _write(tmp_path, SMALL_TAGS.replace("[belt_analyser]\n", f"[belt_analyser]\nlead_h = {lead}\n"))

    with caplog.at_level(logging.WARNING, logger="grindtwin.online"):
        online.load_tags(_write(tmp_path, SMALL_TAGS), small_scene)
        online.load_tags(with_lead("0.25"), small_scene)
        assert caplog.records == []
        tags = online.load_tags(with_lead("30"), small_scene)
    assert tags.belt_analyser.lead_h == 30.0  # said, not refused: a belt may be that far from the mill
    assert [r.getMessage().split(": ", 1)[1] for r in caplog.records] == [
        "belt_analyser.lead_h 30 h differs from the scene's controller.preview_lead_h 0.25 h: the service takes the "
        "belt reading of 30 h before as the mill's feed now (the first reading until one is that old), where the "
        "scene's own runs preview the feed 0.25 h ahead"]
