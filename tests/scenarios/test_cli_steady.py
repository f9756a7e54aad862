"""`grindtwin steady` end to end, through the console entry point's main()."""

import json
import re

import pytest

from scenarios.cli import main
from tests.conftest import strict_json

from .conftest import BASE_SCENE


def test_steady_json_has_unit_suffixed_kpis(capsys):
    assert main(["steady", "--ore", "B", "--feed-tph", "0.031", "--speed", "0.70", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert 150 < out["p80_um"] < 300 and 5 < out["specific_energy_kwh_t"] < 20
    assert out["throughput_tph"] == pytest.approx(0.031, rel=1e-6)
    assert out["load_status"] in ("under", "stable", "over")
    assert out["mineralogy"]["B"]["wt_pct"]["quartz"] == pytest.approx(40.0)


def test_steady_blend_at_constant_load(capsys):
    assert main(["steady", "--blend", "B=0.6,D=0.4", "--at-constant-load", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["load_frac"] == pytest.approx(1.0, abs=1e-6)
    assert set(out["blend"]) == {"B", "D"}


def test_steady_ore_from_toml(tmp_path, capsys):
    ore = tmp_path / "quartzite.toml"
    ore.write_text("[mineralogy]\nquartz = 90.0\nk_feldspar = 10.0\n[texture]\nmean_grain_um = 300.0\n"
                   "uniformity = 0.6\nassociation_entropy = 0.5\n")
    assert main(["steady", "--ore", str(ore), "--feed-tph", "0.03", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["mineralogy"]["quartzite"]["hardness_index_gpa"] > 10


@pytest.mark.parametrize("argv, message", [
    (["steady", "--speed", "1.3"], "--speed must be in (0, 1). Got 1.3."),
    (["steady", "--feed-tph", "-1"], "--feed-tph must be in [0, 100000). Got -1."),
    # the twin's own range (it passed the parser at 1e5, and the twin's refusal named no option)
    (["steady", "--feed-tph", "100000"], "--feed-tph must be in [0, 100000). Got 100000."),
    (["steady", "--ore", "E"], "must be a reference type (A, B, C, D)"),
    (["steady", "--blend", "B=0.6,D=0.3"], "--blend B=0.6,D=0.3: Blend fractions must sum to 1"),
    (["steady", "--ore", "A", "--blend", "B=0.6,D=0.4"], "--ore A and --blend B=0.6,D=0.4: give one"),
    (["optimize", "--ore", "A", "--blend", "B=0.6,D=0.4", "--target-p80-um", "210"],
     "--ore A and --blend B=0.6,D=0.4: give one"),
    (["steady", "--scene", "scenarios/molycop_ballsim.toml", "--ore", "A"], "--ore do not apply"),
    (["steady", "--scene", "scenarios/molycop_ballsim.toml", "--mill", "lab", "--blend", "B=1"],
     "--blend, --mill do not apply"),
    # a bare --uncertainty (all replicates) is 0: it printed the scene's steady state without the intervals asked for
    (["steady", "--scene", "scenarios/molycop_ballsim.toml", "--uncertainty"], "--uncertainty do not apply"),
])
def test_bad_arguments_give_one_line_and_exit_2(argv, message, capsys):
    with pytest.raises(SystemExit) as exc:
        code = main(argv)
        raise SystemExit(code)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


def test_steady_from_surrogate_is_close_to_the_twin(capsys):
    assert main(["steady", "--ore", "C", "--feed-tph", "0.035", "--speed", "0.72", "--json"]) == 0
    twin = json.loads(capsys.readouterr().out)
    assert main(["steady", "--ore", "C", "--feed-tph", "0.035", "--speed", "0.72", "--json", "--surrogate"]) == 0
    sur = json.loads(capsys.readouterr().out)
    assert (twin["source"], sur["source"]) == ("twin", "surrogate")
    assert sur["p80_um"] == pytest.approx(twin["p80_um"], rel=0.05)
    assert sur["specific_energy_kwh_t"] == pytest.approx(twin["specific_energy_kwh_t"], rel=0.03)


def test_zero_feed_reports_specific_energy_as_undefined(capsys):
    """Energy per tonne fed has no value without feed: null with a note, never the model's
    1e7 kWh/t from its division floor."""
    assert main(["steady", "--ore", "B", "--feed-tph", "0", "--json", "--uncertainty", "20"]) == 0
    out = strict_json(capsys.readouterr().out)  # strict JSON: no NaN
    assert out["specific_energy_kwh_t"] is None and out["power_kw"] > 0
    assert out["p80_um"] is None  # no product, no P80
    assert any(n.startswith("p80_um, specific_energy_kwh_t, ")
               and n.endswith(" undefined (NaN): no feed: the steady mill is empty and makes no product")
               for n in out["notes"])
    assert not any("is undefined at" in n for n in out["notes"])  # said once, by the steady state
    assert out["uncertainty"]["intervals"]["specific_energy_kwh_t"] is None
    # the intervals were read as prediction intervals: B's measured 12.8 kWh/t lies outside its [13.10, 13.12]
    assert any(n.startswith("the 90% intervals carry the DEM particles' scatter only") for n in out["notes"])
    assert main(["steady", "--ore", "B", "--feed-tph", "0", "--uncertainty", "20"]) == 0
    text = capsys.readouterr().out
    assert "specific_energy_kwh_t    undefined" in text and "e+0" not in text
    assert "specific_energy_kwh_t  undefined" in text  # the interval line too


def test_scene_steady_at_zero_feed_says_undefined(capsys):
    """The --scene path applies the same rules: no 1e6 kWh/t floor, no NaN in the JSON."""
    from pathlib import Path

    scene = str(Path(__file__).resolve().parents[2] / "scenarios" / "pyrite_surge.toml")
    assert main(["steady", "--scene", scene, "--feed-tph", "0", "--json"]) == 0
    out = strict_json(capsys.readouterr().out)
    assert out["specific_energy_kwh_t"] is None and out["p80_um"] is None
    assert sum("specific_energy_kwh_t" in n for n in out["notes"]) == 1
    assert any(n.endswith("undefined (NaN): no feed: the steady mill is empty and makes no product")
               for n in out["notes"])


def test_a_hold_up_beyond_the_mills_volume_is_said(capsys):
    """5 t/h into the 0.031-t/h laboratory mill: the model's steady state holds far more ore than
    the mill, filled to its shell, could (5.6x nominal): a note says so; none at the nominal feed."""
    from twin import Twin

    lab = Twin("B")
    capacity = lab.mill.max_holdup_t(lab.spec.solids_density_t_m3)
    m = lab.mill  # full over nominal: (1 - J (1 - eps)) / (U eps J), Austin's U, bed porosity, ball filling
    j, eps, u = m.ball_filling_frac, m.bed_porosity, m.powder_filling_nominal
    assert capacity / lab.spec.holdup_nominal_t == pytest.approx((1 - j * (1 - eps)) / (u * eps * j), rel=1e-9)
    assert main(["steady", "--ore", "B", "--feed-tph", "5", "--json", "--allow-overflow"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["holdup_t"] > capacity and any("overflow" in n for n in out["notes"])
    assert main(["steady", "--ore", "B", "--feed-tph", "0.031", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["notes"] == []


def test_a_steady_state_beyond_the_mills_volume_is_refused_with_the_feed_that_fills_it(capsys):
    """Without --allow-overflow, 5 t/h into the laboratory mill is bad input (exit 2, nothing on
    stdout): the error names the argument, its value and the feed that fills the mill to its
    shell, which the twin confirms: its steady state there holds the shell's hold-up, and a feed
    just below it is answered without a note."""
    from twin import Twin

    assert main(["steady", "--ore", "B", "--feed-tph", "5", "--json"]) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    m = re.search(r"--feed-tph 5 t/h: .* hold ([0-9.e+]+) t .* filled to its shell \(([0-9.e+-]+) t\).* feeds up to "
                  r"([0-9.e+-]+) t/h", cap.err)
    assert m, cap.err
    lab = Twin("B")
    capacity = lab.mill.max_holdup_t(lab.spec.solids_density_t_m3)
    assert float(m.group(2)) == pytest.approx(capacity, rel=1e-3)
    assert float(m.group(1)) > capacity
    full_tph = float(m.group(3))
    assert lab.steady(feed_tph=full_tph).summary()["holdup_t"] == pytest.approx(capacity, rel=2e-3)
    assert main(["steady", "--ore", "B", "--feed-tph", f"{0.99 * full_tph}", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["notes"] == []
    assert main(["steady", "--ore", "B", "--feed-tph", f"{1.02 * full_tph}", "--json"]) == 2


def test_the_industrial_mill_says_it_runs_its_grate_not_its_sized_circuit(capsys):
    assert main(["steady", "--ore", "B", "--mill", "industrial", "--feed-tph", "31", "--json"]) == 0
    assert any("hydrocyclone" in n for n in json.loads(capsys.readouterr().out)["notes"])


def test_the_scene_path_refuses_an_overflowing_steady_state_too(capsys):
    """--scene: a --feed-tph beyond the mill's shell is refused naming the argument (the scene's
    own feed rate is its mill's nominal feed, so it holds the nominal hold-up); --allow-overflow
    answers with the note."""
    from pathlib import Path

    scene = str(Path(__file__).resolve().parents[2] / "scenarios" / "pyrite_surge.toml")
    assert main(["steady", "--scene", scene, "--feed-tph", "200", "--json"]) == 2
    assert "--feed-tph 200 t/h:" in capsys.readouterr().err
    assert main(["steady", "--scene", scene, "--feed-tph", "200", "--json", "--allow-overflow"]) == 0
    assert any("overflow" in n for n in json.loads(capsys.readouterr().out)["notes"])


def test_a_speed_where_the_charge_centrifuges_is_said(capsys):
    """Beyond the midpoint of Austin's speed-factor falloff (eq. 8.4: its logistic term is 1/2
    there) the charge centrifuges and the power models do not know it: a note; none at 0.94."""
    from twin import CENTRIFUGING_FRAC_CRITICAL
    from twin.breakage import austin_speed_factor

    c = CENTRIFUGING_FRAC_CRITICAL
    assert float(austin_speed_factor(c)) == pytest.approx((c - 0.1) / 2, rel=1e-12)
    assert main(["steady", "--ore", "B", "--feed-tph", "0.031", "--speed", "0.96", "--json"]) == 0
    assert any("centrifuges" in n for n in json.loads(capsys.readouterr().out)["notes"])
    assert main(["steady", "--ore", "B", "--feed-tph", "0.031", "--speed", f"{c}", "--json"]) == 0
    assert not any("centrifuges" in n for n in json.loads(capsys.readouterr().out)["notes"])


def test_a_slurry_past_jamming_is_said(capsys, clay_ore):
    """An ore of 90 % kaolinite puts the mill slurry past jamming (phi_v (1 + k w_clay) above
    random close packing) at this calibration's clay crowding: a note naming both fractions;
    none for ore D, the deposit's clay-rich type."""
    from twin import Twin
    from twin.effects.rheology import JAMMING_VOL_FRAC, SLURRY_SOLIDS_VOL_FRAC, jamming_clay_frac

    k = Twin("B").spec.coefficients["clay_crowding_coeff"]
    limit = jamming_clay_frac(k)
    assert SLURRY_SOLIDS_VOL_FRAC * (1 + k * limit) == pytest.approx(JAMMING_VOL_FRAC, rel=1e-12)
    assert main(["steady", "--ore", str(clay_ore), "--feed-tph", "0.031", "--json"]) == 0
    jam = [n for n in json.loads(capsys.readouterr().out)["notes"] if "jams" in n]
    assert len(jam) == 1 and f"past the {limit:.0%} at which it jams" in jam[0] and "holds 90% clay" in jam[0]
    assert main(["steady", "--ore", "D", "--feed-tph", "0.031", "--json"]) == 0
    assert not any("jams" in n for n in json.loads(capsys.readouterr().out)["notes"])



def test_steady_says_the_dem_calibration_does_not_read_texture(tmp_path, capsys):
    """Two ores that differ only in grain size (10 vs 1000 um) give one P80 under the dem
    calibration, whose map reads hardness, modulus and density; steady printed their textural
    indices and said nothing. The table calibration maps texture: different P80s, no such note."""
    b = {"mineralogy": {"quartz": 40.0, "k_feldspar": 12.0, "plagioclase": 6.0, "biotite": 18.0, "chlorite": 2.0,
                        "kaolinite": 4.0, "illite": 3.0, "pyrite": 11.0, "chalcopyrite": 4.0}}
    paths = []
    for g in (10, 1000):
        (tmp_path / f"g{g}").mkdir()
        p = tmp_path / f"g{g}" / "ore.toml"
        p.write_text("[mineralogy]\n" + "".join(f"{k} = {v}\n" for k, v in b["mineralogy"].items())
                     + f"[texture]\nmean_grain_um = {g}.0\nuniformity = 0.6\nassociation_entropy = 0.55\n")
        paths.append(p)
    p80 = {}
    for cal in ("dem", "table"):
        for p in paths:
            assert main(["steady", "--ore", str(p), "--feed-tph", "0.031", "--speed", "0.7", "--json",
                         "--calibration", cal]) == 0
            out = json.loads(capsys.readouterr().out)
            p80[cal, p.parent.name] = out["p80_um"]
            assert any("not its texture" in n for n in out["notes"]) == (cal == "dem")
    assert p80["dem", "g10"] == p80["dem", "g1000"] and p80["table", "g10"] != p80["table", "g1000"]
    # optimize and a scene's run say it too (the note is the twin's: every steady state carries it);
    # a reference ore does not get it
    assert main(["optimize", "--ore", str(paths[0]), "--target-p80-um", "150", "--json"]) in (0, 1)
    assert any("not its texture" in n for n in json.loads(capsys.readouterr().out)["notes"])
    assert main(["optimize", "--ore", "B", "--target-p80-um", "150", "--json"]) in (0, 1)
    assert not any("texture" in n for n in json.loads(capsys.readouterr().out)["notes"])
    from scenarios.run.models import build_models
    from scenarios.scene.loader import load_scene

    scene = tmp_path / "user_ore.toml"
    mineral = ", ".join(f"{k} = {v}" for k, v in b["mineralogy"].items())
    user = (f"[ores.B]\nmineralogy = {{ {mineral} }}\n"
            "texture = { mean_grain_um = 10.0, uniformity = 0.6, association_entropy = 0.55 }")
    scene.write_text(BASE_SCENE.replace('[ores.B]\ntype = "B"', user))
    assert any("ore B, not its texture" in n for n in build_models(load_scene(scene)).notes)


def test_an_ore_beyond_the_calibrations_fitted_ores_is_said_to_be_extrapolated(tmp_path, capsys):
    """95 % quartz: its energy group Pi (the dem map's input) and its hardness index (the table
    map's) lie above the reference ores' the calibrations were fitted on, and steady said nothing.
    The fitted ores themselves and a blend of them get no such note."""
    import math

    from twin import load_ore, reference_ores
    from twin.calibration import load_calibration
    from twin.calibration.strength import energy_group

    ore = tmp_path / "quartzite.toml"
    ore.write_text("[mineralogy]\nquartz = 95.0\npyrite = 5.0\n[texture]\nmean_grain_um = 300.0\n"
                   "uniformity = 0.6\nassociation_entropy = 0.5\n")
    law = load_calibration("dem").record["law"]
    pi = energy_group(load_ore(str(ore)), law["reference"])
    top = max(math.exp(v) for v in law["ln_energy_group"].values())
    assert pi > top  # the independent check of what the note must say
    assert main(["steady", "--ore", str(ore), "--feed-tph", "0.031", "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert [n for n in notes if f"energy group Pi {pi:.3g} lies outside the" in n and f"-{top:.3g} of the ores the "
            "dem calibration was fitted on (A, B, C, D)" in n and "extrapolation" in n]
    hard = max(o.hardness_index_gpa for o in reference_ores().values())
    assert main(["steady", "--ore", str(ore), "--feed-tph", "0.031", "--json", "--calibration", "table"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert [n for n in notes if "hardness index 12 GPa lies outside" in n and f"-{hard:.3g} GPa" in n]
    for cal in ("dem", "table"):
        for argv in (["--ore", "A"], ["--ore", "D"], ["--blend", "A=0.5,D=0.5"]):
            assert main(["steady", *argv, "--feed-tph", "0.031", "--json", "--calibration", cal]) == 0
            assert not [n for n in json.loads(capsys.readouterr().out)["notes"] if "extrapolation" in n], (cal, argv)


def test_a_speed_where_the_breakage_stops_is_refused_before_solving(capsys):
    """0.001 of critical failed in the solver with "tighten the tolerances", which the command has
    no option for: below 0.1 of critical Austin's speed factor, and so every breakage rate, is
    negative. Refused with the allowed range, exit 2, on every path that solves a steady state."""
    from pathlib import Path

    from twin import SPEED_FACTOR_ZERO_FRAC_CRITICAL as SPEED_MIN_FRAC_CRITICAL
    from twin.breakage import austin_speed_factor

    assert austin_speed_factor(SPEED_MIN_FRAC_CRITICAL) == pytest.approx(0.0, abs=1e-12)  # the model's own zero
    assert austin_speed_factor(SPEED_MIN_FRAC_CRITICAL - 0.01) < 0 < austin_speed_factor(SPEED_MIN_FRAC_CRITICAL + 0.01)
    scene = str(Path(__file__).resolve().parents[2] / "scenarios" / "pyrite_surge.toml")
    for argv in (["--ore", "B", "--feed-tph", "0.031", "--speed", "0.001"],
                 ["--ore", "B", "--at-constant-load", "--speed", "0.05"],
                 ["--scene", scene, "--speed", "0.1"]):
        assert main(["steady", *argv]) == 2, argv
        captured = capsys.readouterr()
        speed = argv[-1]
        assert f"--speed {speed}: at or below 0.1 of critical speed" in captured.err
        assert "allowed: a speed in (0.1, 1) of critical" in captured.err
        assert "tolerances" not in captured.err and captured.out == ""
    assert main(["steady", "--ore", "B", "--mill", "industrial", "--speed", "0.11", "--json"]) == 0  # just above
    assert json.loads(capsys.readouterr().out)["speed_frac_critical"] == pytest.approx(0.11)


def test_a_speed_where_the_breakage_stops_is_refused_by_the_twin_and_by_check(tmp_path, capsys):
    """The limit lives with the twin: Twin refuses such a speed with the speed effect (it tried to
    solve), and `check` refuses a scene that holds or may plan one (it said OK and the run failed
    in the solver). Without the speed effect the breakage does not follow the speed: allowed."""
    from tests.scenarios.conftest import BASE_SCENE
    from twin import Twin, TwinInputError

    with pytest.raises(TwinInputError, match=r"'speed_frac_critical'.*\(0.1, 1\) with the speed effect"):
        Twin("B").steady(feed_tph=0.031, speed_frac_critical=0.05)
    assert Twin("B", effects=["breakage", "transport", "holdup"]).steady(
        feed_tph=0.031, speed_frac_critical=0.05).p80_um > 0
    slow = tmp_path / "slow.toml"
    slow.write_text(BASE_SCENE.replace('effects = ["breakage", "transport", "holdup", "cushioning", "power"]',
                                       'effects = ["breakage", "transport", "holdup", "speed", "cushioning", "power"]')
                    .replace("speed_frac_critical = 0.70", "speed_frac_critical = 0.08")
                    .replace("feed_tph_max = 45.0", "feed_tph_max = 45.0\nspeed_min = 0.05"))
    assert main(["check", str(slow)]) == 2
    err = capsys.readouterr().err
    assert "feed.speed_frac_critical: 0.08 is at or below 0.1 of critical" in err
    assert "controller.bounds.speed_min: 0.05 is at or below 0.1 of critical" in err


def test_min_replicates_leaves_one_replicate_beyond_each_end(monkeypatch):
    """The rule is the library's: steady_intervals refuses too few replicates before solving
    (the CLI refused them, the API computed a one-replicate '90 % interval')."""
    import twin.calibration.uncertainty as uncertainty
    from twin import TwinInputError
    from twin.calibration import load_calibration, min_replicates, steady_intervals

    assert [min_replicates(level) for level in (0.8, 0.9, 0.95)] == [10, 20, 40]
    monkeypatch.setattr(uncertainty, "replicate_steady_states", lambda *a, **k: pytest.fail("solved"))
    with pytest.raises(TwinInputError, match=r"'n' parameter of steady_intervals must be .* at least 20.*Got 5"):
        steady_intervals(["B"], load_calibration(), feed_tph=0.031, n=5)


@pytest.mark.parametrize("argv, message", [
    (["--uncertainty", "1"], "--uncertainty 1: a 90% interval needs at least 20 bootstrap replicates"),
    (["--uncertainty", "19"], "give --uncertainty 20 or more, or 0 for all 100"),
    (["--calibration", "table", "--uncertainty"], "keeps 0 converged bootstrap replicates; a 90% interval needs at "
                                                  "least 20"),
])
def test_too_few_replicates_for_an_interval_are_refused_before_solving(argv, message, capsys):
    """--uncertainty 1 printed a "90 % interval" of one replicate, [x, x]."""
    assert main(["steady", "--ore", "B", *argv]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and captured.out == ""


def test_intervals_left_with_too_few_solved_replicates_are_undefined(monkeypatch, capsys):
    """20 replicates asked, 15 steady states failed: the 5 left make no 90 % interval."""
    import twin.calibration

    def five_left(*args, **kwargs):
        return {"intervals": {"p80_um": (200.0, 201.0, 202.0)}, "n": 5, "failed": 15, "unconverged": 0,
                "level": 0.9}

    monkeypatch.setattr(twin.calibration, "steady_intervals", five_left)
    assert main(["steady", "--ore", "B", "--uncertainty", "20", "--json"]) == 0
    out = strict_json(capsys.readouterr().out)
    assert out["uncertainty"]["intervals"] == {"p80_um": None}
    assert "the 90% intervals are undefined: the steady state solved for 5 replicates, fewer than the 20 an " \
           "interval needs" in out["notes"]


def test_steady_of_a_scene_says_what_its_speed_and_start_do_not_move(capsys):
    """The Moly-Cop scene has no `speed` effect: its P80 was the same to 7 digits at 0.5 and 0.8 of
    critical, its kWh/t not, and nothing said why. The reference scene starts its runs at the target's
    steady state (feed.start = "target"), not at the feed.feed_tph `steady --scene` answers for."""
    from pathlib import Path

    lib = Path(__file__).parents[2] / "scenarios"
    outs = []
    for speed in ("0.5", "0.8"):
        assert main(["steady", "--scene", str(lib / "molycop_ballsim.toml"), "--speed", speed, "--json"]) == 0
        outs.append(json.loads(capsys.readouterr().out))
    assert outs[0]["p80_um"] == pytest.approx(outs[1]["p80_um"], rel=1e-9)
    assert outs[0]["specific_energy_kwh_t"] < 0.8 * outs[1]["specific_energy_kwh_t"]
    assert any("no `speed` effect: its breakage rates are those of the nominal speed" in n for n in outs[0]["notes"])
    assert main(["steady", "--scene", str(lib / "reference_transition.toml"), "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert any('feed.start = "target"' in n for n in notes)
    assert not any("no `speed` effect" in n for n in notes)


def test_the_surrogate_says_it_answers_a_blend_as_one_ore(capsys):
    """Its P80 for A=B=C=D=0.25 was coarser than every pure ore's, with no word of why."""
    assert main(["steady", "--blend", "A=0.5,C=0.5", "--surrogate", "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert any("answers a blend as one ore of the blend's mean mineralogy and texture" in n for n in notes)
    assert main(["steady", "--ore", "A", "--surrogate", "--json"]) == 0
    assert not any("answers a blend" in n for n in json.loads(capsys.readouterr().out)["notes"])


def test_the_surrogate_on_a_mill_it_was_not_trained_on_names_the_option(capsys):
    # the error named "the 'mill' of surrogate_steady", a parameter the user never saw
    assert main(["steady", "--ore", "B", "--mill", "industrial", "--surrogate"]) == 2
    err = capsys.readouterr().err
    assert "--mill industrial: the surrogate was trained on the 'lab' mill only; drop --surrogate" in err
    assert "surrogate_steady" not in err


def test_an_overflow_at_a_slow_speed_names_the_feed_the_user_did_not_give(capsys):
    """`steady --speed 0.2` overflows the laboratory mill at its nominal feed; the error blamed
    "--feed-tph 0.031 t/h", an option never typed."""
    assert main(["steady", "--ore", "B", "--speed", "0.2"]) == 2
    err = capsys.readouterr().err
    assert "the mill's nominal feed (no --feed-tph given) 0.031 t/h: at 0.2 of critical speed" in err
    assert "--feed-tph 0.031" not in err


def test_a_feed_the_mill_overloads_at_is_bad_input(tmp_path, capsys):
    """500 t/h into the sized industrial cyclone circuit: no steady state, the mill overloading
    (103 t against a shell's 15.5 t) was exit 1, "steady failed"; README has a feed that would
    overflow the mill as bad input (exit 2), as the overflowing steady state already was."""
    text = BASE_SCENE.replace('"cushioning", "power"]', '"cushioning", "power", "classification"]')
    text += '\n[effect_options.classification]\nkind = "hydrocyclone"\n'
    path = tmp_path / "cyclones.toml"
    path.write_text(text)
    assert main(["steady", "--scene", str(path), "--feed-tph", "500"]) == 2
    err = capsys.readouterr().err
    assert "--feed-tph 500 t/h: Steady state not found" in err and "The mill overloads" in err
    assert "steady failed" not in err


THIRDS_SCENE = """\
effects = ["breakage", "transport", "holdup", "speed", "cushioning", "rheology", "power", "classification"]

[scene]
name = "thirds"
duration_h = 1.0
sample_period_h = 0.25

[mill]
preset = "lab"

[ores.A]
type = "A"

[ores.B]
type = "B"

[ores.C]
type = "C"

[feed]
blend = { A = 0.333, B = 0.333, C = 0.333 }
feed_tph = 0.031  # the lab mill's nominal feed, which the CLI's twin keeps
speed_frac_critical = 0.70
"""


def test_a_blend_typed_to_three_decimals_gives_one_answer_from_the_cli_and_from_a_scene(tmp_path, capsys):
    """--blend A=0.333,B=0.333,C=0.333 was refused (the twin's 1e-6) where a scene took the same blend (1e-3) and
    rescaled it; both now take it and rescale it to sum to 1: the same steady state."""
    scene = tmp_path / "thirds.toml"
    scene.write_text(THIRDS_SCENE + '\n[controller]\nkind = "none"\n', encoding="utf-8")
    assert main(["steady", "--scene", str(scene), "--json"]) == 0
    of_scene = strict_json(capsys.readouterr().out)
    assert main(["steady", "--blend", "A=0.333,B=0.333,C=0.333", "--feed-tph", "0.031", "--speed", "0.70",
                 "--json"]) == 0
    of_cli = strict_json(capsys.readouterr().out)
    assert of_cli["blend"] == pytest.approx({k: 1 / 3 for k in "ABC"}, rel=1e-15)
    for key in ("p80_um", "power_kw", "specific_energy_kwh_t", "load_frac", "holdup_t", "throughput_tph"):
        assert of_cli[key] == pytest.approx(of_scene[key], rel=1e-12, abs=0), key
