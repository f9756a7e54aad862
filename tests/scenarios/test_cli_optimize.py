"""`grindtwin optimize`: set points that hold a target P80, with the alternatives."""

import json

import pytest

from scenarios.cli import main
from tests.conftest import strict_json


def test_optimize_holds_the_target_at_least_energy(capsys):
    assert main(["optimize", "--blend", "B=0.6,D=0.4", "--mill", "industrial", "--target-p80-um", "210",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["feasible"] and out["p80_um"] == pytest.approx(210.0, abs=0.5)
    both = [r for r in out["table"] if r["option"] == "both" and r["feasible"]]
    assert out["specific_energy_kwh_t"] == pytest.approx(min(r["specific_energy_kwh_t"] for r in both), rel=1e-6)
    assert 0.8 <= out["load_frac"] <= 1.2
    assert any("hydrocyclone" in n for n in out["notes"])  # the preset's sized circuit is not what ran
    # the constraints the answer sits on, as the table's row of the answer says (it was in the table alone)
    answer = min(both, key=lambda r: abs(r["specific_energy_kwh_t"] - out["specific_energy_kwh_t"]))
    assert "active" in out and out["active"] == answer["active"]


def test_unreachable_target_is_reported_with_exit_1(capsys):
    assert main(["optimize", "--ore", "A", "--target-p80-um", "20"]) == 1
    assert "no feasible answer" in capsys.readouterr().out


def test_unreachable_target_in_json_is_strict_json_with_nulls(capsys):
    assert main(["optimize", "--ore", "A", "--target-p80-um", "20", "--json"]) == 1
    out = strict_json(capsys.readouterr().out)  # no NaN
    assert not out["feasible"] and out["feed_tph"] is None and out["p80_um"] is None



def test_an_answer_whose_slurry_jams_is_said(capsys, clay_ore):
    """optimize's answer for a 90 % kaolinite ore lies past the slurry's jamming: a note (the
    steady state at the answer, as steady would say it); none for ore B."""
    assert main(["optimize", "--ore", str(clay_ore), "--target-p80-um", "150", "--json"]) == 0
    assert any("jams" in n for n in json.loads(capsys.readouterr().out)["notes"])
    assert main(["optimize", "--ore", "B", "--target-p80-um", "150", "--json"]) == 0
    assert not any("jams" in n for n in json.loads(capsys.readouterr().out)["notes"])


def test_an_objective_with_one_input_is_refused(capsys):
    """--mode feed --objective max_throughput was ignored (one input, one answer) and the JSON said
    max_throughput; refused before any work."""
    assert main(["optimize", "--target-p80-um", "210", "--mode", "feed", "--objective", "max_throughput"]) == 2
    assert "--objective max_throughput: with --mode feed" in capsys.readouterr().err
