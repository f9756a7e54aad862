"""Scene files are validated as a whole; each broken file gets a message naming file, key
path, value and what is allowed."""

from __future__ import annotations

from pathlib import Path

import pytest

from twin import get_mill, power_kw

from scenarios.errors import SceneError
from scenarios.scene.loader import check_scene, load_scene
from tests.scenarios.conftest import BASE_SCENE

LIBRARY = sorted((Path(__file__).parents[2] / "scenarios").glob("*.toml"))


def edit(old: str, new: str) -> str:
    assert old in BASE_SCENE, old
    return BASE_SCENE.replace(old, new, 1)


# (id, broken scene text, fragments that one message must contain)
BROKEN = [
    ("wrong type", edit("feed_tph = 30.0", 'feed_tph = "thirty"'),
     ["feed.feed_tph", "valid number", "'thirty'"]),
    ("out of range", edit("speed_frac_critical = 0.70", "speed_frac_critical = 1.3"),
     ["feed.speed_frac_critical", "less than 1", "1.3"]),
    ("unknown key, close match", edit("duration_h = 8.0", "duraton_h = 8.0"),
     ["scene.duraton_h", "unknown key", "did you mean 'duration_h'"]),
    ("misspelt word", edit('preset = "industrial"', 'preset = "industral"'),
     ["mill.preset", "'lab', 'industrial' or a preset file", "did you mean 'industrial'", "'industral'"]),
    ("unknown effect", edit('"cushioning"', '"cushoning"'),
     ["effects[3]", "Unknown effect", "Did you mean 'cushioning'", "'cushoning'"]),
    ("unknown ore", edit("blend = { B = 0.6, D = 0.4 }", "blend = { B = 0.6, E = 0.4 }"),
     ["feed.schedule[0].blend.E", "not defined in [ores]", "'E'"]),
    ("blend sum", edit("blend = { B = 0.6, D = 0.4 }", "blend = { B = 0.6, D = 0.3 }"),
     ["feed.schedule[0].blend", "sum to 1 within 0.001", "0.9"]),
    ("schedule out of order", BASE_SCENE + "\n[[feed.schedule]]\nat_h = 1.5\nblend = { B = 1.0 }\n",
     ["feed.schedule[1].at_h", "increasing time", "1.5"]),
    ("schedule beyond duration", edit("at_h = 2.0", "at_h = 7.5"),
     ["feed.schedule[0].at_h", "after scene.duration_h = 8", "7.5"]),
    ("missing required", edit("speed_frac_critical = 0.70\n", ""),
     ["feed.speed_frac_critical", "required key is missing"]),
    ("bad history path", edit('[[feed.schedule]]\nat_h = 2.0\nkind = "ramp"\nramp_h = 1.0\n'
                              "blend = { B = 0.6, D = 0.4 }\n", "").replace(
        "blend = { B = 1.0 }\n", 'history = "no_such_day.csv"\n'),
     ["feed.history", "file not found", "no_such_day.csv"]),
    ("bounds reversed", edit("feed_tph_min = 20.0", "feed_tph_min = 50.0"),
     ["controller.bounds.feed_tph_max", "above feed_tph_min = 50", "45"]),
    ("controller without target", edit("target_p80_um = 210.0\n", ""),
     ["controller.target_p80_um", "required when kind = 'nmpc'"]),
    ("options for an effect not used", BASE_SCENE + '\n[effect_options.classification]\nkind = "grate"\n',
     ["effect_options.classification", "which is not in the list", "Add it to the effects or remove"]),
    ("unknown mineral", edit('[ores.D]\ntype = "D"',
                             "[ores.D.mineralogy]\nquartz = 60.0\npyrit = 40.0\n"
                             "[ores.D.texture]\nmean_grain_um = 50.0\nuniformity = 0.4\n"
                             "association_entropy = 0.8"),
     ["ores.D.mineralogy.pyrit", "unknown mineral", "did you mean 'pyrite'"]),
    # an empty mineralogy failed later without the file or the key; fractions got no hint of their unit
    ("empty mineralogy", edit('[ores.D]\ntype = "D"', "[ores.D]\nmineralogy = {}\n"
                              "texture = { mean_grain_um = 50.0, uniformity = 0.4, association_entropy = 0.8 }"),
     ["ores.D.mineralogy", "wt% must sum to 100 within 0.5", "got 0.0"]),
    ("mineralogy in mass fractions", edit('[ores.D]\ntype = "D"', "[ores.D]\nmineralogy = { quartz = 0.6, "
                                          "calcite = 0.4 }\ntexture = { mean_grain_um = 50.0, uniformity = 0.4, "
                                          "association_entropy = 0.8 }"),
     ["ores.D.mineralogy", "mass fractions summing to 1? give wt%: x 100", "got 1.0"]),
    # a bulk density (broken ore with its voids) held 1.75 x the solids' volume: P80 a quarter of the ore's, exit 0
    ("bulk density of a type", edit('[ores.D]\ntype = "D"', '[ores.D]\ntype = "D"\ndensity_t_m3 = 1.6'),
     ["ores.D.density_t_m3", "lies between 2.56 (k_feldspar) and 5.01 t/m3 (pyrite), within 10%", "got 1.6"]),
    ("type and mineralogy both", edit('[ores.D]\ntype = "D"', '[ores.D]\ntype = "D"\n'
                                      "mineralogy = { quartz = 100.0 }"),
     ["ores.D", "either `type` or an explicit mineralogy"]),
    ("batch scene with a feed rate", edit('"transport", "holdup", ', "").replace(
        'kind = "nmpc"', 'kind = "none"'),
     ["feed.feed_tph", "batch scene", "batch_charge_kg"]),
    ("batch scene with a schedule", edit('"transport", "holdup", ', "").replace('kind = "nmpc"', 'kind = "none"')
     .replace("feed_tph = 30.0", "batch_charge_kg = 12.0"),
     ["feed.schedule", "batch scene", "grinds one charge of feed.blend", "not used"]),
    # a batch run gave no analyser column and said nothing of the [sensors] it was given
    ("batch scene with sensors", edit('"transport", "holdup", ', "").replace('kind = "nmpc"', 'kind = "none"')
     .replace("feed_tph = 30.0", "batch_charge_kg = 12.0").replace("[[feed.schedule]]", "[sensors]\n"
     "p80_noise_um = 5.0\n\n[[feed.schedule]]"),
     ["sensors: read by nothing: a batch scene (effects without `transport`) has no analyser"]),
    ("not TOML", BASE_SCENE + "\n[feed\n", ["not valid TOML"]),
    ("top-level key inside a table", BASE_SCENE + '\nseed = 3\neffects = ["breakage"]\n',
     ["controller.bounds.effects", "'effects' is a top-level key", "before the first [table]"]),
    ("plant model with effects", BASE_SCENE + '\n[plant]\nmodel = "leroux2013"\n'
     'effects = ["breakage"]\n', ["plant.effects", "not used with model = \"leroux2013\""]),
    ("le Roux plant not run by scenes", BASE_SCENE + '\n[plant]\nmodel = "leroux2013"\n',
     ["plant.model", "not run by scenes yet", "mpc_leroux_case.py", "leroux2013"]),
    ("ball size in metres", edit('preset = "industrial"', 'preset = "industrial"\nball_size_mm = 0.025'),
     ["mill.ball_size_mm", "greater than or equal to 10", "0.025"]),
    ("integer expected", edit('name = "base"', 'name = "base"\nseed = 1.5'),
     ["scene.seed", "valid integer", "1.5"]),
    ("too many samples", edit("sample_period_h = 0.25", "sample_period_h = 5e-8"),  # it took 18 GB unchecked
     ["scene", "160,000,000 samples", "at most 2,108,160", "sample_period_h = 5e-08"]),
]


@pytest.mark.parametrize("text,fragments", [b[1:] for b in BROKEN], ids=[b[0] for b in BROKEN])
def test_broken_scene_names_file_path_value_and_rule(write_scene, text, fragments):
    path = write_scene(text, name="broken.toml")
    messages = check_scene(path)
    assert messages, "a broken scene must not pass"
    assert all(str(path) in m for m in messages)
    matching = [m for m in messages if all(f in m for f in fragments)]
    assert matching, f"no message contains {fragments}; got:\n" + "\n".join(messages)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert all(m in str(info.value) for m in messages)


def test_every_error_of_a_file_is_reported_at_once(write_scene):
    text = (edit("feed_tph = 30.0", "feed_tph = -1.0")
            .replace("duration_h = 8.0", "duraton_h = 8.0")
            .replace('"cushioning"', '"cushoning"')
            .replace("feed_tph_min = 20.0", "feed_tph_min = 50.0"))
    messages = check_scene(write_scene(text))
    for path in ("feed.feed_tph", "scene.duraton_h", "scene.duration_h", "effects[3]",
                 "controller.bounds.feed_tph_max"):
        assert any(f": {path}:" in m for m in messages), (path, messages)


def test_a_horizon_below_one_is_one_error_not_also_the_move_blocks(write_scene):
    messages = check_scene(write_scene(BASE_SCENE.replace('target_p80_um = 210.0', 'target_p80_um = 210.0\n'
                                                                                   'horizon_steps = 0')))
    assert any("controller.horizon_steps" in m for m in messages), messages
    assert not any("move_block" in m for m in messages), messages
    messages = check_scene(write_scene(BASE_SCENE.replace('target_p80_um = 210.0', 'target_p80_um = 210.0\n'
                                                                                   'horizon_steps = 3')))
    assert any("controller.move_block: must not exceed horizon_steps = 3 (got 5)" in m for m in messages), messages


def test_base_scene_is_valid_and_defaults_are_filled_visibly(write_scene):
    scene = load_scene(write_scene())
    assert scene.source_path.name == "scene.toml"
    preset = get_mill("industrial")  # the sized preset's file, not the base mill's dimensions
    assert (scene.mill.diameter_m, scene.mill.length_m, scene.mill.n_mixers) == (preset.diameter_m, preset.length_m, 3)
    assert scene.feed.p80_um == 3200.0
    assert scene.sensors.p80_sample_period_h == scene.scene.sample_period_h
    assert scene.controller.bounds.speed_max == 0.85


def test_blend_within_tolerance_is_rescaled_to_exactly_one(write_scene):
    scene = load_scene(write_scene(edit("blend = { B = 0.6, D = 0.4 }",
                                        "blend = { B = 0.6, D = 0.3995 }")))
    assert sum(scene.feed.schedule[0].blend.values()) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize("path", LIBRARY, ids=[p.stem for p in LIBRARY])
def test_library_scene_is_valid(path):
    assert check_scene(path) == []


def test_library_has_the_scenes_of_the_issue():
    names = {p.stem for p in LIBRARY}
    assert {"reference_transition", "hard_to_soft", "pyrite_surge", "replay_day"} <= names
    assert len([n for n in names if n.startswith("batch_")]) == 3


def test_batch_scenes_have_no_transport_and_reference_scene_previews():
    for path in LIBRARY:
        scene = load_scene(path)
        if path.stem.startswith("batch_"):
            assert "transport" not in scene.effects and scene.feed.batch_charge_kg > 0
    ref = load_scene(LIBRARY[[p.stem for p in LIBRARY].index("reference_transition")])
    assert ref.controller.kind == "nmpc" and ref.controller.target_p80_um == 210.0
    assert ref.controller.preview_lead_h == 0.5
    assert ref.feed.schedule[-1].blend == {"B": 0.6, "D": 0.4}


def test_pyrite_surge_differs_from_type_b_by_fifteen_points_of_pyrite_for_biotite():
    scene = load_scene(Path(__file__).parents[2] / "scenarios" / "pyrite_surge.toml")
    ref, surge = scene.ores["B_ref"].mineralogy, scene.ores["B_pyrite"].mineralogy
    diff = {m: surge[m] - ref[m] for m in ref if surge[m] != ref[m]}
    assert diff == {"pyrite": 15.0, "biotite": -15.0}


def test_effect_requirements_come_from_the_twin_registry(write_scene):
    messages = check_scene(write_scene(edit('"transport", ', "")))
    assert any("effects[1]" in m and "'holdup' requires effect 'transport'" in m
               for m in messages), messages


def test_unknown_effect_option_names_the_allowed_ones(write_scene):
    from twin import EFFECTS

    allowed = list(EFFECTS["classification"].options)
    text = edit('"power"]', '"power", "classification"]') + \
        '\n[effect_options.classification]\nknd = "grate"\n'
    messages = check_scene(write_scene(text))
    assert any("effect_options.classification.knd" in m and "Did you mean 'kind'" in m
               and ", ".join(allowed) in m for m in messages), messages


def test_the_feed_check_judges_against_the_scenes_own_mill(write_scene):
    """The kg/h-for-t/h check scales the preset's nominal feed by the power of the mill the scene
    describes: a mill twice the preset's diameter and length draws 2^3.5 ~ 11x the power (Bond,
    P ~ D^2.5 L at a given filling and speed), so 10 x the preset's nominal feed is a plausible
    rate for it, while a mill of a third the size cannot take the preset's own feed x 10."""
    base = get_mill("industrial")
    big = f"preset = \"industrial\"\ndiameter_m = {2 * base.diameter_m}\nlength_m = {2 * base.length_m}"
    small = f"preset = \"industrial\"\ndiameter_m = {base.diameter_m / 3}\nlength_m = {base.length_m / 3}"
    ratio_big = power_kw(base.with_(diameter_m=2 * base.diameter_m, length_m=2 * base.length_m), 0.7) / power_kw(base, 0.7)
    assert 2 ** 3.2 < ratio_big < 2 ** 3.6  # Bond's D^2.3-2.5 L, and nothing else, sets the scale
    feed = 10.5 * base.feed_nominal_tph
    text = edit('preset = "industrial"', big).replace("feed_tph = 30.0", f"feed_tph = {feed}", 1)
    assert not [m for m in check_scene(write_scene(text, name="big.toml")) if "nominal" in m]
    text = edit('preset = "industrial"', small)
    assert feed / 10.5 * 10 > 30.0  # the preset's own limit would let 30 t/h through
    messages = [m for m in check_scene(write_scene(text, name="small.toml")) if "feed.feed_tph" in m]
    assert messages and "more than 10 x the mill's nominal" in messages[0], messages


def test_a_controllers_lowest_feed_below_a_feed_stop_is_refused(write_scene):
    """A controller whose feed_tph_min lay below 5 % of the mill's nominal feed could cut the feed to a level the
    KPIs take for a feed stop and leave out of its P80 IAE: refused, naming the limit; just above 5 % passes, and
    a scene without a controller is not judged."""
    nominal = get_mill("industrial").feed_nominal_tph
    low = edit("feed_tph_min = 20.0", "feed_tph_min = 0.5")
    messages = [m for m in check_scene(write_scene(low, name="low.toml")) if "feed_tph_min" in m]
    assert len(messages) == 1 and f"must be at least {0.05 * nominal:.4g} t/h, 5% of the mill's nominal" in messages[0]
    assert "0.5" in messages[0]
    above = edit("feed_tph_min = 20.0", f"feed_tph_min = {1.001 * 0.05 * nominal!r}")  # the nominal at round-off
    assert not [m for m in check_scene(write_scene(above, name="above.toml")) if "feed_tph_min" in m]
    open_loop = low.replace('kind = "nmpc"', 'kind = "none"')
    messages = [m for m in check_scene(write_scene(open_loop, name="open.toml")) if "feed_tph_min" in m]
    assert len(messages) == 1 and "feed_tph_min: read by nothing" in messages[0], messages  # not the feed stop's


def test_an_nmpc_power_limit_the_mill_cannot_meet_or_never_reaches_is_refused(write_scene):
    """The ball charge draws the mill's power whatever the feed (Bond 1961): a limit in MW (0.2 for 200 kW) held
    the NMPC at its lowest speed and feed with P80 off target, one in W (200000) ran as none, both silently.
    Refused beyond a factor 2 of the mill's power at the speed bounds, naming the unit; limits near the draw pass."""
    mill = get_mill("industrial")
    low, high = float(power_kw(mill, 0.60)), float(power_kw(mill, 0.85))  # the schema's default speed bounds

    def limit(kw, extra=""):
        text = edit('target_p80_um = 210.0', f'target_p80_um = 210.0\npower_max_kw = {kw!r}') + extra
        return [m for m in check_scene(write_scene(text, name="limit.toml")) if "power_max_kw" in m]

    mw, watts = limit(low / 1000.0), limit(high * 1000.0)
    assert len(mw) == 1 and "MW? kW expected" in mw[0] and "speed_min 0.6" in mw[0], mw
    assert len(watts) == 1 and "W? kW expected" in watts[0] and "never binds" in watts[0], watts
    assert not limit(0.9 * low) and not limit(1.2 * high)  # a limit that binds at some speed within the bounds
    # a power model the scene names draws less: the limit is judged by the least of them
    hf = float(power_kw(mill.with_(power_model="hogg_fuerstenau"), 0.60))
    assert hf < low and limit(0.45 * low)
    assert not limit(0.45 * low, '\n[effect_options.power]\nmodel = "hogg_fuerstenau"\n') and 0.45 * low > hf / 2
