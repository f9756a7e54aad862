"""size_mill and `grindtwin size-mill`: trials outside the models, misses that name their cause,
where a preset may be written, and what a design point at another speed cannot show."""

import json
import math

import numpy as np
import pytest

from twin.errors import SolverError


def test_a_trial_cyclone_outside_the_models_is_a_miss_not_an_input_error():
    """At 3000 t/h the first guess of one cyclone is 15 m tall: Hydrocyclone's TwinInputError
    (a 'free_vortex_height_cm' the user never gave) ended the whole sizing; it is a miss of that
    count, and the next count is tried."""
    from twin.calibration import load_calibration
    from twin.effects.classification import Hydrocyclone
    from twin.mill import INDUSTRIAL_BASE
    from twin.sizing import _DesignPoint

    point = _DesignPoint("B", INDUSTRIAL_BASE, Hydrocyclone(), 1, 3000.0, 100.0, 0.7, load_calibration(None), 53.0,
                         "direct")
    with pytest.raises(SolverError, match=r"a trial of 2e\+03-cm cyclones and a 10-m mill, outside what the models"):
        point(np.array([math.log(10.0), math.log(2000.0), 4.0]))
    with pytest.raises(SolverError, match=r"a 25-m mill, outside what the models take"):
        point(np.array([math.log(25.0), math.log(50.0), 4.0]))


def test_a_mill_outside_its_sizes_is_named_and_no_pressure_is_advised():
    """Lab scale, 30 kg/h: the design point's mill is 0.34 m, below the sizes allowed, and its
    cyclones are under 1 cm. Only the cyclones were named, with advice to change their pressure,
    which cannot move the mill."""
    from twin.sizing import size_mill

    with pytest.raises(SolverError) as err:
        size_mill("B", 0.03, 210.0)
    text = str(err.value)
    assert "cyclones of 0.846 cm, outside" in text and "a 0.342-m mill, outside 0.8-8 m" in text
    assert "another design pressure" not in text and "neither the cyclones nor their pressure" in text


def test_a_feed_no_mill_takes_is_refused_before_sizing():
    """31,000 t/h (kg/h typed as t/h) ran every cyclone count and failed blaming the cyclones' pressure."""
    from twin import TwinInputError
    from twin.mill import INDUSTRIAL_BASE
    from twin.sizing import DIAMETER_RANGE_M, FIRST_GUESS_DIAMETER_MAX_FACTOR, size_mill

    guess = INDUSTRIAL_BASE.diameter_m * (31000.0 / INDUSTRIAL_BASE.feed_nominal_tph) ** (1.0 / 3.5)
    assert guess > FIRST_GUESS_DIAMETER_MAX_FACTOR * DIAMETER_RANGE_M[1]
    with pytest.raises(TwinInputError, match=r"'feed_tph' parameter of size_mill is 31000 t/h: .* one mill would be "
                                             rf"about {guess:.3g} m across, and ball mills are made up to 8 m"):
        size_mill("B", 31000.0, 210.0)


def test_a_preset_is_never_written_into_grindtwins_packages(tmp_path, monkeypatch):
    """A new file in twin/data, or in scenarios/, passed (any existing folder did): the preset was
    written into the installed package. The shipped industrial preset is written only in a checkout
    of the repository. A path under a file is named as such (it said the folder does not exist)."""
    import twin.sizing as sizing
    from twin.errors import TwinInputError
    from twin.mill import INDUSTRIAL_PRESET_PATH

    package = INDUSTRIAL_PRESET_PATH.parent
    for path in (package / "mine.json", package.parents[1] / "scenarios" / "mine.json"):
        with pytest.raises(TwinInputError, match=r"Refusing to write the preset .*mine.json inside grindtwin's"):
            sizing.check_preset_path(path)
        assert not path.exists()
    assert sizing.check_preset_path(INDUSTRIAL_PRESET_PATH) == INDUSTRIAL_PRESET_PATH  # this checkout's
    monkeypatch.setattr(sizing, "is_grindtwin_checkout", lambda root: False)
    with pytest.raises(TwinInputError, match="rewritten only in a checkout of the grindtwin repository"):
        sizing.check_preset_path(INDUSTRIAL_PRESET_PATH)
    (tmp_path / "afile").write_text("x")
    with pytest.raises(TwinInputError, match="afile/p.json is a file"):
        sizing.check_preset_path(tmp_path / "afile" / "p.json")


def test_a_design_at_another_speed_than_the_calibrated_mills_follows_austins_speed_factor():
    """--speed 0.9 gave the diameter sized at 0.7 (the scale-up cancelled a mill's own nominal speed
    out of its rates) with a note saying so. Austin's scale-up carries his speed factor: at 0.9 a
    mill breaks f(0.9)/f(0.7) = 0.89 as fast (past the factor's peak), so it is sized larger, and no
    note excuses it."""
    from twin.mill import get_mill
    from twin.sizing import size_mill

    sized = size_mill("B", 31.0, 210.0, speed_frac_critical=0.9)
    assert sized.mill.diameter_m > 1.02 * get_mill("industrial").diameter_m
    assert not any("of critical, not the calibrated mill's" in n for n in sized.notes)


def test_size_mill_json_with_a_preset_is_json_and_its_command_sizes_the_same_design(tmp_path, capsys, monkeypatch):
    """--json --write-preset printed 'wrote PATH' before the JSON (stdout no longer parsed); the
    recorded command rounded --feed-tph 31.1234567 to 31.1235 (%g) and left an ore path with a
    space unquoted; a preset replaced was not said."""
    import shlex

    import twin
    from scenarios.cli import main
    from twin.effects.classification import Hydrocyclone
    from twin.mill import INDUSTRIAL_BASE
    from twin.sizing import CIRCUIT_KEYS, similar_cyclone

    sized = twin.SizedMill(INDUSTRIAL_BASE, similar_cyclone(Hydrocyclone(), 25.0, 3, 40.0), "B", 31.1234567, 210.0,
                           210.0, 2.5, 200.0, 7.0, 0.99, "stable", circuit={k: 1.0 for k in CIRCUIT_KEYS})
    monkeypatch.setattr(twin, "size_mill", lambda *a, **k: sized)
    ore = tmp_path / "my ores" / "b.toml"
    ore.parent.mkdir()
    ore.write_text("[mineralogy]\nquartz = 100.0\n[texture]\nmean_grain_um = 125.0\nuniformity = 0.6\n"
                   "association_entropy = 0.55\n")
    preset = tmp_path / "p.json"
    argv = ["size-mill", "--ore", str(ore), "--feed-tph", "31.1234567", "--target-p80-um", "210", "--json",
            "--write-preset", str(preset)]
    for replaced in (False, True):
        assert main(argv) == 0
        out, err = capsys.readouterr()
        command = shlex.split(json.loads(out)["command"])
        assert command[command.index("--feed-tph") + 1] == "31.1234567"
        assert command[command.index("--ore") + 1] == str(ore)
        assert err.startswith(f"wrote {preset}") and ("replacing the preset it held" in err) == replaced
    assert shlex.split(json.loads(preset.read_text())["command"])[-1] == str(preset)


def test_an_empty_preset_path_is_refused_before_sizing(capsys, monkeypatch):
    """--write-preset '' (an unset shell variable) wrote nothing and said nothing, exit 0."""
    import twin
    from scenarios.cli import main

    monkeypatch.setattr(twin, "size_mill", lambda *a, **k: pytest.fail("sized although the output is refused"))
    assert main(["size-mill", "--feed-tph", "31", "--target-p80-um", "210", "--write-preset", ""]) == 2
    assert "The preset output path is empty ('')" in capsys.readouterr().err


def test_a_sized_mill_run_under_another_calibration_says_so():
    """The industrial preset was sized under the dem calibration (B to 210 um at 31 t/h); under the table
    calibration B at 25 t/h grinds to ~330 um against ~222, and nothing said that the mill's sizing does not hold.
    A twin under another calibration than its mill was sized with says which; under the same, nothing; the
    laboratory mill (not sized) never."""
    from twin import Twin

    def sized_notes(calibration, mill="industrial"):
        return [n for n in Twin("B", mill=mill, calibration=calibration).notes if "was sized under" in n]

    assert sized_notes("dem") == [] and sized_notes("table", mill="lab") == []
    (note,) = sized_notes("table")
    assert note.startswith("mill 'industrial' was sized under calibration 'dem'; this twin runs calibration 'table'")
