"""A calibration file is refused, naming the file, the field, its value and what is allowed,
when it was edited by hand or cut short: a changed or missing coefficient, a wrong type, a NaN,
laws that are not its DEM step's. A file as grindtwin wrote it runs as the shipped one."""

from __future__ import annotations

import json

import numpy as np

import pytest

from twin import Twin, TwinInputError
from twin.calibration import DEM_NAMES, load_calibration
from twin.calibration.breakage_map import COEFFICIENT_NAMES
from twin.calibration.record_checks import MAP_COEFFICIENTS, dem_step_sha256


def _copy(name: str) -> dict:
    return json.loads(json.dumps(load_calibration(name).record))


def _write(tmp_path, record, stem="edited"):
    path = tmp_path / f"{stem}.json"
    path.write_text(json.dumps(record))
    return path


def test_the_light_list_of_coefficients_is_the_maps():
    assert MAP_COEFFICIENTS["dem"] == tuple(n for n in DEM_NAMES if not n.startswith("lab_"))
    assert MAP_COEFFICIENTS["mineralogy"] == COEFFICIENT_NAMES


@pytest.mark.parametrize("name", ["dem", "table"])
def test_an_unedited_copy_runs_as_the_shipped_file(tmp_path, name):
    path = _write(tmp_path, _copy(name), stem=f"copy-{name}")
    shipped = Twin("B", calibration=name).steady(0.031, 0.70).p80_um
    assert Twin("B", calibration=path).steady(0.031, 0.70).p80_um == shipped


def _edits(rec):
    """(what, edit, field named, value shown) of each hand edit; values from the file itself."""
    coef = rec["coefficients"]["dem_capture_scale"]
    return [
        ("a coefficient changed", lambda r: r["coefficients"].update(dem_capture_scale=coef * 1.3),
         "coefficients.dem_capture_scale", repr(coef * 1.3)),
        ("a coefficient missing", lambda r: r["coefficients"].pop("cushioning_rate_coeff"),
         "coefficients.cushioning_rate_coeff", "(missing)"),
        ("a coefficient as text", lambda r: r["coefficients"].update(dem_capture_scale=str(coef)),
         "coefficients.dem_capture_scale", repr(str(coef))),
        ("a NaN coefficient", lambda r: r["coefficients"].update(slurry_power_coeff=float("nan")),
         "coefficients.slurry_power_coeff", "nan"),
        ("a mill value missing", lambda r: r["mills"]["lab"].pop("power_factor"), "mills.lab.power_factor",
         "(missing)"),
        ("a mill value changed", lambda r: r["mills"]["lab"].update(grate_d50_um=400.0), "mills.lab.grate_d50_um",
         "400.0"),
        ("the mills emptied", lambda r: r.update(mills={}), "mills", "{}"),
        ("a grid count as text", lambda r: r["size_grid"].update(count="25"), "size_grid", "'count': '25'"),
        ("n_mixers as text", lambda r: r.update(n_mixers="3"), "n_mixers", "'3'"),
        ("another mill", lambda r: r.update(mill="industrial"), "mill", "'industrial'"),
        ("effects as text", lambda r: r.update(effects="breakage"), "effects", "'breakage'"),
        ("the fit removed", lambda r: r.pop("fit"), "fit", "None"),
        ("the fast flag removed", lambda r: r["dem"]["settings"].pop("fast"), "dem.settings.fast", "(missing)"),
    ]


@pytest.mark.parametrize("index", range(13), ids=[e[0] for e in _edits(_copy("dem"))])
def test_a_hand_edited_file_is_refused_naming_file_field_and_value(tmp_path, index):
    rec = _copy("dem")
    _, edit, field, shown = _edits(rec)[index]
    edit(rec)
    path = _write(tmp_path, rec)
    with pytest.raises(TwinInputError) as err:  # when read, before any twin is built
        load_calibration(path)
    msg = str(err.value)
    assert str(path) in msg and f"'{field}'" in msg and shown in msg, msg
    assert "must be" in msg


def test_a_changed_coefficient_is_refused_with_the_value_its_fit_recorded(tmp_path):
    rec = _copy("table")
    fitted = rec["fitted"]["se_ref_t_kwh"]["value"]
    rec["coefficients"]["se_ref_t_kwh"] = fitted * 0.9
    with pytest.raises(TwinInputError, match="coefficients.se_ref_t_kwh") as err:
        load_calibration(_write(tmp_path, rec))
    assert repr(fitted) in str(err.value) and "fitted.se_ref_t_kwh" in str(err.value)


def test_laws_that_are_not_the_files_dem_step_are_refused(tmp_path):
    rec = _copy("dem")
    c0 = rec["law"]["energy"]["c0"]
    rec["law"]["energy"]["c0"] = c0 + 0.1
    path = _write(tmp_path, rec)
    with pytest.raises(TwinInputError) as err:
        Twin("B", calibration=path)
    msg = str(err.value)
    assert str(path) in msg and "'law.energy.c0'" in msg and repr(c0 + 0.1) in msg and repr(c0) in msg, msg
    with pytest.raises(TwinInputError, match="law.energy.c0"):  # every time, not only the first
        Twin("B", calibration=path)


# --------------------------------------------------------------------------- grindtwin calibrate
def _calibrate(argv) -> int:
    from twin.calibration import main

    return main([*argv, "--quiet"])


def test_a_new_file_is_named_after_itself_and_never_takes_a_shipped_name(tmp_path, capsys):
    mine = tmp_path / "mine.json"
    assert _calibrate(["--from", "dem", "--replicates", "0", "--out", str(mine)]) == 0
    _says_what_is_on_a_bound(capsys.readouterr().out, json.loads(mine.read_text()))
    made = load_calibration(mine)
    assert made.name == "mine" and made.label().startswith("'mine'")
    for argv, out in ((["--out", str(tmp_path / "dem.json")], tmp_path / "dem.json"),
                      (["--name", "table", "--out", str(tmp_path / "t.json")], tmp_path / "t.json")):
        capsys.readouterr()
        assert _calibrate(["--from", "dem", "--replicates", "0", *argv]) == 2
        err = capsys.readouterr().err
        assert "is the name of a shipped calibration" in err and str(out) in err and not out.exists(), err


def test_a_calibration_is_replaced_only_by_one_of_its_kind_and_options_it_would_not_use_are_refused(tmp_path,
                                                                                                    capsys):
    """`calibrate --map mineralogy --out mine.json` replaced a DEM calibration there with "wrote mine.json" alone
    (the DEM step takes minutes to hours, and scenes naming the file ran on the other map); `--from dem --seed 9`
    recorded a seed its reused DEM step never ran with."""
    mine = tmp_path / "mine.json"
    assert _calibrate(["--from", "dem", "--replicates", "0", "--out", str(mine)]) == 0
    before = mine.read_bytes()
    capsys.readouterr()
    assert _calibrate(["--map", "mineralogy", "--out", str(mine)]) == 2
    assert (f"--out {mine}: it holds a 'dem' calibration, which this command would replace with a 'mineralogy' one"
            in capsys.readouterr().err)
    assert mine.read_bytes() == before
    assert _calibrate(["--from", "dem", "--replicates", "0", "--out", str(mine)]) == 0  # its own kind: said
    assert f"note: --out {mine}: replacing the 'dem' calibration it holds (made by `grindtwin calibrate --from dem" \
        in capsys.readouterr().err
    for unused in (["--seed", "9"], ["--fast"], ["--workers", "2"]):
        assert _calibrate(["--from", "dem", "--replicates", "0", "--out", str(tmp_path / "s.json"), *unused]) == 2
        assert f"{unused[0]}: --from dem reuses that file's DEM step, so no DEM test runs" in capsys.readouterr().err
    assert not (tmp_path / "s.json").exists()
    assert _calibrate(["--from", str(tmp_path / "nosuch.json"), "--out", str(tmp_path / "s.json")]) == 2
    assert f"--from {tmp_path / 'nosuch.json'}: The 'calibration' must be" in capsys.readouterr().err


def test_a_shipped_file_keeps_its_own_name(capsys):
    shipped = load_calibration("table")
    before = shipped.path.read_bytes()
    assert _calibrate(["--map", "mineralogy", "--name", "mine", "--out", str(shipped.path)]) == 2
    assert "a shipped calibration file's name is its file's, 'table'" in capsys.readouterr().err
    assert shipped.path.read_bytes() == before


def test_from_a_file_whose_dem_step_is_cut_short_is_refused_before_any_work(tmp_path, capsys):
    rec = _copy("dem")
    ore = sorted(rec["dem"]["ores"])[0]
    del rec["dem"]["ores"][ore]["fracture_energy"]
    source, out = _write(tmp_path, rec, stem="cut"), tmp_path / "new.json"
    assert _calibrate(["--from", str(source), "--replicates", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--from {source}" in err and "'dem'" in err and "fracture_energy" in err and not out.exists(), err


def test_from_a_file_fitted_by_other_twin_sources_refits_its_laws(tmp_path, capsys):
    """A law fit that changed since the file was made (here: a key today's fit adds): --from
    refits the laws from the file's DEM step and says so. By the same sources the same change
    is an edit, refused with a way out that is not --from itself."""
    rec = _copy("dem")
    del rec["law"]["breakage_function"]["at_bounds"]
    rec["model_code"]["sha256"] = "0" * 16
    source, out = _write(tmp_path, rec, stem="older"), tmp_path / "new.json"
    assert _calibrate(["--from", str(source), "--replicates", "0", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "was fitted by other twin sources" in err and "refitted by today's" in err, err
    assert json.loads(out.read_text())["law"] == load_calibration("dem").record["law"]
    rec["model_code"] = load_calibration("dem").record["model_code"]
    source = _write(tmp_path, rec, stem="edited")
    assert _calibrate(["--from", str(source), "--replicates", "0", "--out", str(tmp_path / "no.json")]) == 2
    err = capsys.readouterr().err
    assert "law.breakage_function.at_bounds" in err and "rerun its DEM step" in err, err
    assert not (tmp_path / "no.json").exists()


def test_an_edited_dem_step_is_refused_where_its_laws_cannot_be_compared(tmp_path, capsys):
    """A file fitted by other twin sources has its laws refitted from its DEM step, not compared
    (above): the step's own digest (dem.sha256) still tells an edit of it, refused before any work.
    An older file without that digest is taken, with a note that the step cannot be checked."""
    rec = _copy("dem")
    assert rec["dem"]["sha256"] == dem_step_sha256(rec["dem"])
    rec["model_code"]["sha256"] = "0" * 16
    step = rec["dem"]["ores"]["B"]["specific_fracture_energy_J_kg"]
    ran = step[0]
    step[0] = 1.1 * ran
    out = tmp_path / "new.json"
    source = _write(tmp_path, rec, stem="edited_step")
    assert _calibrate(["--from", str(source), "--replicates", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "dem.sha256" in err and dem_step_sha256(rec["dem"]) in err and not out.exists(), err
    step[0] = ran
    del rec["dem"]["sha256"]
    source = _write(tmp_path, rec, stem="older_step")
    assert _calibrate(["--from", str(source), "--replicates", "0", "--out", str(out)]) == 0
    assert "records no digest of its DEM step" in capsys.readouterr().err
    made = json.loads(out.read_text())["dem"]
    assert made["sha256"] == dem_step_sha256(made) == load_calibration("dem").record["dem"]["sha256"]


def _says_what_is_on_a_bound(out: str, record: dict) -> None:
    """calibrate's report names every fitted number its record marks as on a bound, and each
    parameter of Austin's B with the energies at which it is; the marks are the values'."""
    for name in record["fit"]["at_bounds"]:
        value, bounds = record["fitted"][name]["value"], record["fitted"][name]["bounds"]
        assert min(abs(value - b) for b in bounds) <= 1e-6 * (bounds[1] - bounds[0])
        assert f"{name} {value:.4g}" in out, out
    b = record["law"]["breakage_function"]
    for name in ("gamma", "phi"):
        lo, hi = b["bounds"][name]
        on = [m for m, v in zip(b["energy_multiple"], b[name]) if min(v - lo, hi - v) < 1e-6 * (hi - lo)]
        assert [m for m, names in zip(b["energy_multiple"], b["at_bounds"]) if name in names] == on
        assert (f"{name} at {', '.join(f'{m:g}' for m in on)} x E50" in out) == bool(on), out


def test_austins_b_on_a_bound_is_marked_where_the_tests_ask_for_more():
    """Fragments drawn from Austin's B with gamma 0.1 (below the fit's range) are fitted at its
    lower bound and marked; those of gamma 0.8, phi 0.4 are fitted inside it, unmarked."""
    from twin.calibration.dem_map import AUSTIN_B_BOUNDS, fit_breakage_function_law

    y = 2.0 ** -0.5 * 2.0 ** (-0.5 * np.arange(0, 12))  # the parent's first sieve and 11 below it

    def tests(gamma, phi, mult):
        b = phi * (y / y[0]) ** gamma + (1 - phi) * (y / y[0]) ** 4.0
        return [{"energy_multiple": mult, "sieve_size_rel": y.tolist(), "passing_frac": (0.7 * b).tolist()}]

    law = fit_breakage_function_law([tests(0.1, 0.6, 1.0) + tests(0.8, 0.4, 2.0)], [1.0, 2.0])
    assert law["gamma"][0] == pytest.approx(AUSTIN_B_BOUNDS["gamma"][0]) and law["at_bounds"][0] == ["gamma"]
    assert law["gamma"][1] == pytest.approx(0.8, rel=1e-6) and law["at_bounds"][1] == []
    assert law["bounds"] == {k: list(v) for k, v in AUSTIN_B_BOUNDS.items()}


def test_a_file_changed_after_grindtwin_wrote_it_is_refused(tmp_path):
    """An edit the field checks cannot see ran with exit 0: the effects list without cushioning (P80 159.6 um
    for 203.6), a coefficient x3 in all three of its copies (72.6 um), the fit's reported error. A file now
    records the digest of its content (content_sha256) and one that no longer matches is refused."""
    from twin.calibration import load_calibration

    mine = tmp_path / "mine.json"
    assert _calibrate(["--from", "dem", "--replicates", "0", "--out", str(mine)]) == 0
    record = json.loads(mine.read_text())
    assert load_calibration(mine).record["content_sha256"] == record["content_sha256"]
    def times_three(r):  # in all three of its copies, as check_fitted compares them
        for d in (r["coefficients"], r["fit"]["values"], r["fitted"]["dem_capture_scale"]):
            key = "value" if "value" in d else "dem_capture_scale"
            d[key] *= 3

    edits = {"effects": lambda r: r["effects"].remove("cushioning"), "coefficient x3": times_three,
             "reported error": lambda r: r["fit"].__setitem__("max_abs_error_pct", 0.1)}
    for name, edit in edits.items():
        changed = json.loads(json.dumps(record))
        edit(changed)
        path = tmp_path / f"{name.replace(' ', '_')}.json"
        path.write_text(json.dumps(changed))
        with pytest.raises(TwinInputError, match="changed after grindtwin wrote it"):
            load_calibration(path)
    # and `calibrate --out` over the edited file refuses it (it was replaced, with a note on stderr)
    edited = path.read_text()
    assert _calibrate(["--from", "dem", "--replicates", "0", "--out", str(path)]) == 2
    assert path.read_text() == edited


@pytest.mark.parametrize("where", ["mine.json", "../../ore/data/other.json"])
def test_a_new_file_inside_the_installed_package_is_refused_before_any_work(where, capsys):
    # it was written (exit 0): lost with the next install, and in the shipped folder a new shipped name
    out = load_calibration("table").path.parent / where
    assert _calibrate(["--map", "mineralogy", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "inside the installed twin package" in err and str(out) in err and not out.exists(), err
