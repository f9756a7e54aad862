"""The standard parameterisations an engineer brings (breakage parameters, screen analyses,
mills, hydrocyclones), their validation, and the scale-up rules."""

import hashlib
import json
import math

import numpy as np
import pytest

from twin import (BreakageParams, Hydrocyclone, SizeGrid, TabulatedPSD, Twin, TwinInputError, discretise, get_mill,
                  power_kw)
from twin.errors import TwinError
from twin.mill import INDUSTRIAL_PRESET_PATH, LAB, POWER_MODELS
from twin.scaleup import diameter_factor_a, scale_breakage
from twin.calibration import load_calibration

LEAN = ["breakage", "transport"]


def test_energy_specific_parameters_map_onto_austin_form():
    p = BreakageParams.energy_specific(0.009686, 0.659, 2.5, 7093.0, 0.4, 0.65, 4.0)
    # S^E(1 mm) = alpha0 * 1000^alpha1 / (1 + (1000/7093)^2.5), the form with d in um
    grid = SizeGrid(top_um=1000.0 * 2 ** 0.25, ratio=2 ** 0.5, count=3, scheme="austin")
    from twin.breakage import selection_at
    s = selection_at(1000.0, p.se_1mm_t_kwh, p.alpha, p.mu_um, p.Lambda)
    assert s == pytest.approx(0.009686 * 1000 ** 0.659 / (1 + (1000 / 7093) ** 2.5), rel=1e-12)
    assert (p.phi, p.gamma, p.beta, p.mu_um, p.Lambda) == (0.4, 0.65, 4.0, 7093.0, 2.5)
    assert grid.count == 3


def test_austin_rate_converts_by_power_and_holdup():
    p = BreakageParams.austin_rate(0.5, 1.0, 3000.0, 2.5, 1.0, 4.0, 0.5, power_kw=100.0, holdup_t=4.0)
    assert p.se_1mm_t_kwh == pytest.approx(60 * 0.5 * 4.0 / 100.0 * 2.0 ** 0.25)  # Austin's top size to a mean
    assert p.mu_um == pytest.approx(3000.0 / 2.0 ** 0.25)


@pytest.mark.parametrize("kwargs, field", [
    (dict(alpha0_t_kwh=-1, alpha1=0.6, alpha2=2.5, critical_size_um=7000, beta0=0.4, beta1=0.6, beta2=4), "alpha0_t_kwh"),
    (dict(alpha0_t_kwh=0.01, alpha1=0.6, alpha2=2.5, critical_size_um=7000, beta0=1.4, beta1=0.6, beta2=4), "phi"),
])
def test_bad_breakage_parameters_name_the_field(kwargs, field):
    with pytest.raises(TwinInputError, match=field):
        BreakageParams.energy_specific(**kwargs)


def test_breakage_exponents_swapped_are_refused_with_the_same_b_in_austins_order():
    # gamma (Moly-Cop's beta1) is the fine-fragment term's exponent, below beta: swapped, the run moved P80 by 24 %
    with pytest.raises(TwinInputError, match=r"beta1 = 4 is above beta2 = 0.65.*beta0 = 0.6, beta1 = 0.65, beta2 = 4"):
        BreakageParams.energy_specific(0.009686, 0.659, 2.5, 7093.0, 0.4, 4.0, 0.65)
    with pytest.raises(TwinInputError, match=r"gamma = 4 is above beta = 0.65"):
        BreakageParams.austin_rate(1.25, 0.659, 7093.0, 2.5, 4.0, 0.65, 0.4, power_kw=3885.0, holdup_t=47.6)
    same = BreakageParams.energy_specific(0.009686, 0.659, 2.5, 7093.0, 0.6, 0.65, 4.0)
    grid = SizeGrid(top_um=25400.0, count=20)
    from twin.breakage import cumulative_breakage
    y = grid.upper_um[1:] / grid.upper_um[1]  # the suggested order is the swapped B itself
    assert cumulative_breakage(grid, same.gamma, same.beta, same.phi)[1:, 0] == pytest.approx(
        0.4 * y ** 4.0 + 0.6 * y ** 0.65)


def test_screen_analysis_interpolates_and_extends_below_the_finest_sieve_on_its_ggs_line():
    psd = TabulatedPSD.from_sieves([1000, 500, 250, 125], [100, 70, 49, 34.3])
    assert psd.passing(500.0) == pytest.approx(0.70)
    m = psd.fine_modulus
    assert m == pytest.approx(math.log(49 / 34.3) / math.log(2))
    assert psd.passing(62.5) == pytest.approx(0.343 * 0.5 ** m)
    frac = discretise(SizeGrid(top_um=2000.0, count=12), psd)
    assert frac.sum() == pytest.approx(1.0) and np.all(frac >= 0)


@pytest.mark.parametrize("sizes, passing, field", [([100, 200], [50, 40], "passing_pct"),
                                                   ([100, 200], [50, 140], "passing_pct"),
                                                   ([100, 200, 300], [10, 20], "passing_pct")])
def test_bad_screen_analysis_names_the_field(sizes, passing, field):
    with pytest.raises(TwinInputError, match=field):
        TabulatedPSD.from_sieves(sizes, passing)


def test_screen_analysis_csv(tmp_path):
    path = tmp_path / "feed.csv"
    path.write_text("size_um,passing_pct\n1000,100\n500,60\n250,35\n")
    assert TabulatedPSD.from_csv(path).passing(500.0) == pytest.approx(0.6)
    # comment lines as a scene's history takes them: the header was read from "# screen 3, ..." and refused
    commented = tmp_path / "commented.csv"
    commented.write_text("# screen 3, 2026-12-01\nsize_um,passing_pct\n1000,100\n  # sieve 500 re-weighed\n500,60\n"
                         "250,35\n")
    psd, sha256 = TabulatedPSD.read_csv(commented)
    assert psd == TabulatedPSD.from_csv(path) and sha256 == hashlib.sha256(commented.read_bytes()).hexdigest()
    (tmp_path / "bad.csv").write_text("size,pct\n1,2\n")
    with pytest.raises(TwinInputError, match="size_um"):
        TabulatedPSD.from_csv(tmp_path / "bad.csv")


@pytest.mark.parametrize("row, said", [
    ("500,Bad", "column passing_pct is not a number in data rows [2] (e.g. 'Bad')"),
    ("#N/A,60", "column size_um is not a number in data rows [2] (e.g. '#N/A')"),
    ("500,60,5", "cannot be read as a comma-separated UTF-8 file with decimal points")])
def test_a_screen_analysis_csv_with_a_text_cell_or_a_split_row_is_refused_naming_it(tmp_path, row, said):
    """A text cell (a historian's "Bad", Excel's "#N/A") or a decimal comma splitting a row raised a ValueError
    whose traceback `grindtwin check` and `run` printed, exit 1, naming no row."""
    path = tmp_path / "feed.csv"
    path.write_text(f"size_um,passing_pct\n1000,100\n{row}\n250,35\n")
    with pytest.raises(TwinInputError) as err:
        TabulatedPSD.from_csv(path)
    assert str(path) in str(err.value) and said in str(err.value)


def test_unequal_mixers_hold_their_shares_of_the_holdup():
    fr = (0.7, 0.15, 0.15)
    tw = Twin("B", mill="lab", effects=LEAN, mixer_volume_fracs=fr)
    ss = tw.steady()
    held = tw.model.mass_array(ss.x).sum(axis=(0, 2))
    # without breakage every mixer passes the same flow, so the hold-up splits as the volumes
    tw0 = Twin("B", mill="lab", effects=["transport", "breakage"], mixer_volume_fracs=fr,
               ore_breakage={"B": BreakageParams(se_1mm_t_kwh=1e-9)})
    held0 = tw0.model.mass_array(tw0.steady().x).sum(axis=(0, 2))
    assert held0 / held0.sum() == pytest.approx(np.array(fr), rel=1e-6)
    assert held.sum() > 0


def test_mixer_shares_are_validated():
    with pytest.raises(TwinInputError, match="mixer_volume_fracs"):
        Twin("B", mill="lab", effects=LEAN, mixer_volume_fracs=(0.7, -0.1))
    # (1, 1, 1) was rescaled to thirds without a word; a scene refuses it, the twin now too
    with pytest.raises(TwinInputError, match=r"summing to 1 within 0.01 \(sum 3\)"):
        Twin("B", mill="lab", effects=LEAN, mixer_volume_fracs=(1.0, 1.0, 1.0))
    rounded = Twin("B", mill="lab", effects=LEAN, mixer_volume_fracs=(0.33, 0.33, 0.33))  # thirds, rounded
    assert rounded.spec.mixer_fracs == pytest.approx((1 / 3, 1 / 3, 1 / 3), rel=1e-12)


def test_given_net_power_is_drawn_at_nominal_speed_and_shaped_by_the_model():
    mill = LAB.with_(net_power_kw=2.0)
    assert power_kw(mill, 0.70) == pytest.approx(2.0)
    for name, model in POWER_MODELS.items():
        m = mill.with_(power_model=name)
        assert power_kw(m, 0.80) / power_kw(m, 0.70) == pytest.approx(model(LAB, 0.80) / model(LAB, 0.70))
    with pytest.raises(TwinInputError, match="power_model"):
        LAB.with_(power_model="morell")


def test_plitt_factors_scale_their_own_equation_only():
    base, cyc = Hydrocyclone(), Hydrocyclone(d50c_factor=2.0, pressure_factor=1.5)
    a, b = base.plitt(300.0, 2.7), cyc.plitt(300.0, 2.7)
    assert b["d50c_um"] == pytest.approx(2 * a["d50c_um"])
    assert b["pressure_kpa"] == pytest.approx(1.5 * a["pressure_kpa"])
    # a higher pressure (head) lowers Plitt's split: S ~ H^-0.24
    assert b["volume_split"] == pytest.approx(a["volume_split"] * 1.5 ** -0.24)


def test_plitt_cut_size_follows_flow_to_the_minus_045():
    cyc = Hydrocyclone(feed_solids_frac=0.6)
    assert cyc.plitt(400.0, 2.7)["d50c_um"] / cyc.plitt(200.0, 2.7)["d50c_um"] == pytest.approx(2 ** -0.45)


def test_direct_cyclone_needs_its_three_values_and_names_the_missing_one():
    with pytest.raises(TwinInputError, match="water_bypass_frac"):
        Hydrocyclone(d50c_um=180.0, sharpness=1.3)
    with pytest.raises(TwinInputError, match="solids_bypass_frac"):
        Hydrocyclone(d50c_um=180.0, sharpness=1.3, water_bypass_frac=0.4, solids_bypass_frac=1.2)
    cyc = Hydrocyclone(d50c_um=180.0, sharpness=1.3, water_bypass_frac=0.4, solids_bypass_frac=0.35)
    assert cyc.mode == "direct" and cyc.plitt(500.0, 2.8)["d50c_um"] == 180.0


def test_scale_up_is_identity_on_the_calibration_mill_and_follows_austin_elsewhere():
    p = BreakageParams(se_1mm_t_kwh=1.0)
    assert scale_breakage(p, LAB, LAB, 2.7) == p
    big = LAB.with_(name="big", diameter_m=2.0, length_m=1.2)
    q = scale_breakage(p, LAB, big, 2.7)
    # Bond's power P ~ D^2.3 L, hold-up ~ D^2 L: S^E grows as D^(0.5 - 0.3) = D^0.2
    assert q.se_1mm_t_kwh == pytest.approx(4.0 ** 0.2, rel=1e-9)
    assert q.mu_um == pytest.approx(3000.0 * 4.0 ** 0.2)
    # Hogg-Fuerstenau's P ~ D^2.5: energy-specific rates do not change with diameter
    hf = scale_breakage(p, LAB.with_(power_model="hogg_fuerstenau"), big.with_(power_model="hogg_fuerstenau"), 2.7)
    assert hf.se_1mm_t_kwh == pytest.approx(1.0, rel=1e-9)
    balls = scale_breakage(p, LAB, LAB.with_(name="b", ball_size_mm=50.0), 2.7)
    assert balls.se_1mm_t_kwh == pytest.approx(0.5) and balls.mu_um == pytest.approx(4 * 3000.0)
    assert diameter_factor_a(1.0, 7.62) == pytest.approx(3.81 ** 0.5 * 2 ** 0.3)


def test_industrial_preset_is_the_sized_mill_and_meets_its_sizing_target():
    """Depends on the shipped calibration: after a recalibration, rerun the command in the file.
    The preset's circuit meets the sizing's three conditions (P80, circulating load, cyclone
    pressure) and needs no water taken out."""
    from twin.sizing import DESIGN_CIRCULATING_LOAD, DESIGN_CYCLONE_PRESSURE_KPA

    record = json.loads(INDUSTRIAL_PRESET_PATH.read_text())
    mill = get_mill("industrial")
    assert mill.diameter_m == record["mill"]["diameter_m"] and dict(mill.cyclone) == record["cyclone"]
    assert record["calibration"]["sha256"] == load_calibration().sha256, "sized with another calibration"
    z = record["sizing"]
    tw = Twin(z["ore"], mill="industrial", effect_options={"classification": {"kind": "hydrocyclone"}})
    ss = tw.steady(feed_tph=z["feed_tph"])
    assert ss.p80_um == pytest.approx(z["target_p80_um"], rel=0.01), record["command"]
    assert ss.load_status == "stable"
    o = ss.outputs
    assert o["circulating_load_frac"] == pytest.approx(DESIGN_CIRCULATING_LOAD, rel=0.01)
    assert o["cyclone_pressure_kpa"] == pytest.approx(DESIGN_CYCLONE_PRESSURE_KPA, rel=0.01)
    assert o["sump_water_m3_h"] >= 0 and o["mill_water_m3_h"] >= 0
    # its one note: the underflow (61 % solids by volume) is as dense as cyclones rope at, which the
    # sizing, keeping the cyclone's shape, does not design out (README, Limitations)
    assert [n for n in ss.notes if "hydrocyclones rope" not in n] == [] and len(ss.notes) == 1


def test_sizing_at_the_molycop_base_cases_scale_designs_a_cluster_like_its_own():
    """Moly-Cop's BallSim base case (scenarios/data/molycop_ballsim_published.toml: 504 t/h, P80
    169.4 um) runs six 66-cm cyclones fed at 61 % solids with a 75.6 % underflow. size_mill at
    that throughput and product, for type B (the case's ore is not ours), at that case's pressure,
    chooses a cluster of the same kind: six cyclones, feed and underflow within 5 points."""
    import tomllib
    from pathlib import Path

    from twin.sizing import size_mill

    published = tomllib.loads((Path(__file__).resolve().parents[2] / "scenarios" / "data"
                               / "molycop_ballsim_published.toml").read_text())
    psi_kpa = 6.894757
    sized = size_mill("B", 504.0, published["overflow_p80_um"],
                      cyclone_pressure_kpa=published["cyclone_pressure_psi"] * psi_kpa)
    assert sized.cyclone["count"] == 6
    assert sized.circuit["cyclone_feed_solids_frac"] == pytest.approx(1902.5 / (1902.5 + 1204.2), abs=0.05)
    assert sized.circuit["underflow_solids_frac"] == pytest.approx(published["underflow_solids_frac"], abs=0.05)
    assert sized.circulating_load_frac == pytest.approx(2.5, rel=0.01)
    assert sized.p80_um == pytest.approx(published["overflow_p80_um"], rel=0.01)


def test_missing_preset_file_names_the_command(monkeypatch, tmp_path):
    import twin.mill as mill_module
    monkeypatch.setattr(mill_module, "INDUSTRIAL_PRESET_PATH", tmp_path / "none.json")
    mill_module.industrial_preset.cache_clear()
    try:
        with pytest.raises(TwinError, match="size-mill"):
            get_mill("industrial")
    finally:
        monkeypatch.undo()
        mill_module.industrial_preset.cache_clear()


def test_a_preset_is_written_only_where_grindtwin_may_write(tmp_path):
    """size-mill --write-preset: a new file or a preset grindtwin wrote; never a user's file."""
    from twin import check_preset_path

    assert check_preset_path(tmp_path / "new.json") == tmp_path / "new.json"
    assert check_preset_path(INDUSTRIAL_PRESET_PATH) == INDUSTRIAL_PRESET_PATH  # a preset it wrote
    mine = tmp_path / "notes.json"
    mine.write_text('{"mine": true}')
    with pytest.raises(TwinInputError, match="not a mill preset grindtwin wrote"):
        check_preset_path(mine)
    with pytest.raises(TwinInputError, match="is a folder"):
        check_preset_path(tmp_path)
    with pytest.raises(TwinInputError, match="does not exist"):
        check_preset_path(tmp_path / "nowhere" / "p.json")
    assert mine.read_text() == '{"mine": true}'


def test_an_impossible_sizing_says_why_each_cyclone_count_misses():
    """size_mill at 1 kg/h: a 75-um cut at 53 kPa would need a feed denser than a slurry can be, and
    more cyclones only a denser one; at 5 t/h and 210 um the one cyclone that cuts coarse enough
    needs its feed denser than the mill discharges (water taken out of the sump). Each error says
    so, naming the counts; _counts joins runs."""
    from twin.errors import SolverError
    from twin.sizing import _counts, size_mill

    with pytest.raises(SolverError, match=r"with 1 cyclone, no design point: the cut would need a cyclone feed of "):
        size_mill("B", 0.001, 75.0)
    with pytest.raises(SolverError, match=r"with 1 cyclone, water taken out \(sump_water_m3_h -[0-9.]+\) \(another"):
        size_mill("B", 5.0, 210.0)
    assert _counts([1, 2, 3, 5, 7, 8]) == "1-3, 5, 7-8" and _counts([4]) == "4"


def test_ore_files_that_are_not_toml_or_absent_are_named(tmp_path):
    """A TOML syntax error, a duplicate key, a binary file or a missing file: a TwinInputError
    naming the file (it was a tomllib/UnicodeDecodeError traceback, or 'must be a reference type')."""
    from twin.ore.ores import load_ore

    for name, data in (("bad.toml", b"[mineralogy\nx = 1\n"), ("dup.toml", b"[texture]\na = 1\na = 2\n"),
                       ("bin.toml", b"\xff\xfe\x00\x01")):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(TwinInputError, match=f"{name} is not valid TOML"):
            load_ore(tmp_path / name)
    with pytest.raises(TwinInputError, match="none.toml was not found"):
        load_ore(tmp_path / "none.toml")


def test_a_blend_names_each_ore_once():
    """B=0.3,B=0.7 lost a component in every result keyed by name (JSON blend {'B': 0.7})."""
    from twin.ore.ores import Blend, load_ore

    with pytest.raises(TwinInputError, match="'B' appears more than once"):
        Blend((load_ore("B"), load_ore("B")), (0.3, 0.7))


def test_a_feed_reaching_above_the_grid_is_refused_not_lumped():
    """GGS feed P80 20 mm on the 6.7-mm grid put 67 % of the feed into the top class (the twin
    ground a 6.1-mm feed and said nothing); 6.6 mm, which a scene's F80-below-top rule let
    through, 19 %. Now refused naming the share; the default 3.2-mm feed (top particle 4.4 mm)
    is fine. Class fractions with a NaN are refused too (NaN passed both comparisons)."""
    for f80, share in ((20000.0, "66.6%"), (6600.0, "19.0%")):
        with pytest.raises(TwinInputError, match=f"feed_p80_um {f80:g} with modulus 0.8 puts {share} of the feed"):
            Twin("B", feed_p80_um=f80)
    grid = SizeGrid()
    frac = np.full(grid.count, 1.0 / grid.count)
    frac[3] = np.nan
    with pytest.raises(TwinInputError, match="feed_psd"):
        Twin("B", feed_psd=frac)


def test_a_hardness_scale_that_is_not_a_positive_number_is_refused():
    """It divides every breakage rate: 0 and NaN made a CasADi NaN error, -1 a 'tighten the
    tolerances' failure, inf a P80 of 3182 um with only an overflow note."""
    tw = Twin("B")
    for h in (0.0, math.nan, -1.0, math.inf):
        with pytest.raises(TwinInputError, match="'hardness_scale'"):
            tw.steady(feed_tph=0.031, hardness_scale=h)


def test_an_ore_file_with_a_key_nothing_reads_is_refused(tmp_path):
    """A bond_wi_kwh_t beside [mineralogy] and [texture] was read by nothing, silently."""
    from twin.ore.ores import load_ore

    path = tmp_path / "ore.toml"
    path.write_text("bond_wi_kwh_t = 25.0\n[mineralogy]\nquartz = 100.0\n"
                    "[texture]\nmean_grain_um = 125.0\nuniformity = 0.6\nassociation_entropy = 0.55\n")
    with pytest.raises(TwinInputError, match="unknown key bond_wi_kwh_t; allowed: description, mineralogy, texture"):
        load_ore(path)
    path.write_text(path.read_text().replace("bond_wi_kwh_t = 25.0\n", 'description = "mine"\n'))
    assert load_ore(path).name == "ore"


def test_size_mill_refuses_a_target_coarser_than_its_feed():
    """5000 um against the 3.2-mm feed: the Newton failure of the first trial mill said nothing
    of why; refused before any work."""
    from twin.sizing import size_mill

    with pytest.raises(TwinInputError, match="finer than the feed the sizing grinds"):
        size_mill("B", 31.0, 5000.0)


def test_a_count_whose_start_from_the_last_design_fails_starts_again_from_its_first_guess():
    """size_mill starts each count after the first from the last count's design point; where
    Newton fails from there, it starts again from the count's own first guess, as it did before."""
    from twin.errors import SolverError
    from twin.sizing import _newton_from

    target = np.array([0.5, 3.0, 4.0])
    starts_seen = []

    def point(x):  # no steady state for x[0] > 1 (an overloaded trial mill); else linear residuals
        starts_seen.append(x.copy())
        if x[0] > 1.0:
            raise SolverError("no steady state")
        return x - target, "mill", "steady state"

    x, mill, ss = _newton_from(point, [np.array([2.0, 3.0, 4.0]), np.array([0.0, 2.5, 3.5])])
    assert np.allclose(x, target, atol=1e-9) and starts_seen[0][0] == 2.0 and starts_seen[1][0] == 0.0
    with pytest.raises(SolverError, match="no steady state"):
        _newton_from(point, [np.array([2.0, 3.0, 4.0]), np.array([3.0, 3.0, 4.0])])  # neither: the last's error


def test_a_count_newton_missed_is_tried_again_from_the_design_of_more_cyclones(monkeypatch):
    """One cyclone whose Newton fails from its first guess (here: a 100-m mill guessed, outside
    what the models take) is tried again from the two-cyclone design point, and the sizing keeps
    the fewest cyclones: the design it finds from a good guess."""
    import twin.sizing as sizing

    good = sizing.size_mill()
    assert good.cyclone["count"] == 1
    first_guess = sizing._first_guess

    def bad_for_one(design, base, count, *args):
        x = first_guess(design, base, count, *args)
        return np.array([math.log(100.0), *x[1:]]) if count == 1 else x

    monkeypatch.setattr(sizing, "_first_guess", bad_for_one)
    sized = sizing.size_mill()
    assert sized.cyclone["count"] == 1 and sized.p80_um == pytest.approx(210.0, rel=1e-4)
    assert sized.mill.diameter_m == pytest.approx(good.mill.diameter_m, rel=1e-4)
    one = sized.tried[0]
    assert one["outcome"].startswith("design (from the 2-cyclone design point; from its own first guess, no design")
