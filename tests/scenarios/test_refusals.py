"""Everything a run refuses, `grindtwin check` refuses first: one line per problem naming the file,
the key path, the value and what is allowed; and the run refuses the same before any work."""

from __future__ import annotations

import pytest

from tests.scenarios.test_cli import grindtwin
from tests.scenarios.test_runner import _controlled, short_pyrite_scene

PLANT_WITHOUT_TRANSPORT = '\n[plant]\nmodel = "twin"\neffects = ["breakage", "speed", "cushioning", "power"]\n'

# (id, controller kind or None, [(old, new) replacements], text appended, fragments of one message)
CASES = [
    ("mineral wt% NaN", None, [("quartz = 40.0\nk_feldspar", "quartz = nan\nk_feldspar")], "",
     ["ores.B_ref.mineralogy.quartz", "finite number", "nan"]),
    ("infinite weight", "nmpc", [], "\n[controller.weights]\np80 = inf\n",
     ["controller.weights.p80", "finite number", "inf"]),
    ("feed_tph_min = 0", "nmpc", [("feed_tph_min = 20.0", "feed_tph_min = 0.0")], "",
     ["controller.bounds.feed_tph_min", "greater than 0", "0.0"]),
    ("sqpmethod with hpipm", "nmpc", [("horizon_steps = 5", 'horizon_steps = 5\nsolver = "sqpmethod"\nqpsol = "hpipm"')],
     "", ["controller.qpsol", "'qrqp' with solver 'sqpmethod'", "'hpipm'"]),
    ("infinite target", "nmpc", [("target_p80_um = 250.0", "target_p80_um = inf")], "",
     ["controller.target_p80_um", "finite number", "inf"]),
    ("power model typo", None, [], '\n[effect_options.power]\nmodel = "bnd"\n',
     ["effect_options.power.model", "'bond'", "'bnd'", "Did you mean 'bond'"]),
    ("stages = 2.7", None, [('"classification"]', '"classification", "sensor_delay"]')], "\n[effect_options.sensor_delay]\nstages = 2.7\n",
     ["effect_options.sensor_delay.stages", "an integer in [1, 50]", "2.7"]),
    ("stages = 0", None, [('"classification"]', '"classification", "sensor_delay"]')], "\n[effect_options.sensor_delay]\nstages = 0\n",
     ["effect_options.sensor_delay.stages", "an integer in [1, 50]", "Got 0"]),
    ("dead time 0", None, [('"classification"]', '"classification", "sensor_delay"]')],
     "\n[effect_options.sensor_delay]\ndead_time_h = 0.0\n",
     ["effect_options.sensor_delay.dead_time_h", "a number in (0, 24)", "0.0"]),
    ("negative dead time", None, [('"classification"]', '"classification", "sensor_delay"]')],
     "\n[effect_options.sensor_delay]\ndead_time_h = -0.1\n",
     ["effect_options.sensor_delay.dead_time_h", "a number in (0, 24)", "-0.1"]),
    ("classification kind typo", None, [],  # the scene has classification
     '\n[effect_options.classification]\nkind = "grte"\n',
     ["effect_options.classification.kind", "'grate'", "'grte'", "Did you mean 'grate'"]),
    ("infinite duration", None, [("duration_h = 1.0", "duration_h = inf")], "",
     ["scene.duration_h", "finite number", "inf"]),
    ("plant without transport", None, [], PLANT_WITHOUT_TRANSPORT,
     ["plant.effects", "continuous mill", "not a batch grind", "add `transport`"]),
    ("feed in kg/h", None, [("feed_tph = 30.0", "feed_tph = 3000.0")], "",  # 3 t/h typed in kg/h
     ["feed.feed_tph", "more than 10 x the mill's nominal", "kg/h?", "3000"]),
]


def _scene(tmp_path, kind, replacements, append):
    path = short_pyrite_scene(tmp_path, duration_h=1.0)
    if kind is not None:
        _controlled(path, kind)
    text = path.read_text()
    for old, new in replacements:
        assert old in text, old
        text = text.replace(old, new, 1)
    path.write_text(text + append)
    return path


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_check_refuses_first_and_run_refuses_the_same(tmp_path, capsys, monkeypatch, case):
    _, kind, replacements, append, fragments = case
    path = _scene(tmp_path, kind, replacements, append)
    assert grindtwin(["check", path]) == 2
    err = capsys.readouterr().err
    assert any(all(f in line for f in fragments) and str(path) in line for line in err.splitlines()), err
    assert "Traceback" not in err

    import scenarios.run.runner as runner

    def no_integration(*args, **kwargs):
        raise AssertionError("the run started although the scene is refused")

    monkeypatch.setattr(runner, "run_open_loop", no_integration)
    monkeypatch.setattr(runner, "run_closed", no_integration)
    out = tmp_path / "out"
    assert grindtwin(["run", path, "--out", out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("grindtwin: error:") and fragments[0] in err and "Traceback" not in err
    assert not out.exists()


def test_a_controller_model_too_large_to_build_is_refused_with_its_size_and_the_fix(tmp_path, capsys):
    """hard_to_soft as it shipped: IPOPT, horizon 60, the full grid as the controller's model
    (std::bad_alloc after minutes, or the OOM killer at ~20 GB): refused at once."""
    path = _scene(tmp_path, "nmpc", [("n_mixers = 1\nsize_classes = { ratio = 2.0, count = 13 }", "n_mixers = 3"),
                                     ("horizon_steps = 5", 'horizon_steps = 60\nsolver = "ipopt"')], "")
    assert grindtwin(["check", path]) == 2
    err = capsys.readouterr().err
    for fragment in ("controller: the NMPC's model is too large to build", "150 states (2 ores x 3 mixers x 25 "
                     "size classes", "horizon 60", "GB, above the limit of 4 GB", "mill.size_classes",
                     "[plant]", 'controller.solver = "rti"'):
        assert fragment in err, err


@pytest.mark.parametrize("content,what", [(b"# caf\xe9\n", "byte 5 is 0xe9"),
                                          ("x = 1\n".encode("utf-16"), "it is UTF-16 text"),
                                          # no byte-order mark: valid UTF-8 (zero bytes), TOML failed at 1:2
                                          ("x = 1\n".encode("utf-16-le"), "it is UTF-16 or UTF-32 text"),
                                          # an executable was called UTF-16 text for its zero bytes
                                          (b"\x7fELF\x02\x01\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x03\x00>\x00"
                                           b"\x01\x00\x00\x00\xb0g", "it is a binary file, not text")])
def test_a_scene_file_that_is_not_utf8_is_refused_in_one_line(tmp_path, capsys, content, what):
    path = tmp_path / "scene.toml"
    path.write_bytes(content)
    for command in (["check", path], ["run", path, "--quiet"]):
        assert grindtwin(command) == 2
        err = capsys.readouterr().err
        assert "not UTF-8 text" in err and what in err and "Traceback" not in err
