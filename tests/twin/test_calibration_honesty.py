"""A calibration's numbers are fitted by its command, each named with its range and why it is
fitted; nothing in the file is typed in by hand; and it is not run silently with another mill,
grid or DEM than it records (helper 37's audit; the other refusals are in
test_calibration_audit.py, test_calibration_consistency.py and test_calibration_model_code.py)."""

from __future__ import annotations

import json

import pytest

from twin import SizeGrid, Twin, TwinInputError, get_mill
from twin.calibration import DEM_FITTED, DEM_NAMES, load_calibration
from twin.calibration import table as table_map
from twin.calibration.model_code import dem_step_digest
from twin.mill import LAB


def _copy(name: str) -> dict:
    return json.loads(json.dumps(load_calibration(name).record))


def _refused(tmp_path, record) -> str:
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(record))
    with pytest.raises(TwinInputError) as err:  # when read, before any twin is built
        load_calibration(path)
    assert str(path) in str(err.value)
    return str(err.value)


#: (what, edit, field, value shown) of numbers added by hand to a file; each ran before, with no
#: word: the lab mill's ball filling 0.45 gave Type B a P80 of 184.7 um for 203.6, the industrial
#: preset took a power factor 2 from the file.
TYPED_IN = [
    ("a lab mill field that is not fitted", lambda r: r["mills"]["lab"].update(ball_filling_frac=0.45),
     "mills.lab.ball_filling_frac", "0.45"),
    ("another mill's values", lambda r: r["mills"].update(industrial={"power_factor": 2.0}), "mills.industrial",
     "'power_factor': 2.0"),
    ("a coefficient that is not fitted", lambda r: r["coefficients"].update(power_exponent=0.3),
     "coefficients.power_exponent", "0.3"),
]


@pytest.mark.parametrize("edit,field,shown", [t[1:] for t in TYPED_IN], ids=[t[0] for t in TYPED_IN])
def test_a_number_typed_into_the_file_is_refused(tmp_path, edit, field, shown):
    record = _copy("dem")
    edit(record)
    message = _refused(tmp_path, record)
    assert f"'{field}' must be absent" in message and shown in message and "grindtwin calibrate" in message


NAMING = [
    ("bounds missing", lambda f: f.pop("bounds"), "fitted.lab_grate_sharpness.bounds", "(missing)"),
    ("value outside its bounds", lambda f: f.update(bounds=[0.5, 5.0]), "fitted.lab_grate_sharpness.value",
     "[0.5, 5.0]"),
    ("no reason", lambda f: f.update(why_not_derivable=" "), "fitted.lab_grate_sharpness.why_not_derivable",
     "' '"),
]


@pytest.mark.parametrize("edit,field,shown", [t[1:] for t in NAMING], ids=[t[0] for t in NAMING])
def test_a_fitted_number_says_its_range_and_why(tmp_path, edit, field, shown):
    record = _copy("dem")
    edit(record["fitted"]["lab_grate_sharpness"])
    message = _refused(tmp_path, record)
    assert f"'{field}' must be" in message and shown in message


@pytest.mark.parametrize("name,names,bounds,why", [
    ("dem", DEM_NAMES, {n: v["bounds"] for n, v in DEM_FITTED.items()}, {n: v["why"] for n, v in DEM_FITTED.items()}),
    ("table", table_map.NAMES, table_map.BOUNDS,
     {n: DEM_FITTED.get(n, {}).get("why", table_map.WHY_MAP) for n in table_map.NAMES}),
])
def test_a_shipped_file_records_the_ranges_its_command_fits_in_and_which_it_ends_at(name, names, bounds, why):
    """A changed range in the code leaves a file fitted in the old one (its value at a bound that
    is no longer one); ``fit.at_bounds`` is what the values and ranges say."""
    record = load_calibration(name).record
    assert record["fit"]["parameters_fitted"] == list(names) == list(record["fitted"])
    for n in names:
        assert record["fitted"][n]["bounds"] == list(bounds[n]), n
        assert record["fitted"][n]["why_not_derivable"] == why[n], n
    at = [n for n, f in record["fitted"].items()
          if min(abs(f["value"] - b) for b in f["bounds"]) <= 1e-6 * max(1.0, abs(f["value"]))]
    assert record["fit"]["at_bounds"] == at


def test_the_shipped_dem_step_was_run_by_todays_dem_sources():
    """The twin's sources are checked at every first use (model_code); the DEM's only by ``--from``,
    which notes another DEM. A change of dem/ or of the virtual tests leaves the shipped breakage
    another DEM's: rerun ``grindtwin calibrate --out twin/calibration/files/dem.json``."""
    assert load_calibration("dem").record["dem"]["sources_sha256"] == dem_step_digest()


def test_a_lab_mill_without_its_fitted_values_is_noted():
    """twin.mill.LAB given as a Mill ran the calibration with the preset's grate (400 um,
    sharpness 3), discharge and power factor 1 where the fit has 517 um, 10, 0.75: Type B's P80 150.9
    um for 203.6, 17.7 kWh/t for 13.4, with no word."""
    dem = load_calibration("dem")
    twin = Twin("B", mill=LAB)
    (problem,) = twin.calibration_mismatch
    fitted = dem.record["mills"]["lab"]["power_factor"]
    assert f"power_factor 1 (fitted {fitted:.6g})" in problem and "get_mill('lab', calibration.record)" in problem
    assert any(problem in n for n in twin.steady(0.031, 0.70).notes)
    assert Twin("B", mill=get_mill("lab", dem.record)).calibration_mismatch == []
    (other,) = Twin("B", mill=get_mill("lab", dem.record), calibration="table").calibration_mismatch
    assert "calibration 'table'" in other


def test_a_twin_on_the_other_discretisation_scheme_is_noted():
    """The same classes discretised by Austin's first-order form are another model (lab P80 -2.5 %
    at 49 classes, twin_grid.md): the calibration's numbers were fitted with the cell-average one."""
    grid = load_calibration("dem").size_grid
    assert grid["scheme"] == "cell_average"
    austin = SizeGrid(top_um=grid["top_um"], ratio=grid["ratio"], count=grid["count"], scheme="austin")
    (problem,) = Twin("B", grid=austin).calibration_mismatch
    assert problem.startswith("size grid") and "'austin'" in problem


def test_another_power_model_on_the_calibrated_mill_or_another_calibrated_mill_is_noted(tmp_path):
    """The lab mill's power factor (0.755) was fitted to Bond's power: on Hogg & Fuerstenau's the lab mill ran at
    7.9 kWh/t for 13.4 with no word (a Twin, and a scene that passed grindtwin check); a twin told the lab
    calibration was measured in the industrial mill ran Type B to 565 um for 204, silently. Both are noted now,
    and the scene's check names the key."""
    from scenarios.scene.loader import check_scene

    cal = load_calibration(None)
    own = get_mill(cal.mill, cal.record)
    assert Twin("B").calibration_mismatch == []
    hf = Twin("B", mill=own.with_(power_model="hogg_fuerstenau")).calibration_mismatch
    assert hf and "power_model 'hogg_fuerstenau'" in hf[0] and "to the power of 'bond'" in hf[0]
    other = Twin("B", calibrated_mill="industrial").calibration_mismatch
    assert other and other[0].startswith("calibrated_mill 'industrial': calibration 'dem' was fitted on mill 'lab'")
    scene = tmp_path / "lab_hf.toml"
    effects = ", ".join(f'"{e}"' for e in cal.effects)
    scene.write_text(f"effects = [{effects}]\n[scene]\nname = \"lab_hf\"\nduration_h = 1.0\nsample_period_h = 0.25\n"
                     "[mill]\npreset = \"lab\"\npower_model = \"hogg_fuerstenau\"\n[ores.B]\ntype = \"B\"\n"
                     "[feed]\nblend = { B = 1.0 }\nfeed_tph = 0.031\nspeed_frac_critical = 0.70\n"
                     "[controller]\nkind = \"none\"\n")
    assert [m for m in check_scene(scene) if "mill.power_model" in m and "to the power of 'bond'" in m]
    scene.write_text(scene.read_text().replace('"hogg_fuerstenau"', '"bond"'))
    assert check_scene(scene) == []


def test_what_readme_says_of_the_table_calibration_holds():
    """README (limitations): the table fit leaves its hardness and texture exponents and the
    cushioning at zero, their lower bounds, so every reference ore gets one specific selection
    rate; the dem calibration's rates differ between them."""
    from twin.ore.ores import load_ore

    table, dem = load_calibration("table"), load_calibration("dem")
    on = set(table.record["fit"]["at_bounds"])
    assert {"hardness_exponent", "texture_exponent", "cushioning_rate_coeff"} <= on
    ores = [load_ore(n) for n in "ABCD"]
    rates = [table.breakage(o).se_1mm_t_kwh for o in ores]
    assert max(rates) / min(rates) - 1.0 < 1e-9, rates
    rates = [dem.breakage(o).se_1mm_t_kwh for o in ores]
    assert max(rates) / min(rates) > 1.2, rates


def test_a_fit_to_values_given_in_place_of_the_table_records_them_and_their_edit_is_refused(tmp_path):
    """fit_to_table(..., reference={...}) recorded its data as the shipped table's (path and sha256): a
    file fitted to a user's three numbers for ore B read as fitted to MISSION.md's table. Now it records
    the values it was given, which travel in the file (`calibrate --table`) and are refused when edited;
    an ore the table lacks is named, where a row E of a user's table was silently left out."""
    from twin.calibration.fitting import TableProblem

    cal = load_calibration("dem")
    mine = {"B": {"p80_um": 225.0, "specific_energy_kwh_t": 12.0, "throughput_kg_h": 30.0}}
    problem = TableProblem(cal, DEM_NAMES, {n: v["bounds"] for n, v in DEM_FITTED.items()}, ores=("B",), reference=mine)
    assert problem.fitted_to["path"] is None and problem.fitted_to["values"] == mine
    record = _copy("dem")
    record["fit"]["fitted_to"] = json.loads(json.dumps(problem.fitted_to))
    record.pop("content_sha256")  # the edit above is this test's, not the check below's
    record["fit"]["fitted_to"]["values"]["B"]["p80_um"] = 210.0
    assert "edited after the fit" in _refused(tmp_path, record)
    with pytest.raises(TwinInputError, match=r"names \['E'\], not in the reference table"):
        TableProblem(cal, DEM_NAMES, {n: v["bounds"] for n, v in DEM_FITTED.items()}, ores=("B", "E"))
