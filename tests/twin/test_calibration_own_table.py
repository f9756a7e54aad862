"""`grindtwin calibrate --table FILE`: the mill's numbers fitted to a user's own laboratory table (ores by type
or by their own ore files), the DEM laws and the mineralogy kept; predictions checked on an ore the fit did not
see; bad tables refused before any work; the table's values travel in the file, checked where it is read."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from twin import Twin, TwinInputError
from twin.calibration import DEM_NAMES, load_calibration, main, reference_table
from twin.calibration.files import content_digest, write_json_atomically
from twin.calibration.parametric import TABLE_LOAD_FRAC, TABLE_SPEED_FRAC_CRITICAL
from twin.calibration.reference import KPIS
from twin.ore import reference_ores

#: Ore B's mineralogy and texture as a user's own ore file.
OWN_B = """[mineralogy]
{minerals}
[texture]
mean_grain_um = {grain}
uniformity = {uniformity}
association_entropy = {entropy}
"""


def _table(path: Path, rows: dict) -> Path:
    path.write_text("# my lab, 0.5 m x 0.3 m mill\nore,p80_um,specific_energy_kwh_t,throughput_kg_h\n"
                    + "".join(f"{ore},{','.join(f'{v[k]:g}' for k in KPIS)}\n" for ore, v in rows.items()))
    return path


def _calibrate(tmp_path, table: Path, name: str, capsys) -> Path:
    out = tmp_path / f"{name}.json"
    assert main(["--table", str(table), "--replicates", "0", "--quiet", "--out", str(out)]) == 0, capsys.readouterr()
    return out


def test_the_shipped_values_in_a_table_of_ones_own_ore_files_fit_the_shipped_numbers(tmp_path, capsys):
    """The shipped values, B's row given by an ore file of B's mineralogy under another name: the table step, from
    its neutral starts, lands on the shipped calibration's numbers, and the file records the table and the ore."""
    b = reference_ores()["B"]
    (tmp_path / "ores").mkdir()
    (tmp_path / "ores" / "my_b.toml").write_text(OWN_B.format(
        minerals="\n".join(f"{m} = {w!r}" for m, w in b.wt_pct.items()), grain=b.texture.mean_grain_um,
        uniformity=b.texture.uniformity, entropy=b.texture.association_entropy))
    ref = reference_table()
    table = _table(tmp_path / "lab.csv", {"A": ref["A"], "ores/my_b.toml": ref["B"], "C": ref["C"], "D": ref["D"]})
    cal = load_calibration(str(_calibrate(tmp_path, table, "mine", capsys)))
    shipped = load_calibration("dem")
    for name in DEM_NAMES:
        assert cal.record["fit"]["values"][name] == pytest.approx(shipped.record["fit"]["values"][name], rel=1e-7)
    fitted_to = cal.record["fit"]["fitted_to"]
    assert fitted_to["path"] == str(table.resolve()) and set(fitted_to["values"]) == {"A", "my_b", "C", "D"}
    assert fitted_to["ores"]["my_b"]["wt_pct"] == b.wt_pct
    assert cal.record["fit"]["max_abs_error_pct"] == pytest.approx(shipped.record["fit"]["max_abs_error_pct"],
                                                                   rel=1e-6)


def test_an_ore_the_fit_did_not_see_is_predicted_from_its_mineralogy(tmp_path, capsys):
    """Leave D out: the mill's numbers fitted to A, B and C alone (9 values for 8 numbers) predict D's three KPIs
    within 10 % of its measurement, through the DEM laws and D's mineralogy (README's leave-one-out)."""
    ref = reference_table()
    table = _table(tmp_path / "abc.csv", {o: ref[o] for o in "ABC"})
    cal = load_calibration(str(_calibrate(tmp_path, table, "abc", capsys)))
    assert set(cal.record["fit"]["fitted_to"]["values"]) == {"A", "B", "C"}
    ss = Twin("D", calibration=cal, effects=cal.effects, grid=cal.grid(), n_mixers=cal.n_mixers) \
        .steady_at_constant_load(speed_frac_critical=TABLE_SPEED_FRAC_CRITICAL, load_frac=TABLE_LOAD_FRAC)
    predicted = {"p80_um": ss.p80_um, "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"],
                 "throughput_kg_h": 1000.0 * ss.feed_tph}
    errors = {k: predicted[k] / ref["D"][k] - 1.0 for k in KPIS}
    assert max(abs(e) for e in errors.values()) < 0.10, errors
    assert cal.record["fit"]["max_abs_error_pct"] < 100 * max(abs(e) for e in errors.values())  # seen < unseen


@pytest.mark.parametrize("rows, message", [
    ({"A": None, "B": None}, "2 ores give 6 values; the table step fits 8 numbers"),
    ({"A": {"throughput_kg_h": 0.0285}, "B": None, "C": None}, r"throughput_kg_h must be a number in \[3.1, 310\]"),
    ({"A": {"p80_um": 0.185}, "B": None, "C": None}, r"p80_um must be a number in \[1, 3200\]"),
    ({"A": None, "B": None, "C": None, "A ": None}, "ore 'A' is given twice"),
    ({"A": None, "B": None, "nope.toml": None}, "ore 'nope.toml'.*was not found"),
    ({"A": None, "B": None, "E": None}, "ore 'E'.*reference type"),
])
def test_a_table_that_cannot_be_fitted_is_refused_before_any_work(tmp_path, capsys, rows, message):
    """Too few ores for the numbers fitted, throughput in t/h, P80 in mm, an ore twice, a missing ore file, an
    unknown type: exit 2 naming the row and the column, no file written."""
    ref = reference_table()
    values = {o: {**ref[o.strip() if o.strip() in ref else "D"], **(v or {})} for o, v in rows.items()}
    path = tmp_path / "bad.csv"
    path.write_text("ore,p80_um,specific_energy_kwh_t,throughput_kg_h\n" + "".join(
        f"{o},{','.join(str(v[k]) for k in KPIS)}\n" for o, v in values.items()))
    out = tmp_path / "never.json"
    assert main(["--table", str(path), "--replicates", "0", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--table {path}" in err
    assert re.search(message, err), err
    assert not out.exists()


def test_other_tables_are_refused_by_name(tmp_path, capsys):
    """Other columns, an ore file named as a reference type, --map mineralogy (no DEM laws to keep)."""
    cols = tmp_path / "cols.csv"
    cols.write_text("ore,p80,kwh_t,tph\nA,185,14.2,28.5\n")
    assert main(["--table", str(cols), "--out", str(tmp_path / "x.json")]) == 2
    assert "columns must be ore, p80_um, specific_energy_kwh_t, throughput_kg_h" in capsys.readouterr().err
    (tmp_path / "A.toml").write_text("[mineralogy]\nquartz = 100.0\n[texture]\nmean_grain_um = 200.0\n"
                                     "uniformity = 0.6\nassociation_entropy = 0.5\n")
    named = _table(tmp_path / "named.csv", {"A.toml": reference_table()["A"], **{o: reference_table()[o] for o in "BC"}})
    assert main(["--table", str(named), "--out", str(tmp_path / "y.json")]) == 2
    assert "named as the reference type 'A'" in capsys.readouterr().err
    assert main(["--map", "mineralogy", "--table", str(named), "--out", str(tmp_path / "z.json")]) == 2
    assert "--table: option of the DEM chain" in capsys.readouterr().err


def test_table_values_edited_in_the_file_are_refused_where_it_is_read(tmp_path, capsys):
    """The table travels in the calibration: a value changed there (and the file's own digest made to match) is
    refused, naming both hashes; untouched, the file loads."""
    ref = reference_table()
    out = _calibrate(tmp_path, _table(tmp_path / "abc.csv", {o: ref[o] for o in "ABCD"}), "own", capsys)
    load_calibration(str(out))
    record = json.loads(out.read_text())
    record["fit"]["fitted_to"]["values"]["B"]["p80_um"] = 150.0
    record["content_sha256"] = content_digest(record)
    write_json_atomically(out, record)
    with pytest.raises(TwinInputError, match="edited after the fit"):
        load_calibration(str(out))
    assert math.isfinite(ref["B"]["p80_um"])


def test_a_table_fitted_file_is_rechecked_and_refitted_with_its_own_table(tmp_path, capsys):
    """A file fitted to a table with an ore file of the user's, read by a twin whose model code changed: its
    predictions are recomputed on the ores it records (the ore's name was taken for a type: refused); the
    refit it names and `--from` it keep its table (the shipped table was fitted instead, unsaid); --fast
    and --seed with --table are refused as with --from (recorded, not used)."""
    from twin.calibration.model_code import refit_command

    b = reference_ores()["B"]
    (tmp_path / "my_b.toml").write_text(OWN_B.format(
        minerals="\n".join(f"{m} = {w!r}" for m, w in b.wt_pct.items()), grain=b.texture.mean_grain_um,
        uniformity=b.texture.uniformity, entropy=b.texture.association_entropy))
    ref = reference_table()
    table = _table(tmp_path / "lab.csv", {"A": ref["A"], "my_b.toml": ref["B"], "C": ref["C"]})
    out = _calibrate(tmp_path, table, "abc", capsys)
    record = json.loads(out.read_text())
    record["model_code"]["sha256"] = "0" * 16  # as made by other twin sources: check_model recomputes
    record["content_sha256"] = content_digest(record)
    write_json_atomically(out, record)
    cal = load_calibration(str(out))
    ss = Twin(str(tmp_path / "my_b.toml"), calibration=cal)
    assert math.isfinite(ss.steady().p80_um)
    command = refit_command(cal.record, str(out))
    assert f"--table {table.resolve()}" in command
    assert main(["--from", str(out), "--replicates", "0", "--out", str(tmp_path / "re.json")]) == 2
    assert "was fitted to your table" in capsys.readouterr().err
    assert main(["--table", str(table), "--fast", "--out", str(tmp_path / "fast.json")]) == 2
    assert "--fast: --from dem reuses that file's DEM step" in capsys.readouterr().err


def test_a_row_with_more_cells_than_the_header_is_refused_naming_them(tmp_path, capsys):
    # a fourth number or a note after the throughput stopped the command with a traceback (exit 1)
    path = tmp_path / "long.csv"
    path.write_text("ore,p80_um,specific_energy_kwh_t,throughput_kg_h\nA,185,14.2,28.5,repeat\nB,210,12.8,31.0\n"
                    "C,265,9.5,36.2\n")
    out = tmp_path / "never.json"
    assert main(["--table", str(path), "--replicates", "0", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--table {path}: data row 1: 5 cells; one per column" in err and "['repeat']" in err, err
    assert not out.exists()
