"""A surveyed hydrocyclone: Plitt's factors from one survey (Flintoff, Plitt & Turak 1987), checked
against the survey itself, Plitt's exponents away from it and the Moly-Cop case's published survey."""

from __future__ import annotations

import copy
import tomllib
from dataclasses import replace
from pathlib import Path

import pytest

from scenarios.errors import SceneError
from scenarios.run.models import build_models
from scenarios.run.sweep import expand_cases
from scenarios.scene import read_toml, scene_from_dict
from twin.effects.classification import (KPA_PER_PSI, CycloneSurvey, Hydrocyclone, calibrate_plitt,
                                         hydrocyclone_from)
from twin.errors import TwinError

ROOT = Path(__file__).resolve().parents[2]
MOLYCOP = ROOT / "scenarios" / "molycop_ballsim.toml"
PUBLISHED = tomllib.loads((ROOT / "scenarios" / "data" / "molycop_ballsim_published.toml").read_text())
#: The Moly-Cop case's cluster: six 26-in cyclones (the shipped scene's geometry).
GEOMETRY = {k: v for k, v in read_toml(MOLYCOP)["effect_options"]["classification"]["cyclone"].items()
            if k in ("count", "diameter_cm", "inlet_cm", "vortex_finder_cm", "apex_cm", "free_vortex_height_cm")}
SURVEY = {"feed_solids_tph": PUBLISHED["cyclone_feed_solids_tph"],
          "feed_water_m3_h": PUBLISHED["cyclone_feed_water_m3_h"],
          "solids_density_t_m3": 2.8, "d50c_um": PUBLISHED["d50c_um"], "sharpness": PUBLISHED["plitt_sharpness"],
          "water_bypass_frac": PUBLISHED["water_bypass_frac"], "pressure_psi": PUBLISHED["cyclone_pressure_psi"]}


def surveyed(**extra) -> Hydrocyclone:
    return hydrocyclone_from({**GEOMETRY, **extra, "survey": dict(SURVEY)})


def test_the_calibrated_equations_give_the_survey_back_at_the_surveys_feed():
    s = CycloneSurvey(**SURVEY)
    got = surveyed().plitt(s.slurry_m3_h, s.solids_density_t_m3)
    assert got["d50c_um"] == pytest.approx(SURVEY["d50c_um"], rel=1e-12)
    assert float(got["sharpness_m"]) == pytest.approx(SURVEY["sharpness"], rel=1e-12)
    assert got["water_bypass_frac"] == pytest.approx(SURVEY["water_bypass_frac"], rel=1e-12)
    assert got["pressure_kpa"] == pytest.approx(SURVEY["pressure_psi"] * 6.894757, rel=1e-6)
    # uncalibrated, the same equations read another cyclone (the factors are not 1)
    plain = Hydrocyclone(**GEOMETRY, feed_solids_frac=s.feed_solids_frac).plitt(s.slurry_m3_h, 2.8)
    assert abs(plain["pressure_kpa"] / got["pressure_kpa"] - 1) > 0.5


def test_the_factors_do_not_depend_on_the_factors_the_cyclone_had_or_on_the_pressure_unit():
    s = CycloneSurvey(**SURVEY)
    a = calibrate_plitt(Hydrocyclone(**GEOMETRY), s)
    b = calibrate_plitt(Hydrocyclone(**GEOMETRY, d50c_factor=3.0, split_factor=0.2, sharpness_factor=5.0), s)
    in_kpa = {**SURVEY, "pressure_kpa": SURVEY["pressure_psi"] * KPA_PER_PSI}
    del in_kpa["pressure_psi"]
    c = calibrate_plitt(Hydrocyclone(**GEOMETRY), CycloneSurvey(**in_kpa))
    for f in ("d50c_factor", "pressure_factor", "split_factor", "sharpness_factor"):
        assert getattr(b, f) == pytest.approx(getattr(a, f), rel=1e-12)
        assert getattr(c, f) == pytest.approx(getattr(a, f), rel=1e-12)


def test_away_from_the_survey_the_cut_and_pressure_follow_plitts_exponents():
    """At 1.3x the survey's slurry flow and the same dilution: d50c ~ Q^-0.45, pressure ~ Q^1.78
    (Plitt 1976), whatever the factors."""
    s = CycloneSurvey(**SURVEY)
    cyc = surveyed()
    at, more = cyc.plitt(s.slurry_m3_h, 2.8), cyc.plitt(1.3 * s.slurry_m3_h, 2.8)
    assert more["d50c_um"] / at["d50c_um"] == pytest.approx(1.3 ** -0.45, rel=1e-12)
    assert more["pressure_kpa"] / at["pressure_kpa"] == pytest.approx(1.3 ** 1.78, rel=1e-12)


def test_a_surveyed_cyclone_keeps_the_surveys_dilution_unless_its_table_sets_one():
    s = CycloneSurvey(**SURVEY)
    assert surveyed().feed_solids_frac == pytest.approx(s.feed_solids_frac, rel=1e-15)
    assert surveyed(feed_solids_frac=0.55).feed_solids_frac == 0.55
    # the factors are the survey's either way: the dilution is where it runs, not what it was surveyed at
    assert surveyed(feed_solids_frac=0.55).d50c_factor == pytest.approx(surveyed().d50c_factor, rel=1e-12)


def _moly_steady(cyclone: dict):
    raw = read_toml(MOLYCOP)
    raw["effect_options"]["classification"]["cyclone"] = cyclone
    scene = scene_from_dict(raw, MOLYCOP)
    twin = build_models(scene).plant
    return twin, twin.steady(feed_tph=scene.feed.feed_tph, speed_frac_critical=scene.feed.speed_frac_critical)


def test_the_moly_cop_circuit_with_its_survey_runs_plitts_cut_at_its_own_cyclone_feed():
    """The circuit's cyclone feed is not the survey's (the twin's circulating load is its own), so
    its cut is the survey's moved by Plitt's flow exponent, at the survey's dilution."""
    twin, ss = _moly_steady({**GEOMETRY, "solids_bypass_frac": PUBLISHED["solids_bypass_frac"],
                             "survey": dict(SURVEY)})
    o = ss.outputs
    solids = (1.0 + o["circulating_load_frac"]) * o["throughput_tph"]
    flow_ratio = solids / SURVEY["feed_solids_tph"]  # same dilution: slurry flow in proportion to solids
    assert o["cyclone_feed_solids_frac"] == pytest.approx(CycloneSurvey(**SURVEY).feed_solids_frac, rel=1e-9)
    assert o["cyclone_d50c_um"] == pytest.approx(SURVEY["d50c_um"] * flow_ratio ** -0.45, rel=1e-6)
    assert o["cyclone_pressure_kpa"] == pytest.approx(SURVEY["pressure_psi"] * KPA_PER_PSI * flow_ratio ** 1.78,
                                                      rel=1e-6)
    assert abs(flow_ratio - 1.0) > 0.01  # the check above is not the survey point itself
    factors = surveyed()
    said = twin.model.describe()  # the model says which factors it runs
    assert f"Plitt factors pressure {factors.pressure_factor:.4g}, split {factors.split_factor:.4g}" in said
    assert f"d50c {factors.d50c_factor:.4g})" in said


@pytest.mark.parametrize("cyclone,fragment", [
    ({**GEOMETRY, "d50c_factor": 0.8, "survey": SURVEY}, "'d50c_factor' and 'survey' are given together"),
    ({**GEOMETRY, "d50c_um": 180.0, "survey": SURVEY}, "'d50c_um' and 'survey' are given together"),
    ({**GEOMETRY, "survey": {**SURVEY, "d50_um": 1.0}}, "Unknown field 'd50_um' of the 'survey'"),
    ({**GEOMETRY, "survey": {**SURVEY, "pressure_kpa": 53.0}}, "'pressure_psi' instead, not both"),
    ({**GEOMETRY, "survey": {k: v for k, v in SURVEY.items() if k != "pressure_psi"}},
     "'pressure_kpa' parameter of CycloneSurvey must be given"),
    ({**GEOMETRY, "survey": {**SURVEY, "water_bypass_frac": 1.2}}, "'water_bypass_frac' parameter of CycloneSurvey"),
    ({**GEOMETRY, "survey": {**SURVEY, "solids_density_t_m3": 0.9}}, "'solids_density_t_m3'"),
    ({**GEOMETRY, "survey": 183.3}, "'survey' of the 'cyclone' option of effect 'classification' must be a table"),
    ({**{k: v for k, v in GEOMETRY.items() if k != "count"}, "survey": SURVEY},
     "a cyclone with a 'survey' needs its 'count'"),
])
def test_a_bad_survey_is_refused_naming_the_field(cyclone, fragment):
    with pytest.raises(TwinError) as info:
        hydrocyclone_from(copy.deepcopy(cyclone))
    assert fragment in str(info.value)


def test_a_sweep_may_vary_a_survey_field_and_names_a_misspelt_one():
    raw = read_toml(MOLYCOP)
    cyc = raw["effect_options"]["classification"]["cyclone"]
    for k in ("d50c_um", "sharpness", "water_bypass_frac"):
        cyc.pop(k)
    cyc["survey"] = dict(SURVEY)
    key = "effect_options.classification.cyclone.survey.d50c_um"
    cases = expand_cases(raw, {key: [170.0, 190.0]})
    assert [c.data["effect_options"]["classification"]["cyclone"]["survey"]["d50c_um"] for c in cases] == [170, 190]
    with pytest.raises(SceneError, match="'d50_um' is not a key of effect_options.classification.cyclone.survey "
                                         r"\(did you mean 'd50c_um'\?\)"):
        expand_cases(raw, {key.replace("d50c", "d50"): [170.0]})


def test_the_survey_file_values_are_the_shipped_scenes_direct_classifier():
    """The Moly-Cop scene gives the classifier directly from the same published numbers."""
    cyc = read_toml(MOLYCOP)["effect_options"]["classification"]["cyclone"]
    s = CycloneSurvey(**SURVEY)
    assert (cyc["d50c_um"], cyc["sharpness"], cyc["water_bypass_frac"]) == (
        s.d50c_um, s.sharpness, s.water_bypass_frac)
    assert cyc["feed_solids_frac"] == pytest.approx(s.feed_solids_frac, rel=1e-9)
    assert replace(s, pressure_psi=None, pressure_kpa=1.0).kpa == 1.0


def test_steady_scene_gives_the_factors_its_survey_made(tmp_path, capsys):
    """The factors are the survey's calibration, computed, not typed: steady --scene shows them
    (JSON and text); a cyclone given directly has none to show."""
    import json

    from scenarios.cli import main

    text = MOLYCOP.read_text()
    for line in ("d50c_um = 183.3\n", "sharpness = 1.34\n", "water_bypass_frac = 0.375\n"):
        assert text.count(line) == 1
        text = text.replace(line, "")
    text = text.replace("feed_solids_frac = 0.6123861331", "# feed_solids_frac")
    text += "\n[effect_options.classification.cyclone.survey]\n" + "".join(
        f"{k} = {v!r}\n" for k, v in SURVEY.items())
    scene = tmp_path / "surveyed.toml"
    scene.write_text(text)
    assert main(["steady", "--scene", str(scene), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)["cyclone_plitt_factors"]
    expected = surveyed()
    assert got == {f: pytest.approx(getattr(expected, f), rel=1e-12) for f in got}
    assert sorted(got) == ["d50c_factor", "pressure_factor", "sharpness_factor", "split_factor"]
    assert main(["steady", "--scene", str(scene)]) == 0
    assert f"cyclone_plitt_factors        pressure {expected.pressure_factor:.4g}, split" in capsys.readouterr().out
    assert main(["steady", "--scene", str(MOLYCOP), "--json"]) == 0
    assert "cyclone_plitt_factors" not in json.loads(capsys.readouterr().out)
