"""The reverse closed circuit (classification option ``circuit = "reverse"``): fresh feed to the
cyclone feed sump, the mill fed by the underflow alone. Checked by conservation (solids, water),
a limiting classifier that sends everything to the overflow (the product is then the fresh
feed itself) and the refusals of options that do not belong together."""

from __future__ import annotations

import pytest

from twin import ModelError, Twin, TwinInputError, pxx_um
from twin.effects.classification import solids_volume_pct

FEED = 31.0
#: A surveyed cyclone given directly (fixed cut), so the limits below are exact.
DIRECT = {"count": 1, "d50c_um": 350.0, "sharpness": 1.4, "water_bypass_frac": 0.35, "feed_solids_frac": 0.65}


def circuit(circuit="reverse", **options) -> Twin:
    return Twin("B", mill="industrial", effect_options={"classification": {
        "kind": "hydrocyclone", "circuit": circuit, **options}})


@pytest.fixture(scope="module")
def reverse():
    tw = circuit(cyclone=DIRECT)
    return tw, tw.steady(feed_tph=FEED)


def test_the_product_is_the_fresh_feed_and_the_mill_is_fed_by_the_underflow(reverse):
    tw, ss = reverse
    o = ss.outputs
    assert o["throughput_tph"] == pytest.approx(FEED, rel=1e-8)
    # the mill's discharge is its feed, the underflow: D = U = CL F (a direct circuit's is F + U)
    assert o["discharge_tph"] == pytest.approx(o["circulating_load_frac"] * FEED, rel=1e-8)
    assert any("reverse circuit" in t.what for t in tw.model.terms)


def test_water_in_is_water_out_and_a_wet_feed_takes_its_water_from_the_sumps_addition(reverse):
    _, dry = reverse
    o = dry.outputs
    assert o["mill_water_m3_h"] + o["sump_water_m3_h"] == pytest.approx(o["overflow_water_m3_h"], rel=1e-9)
    wet = circuit(cyclone=DIRECT, fresh_feed_solids_frac=0.8).steady(feed_tph=FEED).outputs
    assert wet["sump_water_m3_h"] == pytest.approx(o["sump_water_m3_h"] - FEED * 0.2 / 0.8, rel=1e-9)
    assert wet["mill_water_m3_h"] == pytest.approx(o["mill_water_m3_h"], rel=1e-9)
    assert wet["throughput_tph"] == pytest.approx(FEED, rel=1e-8)


def test_a_classifier_that_keeps_nothing_passes_the_fresh_feed_through_unground():
    """A cut far above the feed's top size and no bypass to the underflow: in a reverse circuit
    the fresh feed leaves as product as it came; in a direct one it is ground first."""
    none_kept = {**DIRECT, "d50c_um": 5e4, "sharpness": 6.0, "water_bypass_frac": 1e-6, "solids_bypass_frac": 1e-6}
    tw = circuit(cyclone=none_kept)
    ss = tw.steady(feed_tph=FEED)
    assert ss.outputs["circulating_load_frac"] < 1e-5
    assert ss.p80_um == pytest.approx(pxx_um(tw.grid, tw.spec.feed_frac), rel=1e-4)
    direct = circuit("direct", cyclone=none_kept).steady(feed_tph=FEED)
    assert direct.p80_um < 0.5 * ss.p80_um


@pytest.mark.parametrize("options,fragment", [
    ({"kind": "grate", "circuit": "reverse"}, "options of kind = 'hydrocyclone'"),
    ({"kind": "hydrocyclone", "fresh_feed_solids_frac": 0.7}, "Set 'circuit' = 'reverse'"),
    ({"kind": "hydrocyclone", "circuit": "revers"}, "Did you mean 'reverse'?"),
])
def test_options_that_do_not_belong_together_are_refused(options, fragment):
    with pytest.raises(ModelError) as info:
        Twin("B", mill="industrial", effect_options={"classification": options})
    assert fragment in str(info.value)


def test_a_mill_sized_for_a_reverse_circuit_meets_its_design_point_in_that_circuit():
    """size_mill(circuit="reverse"): the sized mill and cyclones, run again as a reverse circuit,
    hold the target at the design circulating load and pressure; run as a direct circuit they miss
    them (the sizing used the circuit it was asked for)."""
    from twin.sizing import DESIGN_CIRCULATING_LOAD, DESIGN_CYCLONE_PRESSURE_KPA, circuit_twin, size_mill

    sized = size_mill("B", FEED, 210.0, circuit="reverse")
    assert sized.circuit["circuit"] == "reverse"
    ss = circuit_twin("B", sized.mill, sized.cyclone, "reverse").steady(feed_tph=FEED)
    assert ss.p80_um == pytest.approx(210.0, rel=1e-3)
    assert ss.outputs["circulating_load_frac"] == pytest.approx(DESIGN_CIRCULATING_LOAD, rel=1e-3)
    assert ss.outputs["cyclone_pressure_kpa"] == pytest.approx(DESIGN_CYCLONE_PRESSURE_KPA, rel=1e-3)
    direct = circuit_twin("B", sized.mill, sized.cyclone, "direct").steady(feed_tph=FEED).outputs
    assert abs(direct["circulating_load_frac"] / DESIGN_CIRCULATING_LOAD - 1) > 0.1  # 1.85 here
    assert abs(direct["cyclone_pressure_kpa"] / DESIGN_CYCLONE_PRESSURE_KPA - 1) > 0.1
    with pytest.raises(TwinInputError, match="'circuit' parameter of size_mill must be one of 'direct', 'reverse'"):
        size_mill("B", FEED, 210.0, circuit="closed")


def test_a_mill_sized_in_one_circuit_says_so_when_run_in_another(tmp_path, monkeypatch):
    """A preset written with --circuit reverse recorded its circuit, which loading ignored: a
    hydrocyclone twin ran its cyclones (sized for fresh feed to the sump) in the direct circuit
    without a word. The preset's circuit is now the mill's (Mill.cyclone_circuit), and a twin
    running another, or the grate, notes it."""
    import json

    import twin.mill as M

    record = json.loads(M.INDUSTRIAL_PRESET_PATH.read_text())
    assert record["sizing"]["circuit"] == "direct" and M.industrial_preset().cyclone_circuit == "direct"
    record["sizing"]["circuit"] = "reverse"
    path = tmp_path / "preset.json"
    path.write_text(json.dumps(record))
    try:
        with monkeypatch.context() as m:
            m.setattr(M, "INDUSTRIAL_PRESET_PATH", path)
            M.industrial_preset.cache_clear()
            assert M.industrial_preset().cyclone_circuit == "reverse"
            other = "were sized in a reverse circuit; this runs them in a direct one"
            assert any(other in n for n in circuit("direct").notes)
            assert not any("sized" in n for n in circuit("reverse").notes)
            assert any("this is its grate discharge" in n for n in Twin("B", mill="industrial").notes)
            with pytest.raises(TwinInputError, match="'cyclone_circuit'.*'sideways'"):
                M.industrial_preset().with_(cyclone_circuit="sideways")
    finally:
        M.industrial_preset.cache_clear()


def test_any_cyclone_circuit_notes_a_roping_underflow_not_only_a_sizing():
    """The roping note (twin.validity.roping_note) was a sizing's alone: a scene or a Python twin
    running the shipped preset's own cyclones, at 81.8 % solids by mass in the underflow, said
    nothing. A surveyed cyclone with a dilute underflow is not noted."""
    ss = circuit("direct").steady(feed_tph=FEED)
    assert ss.outputs["underflow_solids_frac"] > 0.8
    assert any("at which hydrocyclones rope" in n for n in ss.notes)
    tw = circuit("direct", cyclone={**DIRECT, "water_bypass_frac": 0.6})
    dilute = tw.steady(feed_tph=FEED)
    assert solids_volume_pct(dilute.outputs["underflow_solids_frac"], tw.spec.solids_density_t_m3) < 50.0
    assert not any("rope" in n for n in dilute.notes)


def test_a_cyclone_in_metres_notes_its_pressure():
    """A cyclone's sizes in m for cm (0.41 for a 41-cm cyclone) ran Plitt's pressure to ~1e9 kPa with no word;
    a steady state now notes a feed pressure outside the 5-40 psi cyclones run at. The preset's own cyclones
    (53 kPa) are not noted; neither is a survey's 7.7 psi given in kPa (52 kPa), but 7.7 kPa is."""
    from twin import get_mill
    from twin.validity import pressure_note

    assert not any("cyclone feed pressure" in n for n in circuit("direct").steady(feed_tph=FEED).notes)
    sizes = ("diameter_cm", "inlet_cm", "vortex_finder_cm", "apex_cm", "free_vortex_height_cm")
    metres = {k: (v / 100.0 if k in sizes else v) for k, v in dict(get_mill("industrial").cyclone).items()
              if v is not None}
    ss = circuit("direct", cyclone=metres).steady(feed_tph=FEED)
    assert ss.outputs["cyclone_pressure_kpa"] > 1e6
    assert any(n.startswith("the cyclone feed pressure is") and "sizes in cm" in n for n in ss.notes)
    assert pressure_note({"cyclone_pressure_kpa": 7.7 * 6.894757}) == ""
    assert "7.7 kPa" in pressure_note({"cyclone_pressure_kpa": 7.7})


def test_an_empty_circuit_has_no_cyclone_pressure_to_note():
    """At zero feed the steady circuit is empty and the cyclones get nothing: the model's floored flow gave them
    1e-9 kPa, and a laboratory mill with cyclones (whose pressure at the nominal feed is outside the range) was asked
    whether its cyclone's sizes were in cm. The note reads a state with a product; a fed state keeps it."""
    from twin import Twin

    tw = Twin("B", mill="lab", effect_options={"classification": {"kind": "hydrocyclone"}})
    fed, empty = tw.steady(), tw.steady(feed_tph=0.0)
    assert any(n.startswith("the cyclone feed pressure is") for n in fed.notes)
    assert empty.outputs["throughput_tph"] == 0.0 and not any("cyclone feed pressure" in n for n in empty.notes)


@pytest.mark.parametrize("kind", ["reverse", "direct"])
def test_a_run_reports_the_mills_discharge_and_the_cyclone_feed_apart(kind):
    """A reverse circuit's streams.csv gave the cyclone feed (discharge + fresh feed) as the mill discharge:
    652.6 t/h against the mill's own 402.6 t/h in summary.json and steady."""
    from scenarios.run.streams import size_by_size

    tw = circuit(kind, cyclone=DIRECT)
    ss = tw.steady(feed_tph=FEED)
    t = size_by_size(tw.model, ss.x, ss.u, ss.d, batch=False)
    assert t["mill_discharge_tph"].sum() == pytest.approx(ss.outputs["discharge_tph"], rel=1e-9)
    fresh = t["fresh_feed_tph"] if kind == "reverse" else 0.0
    assert (t["cyclone_feed_tph"] - t["mill_discharge_tph"] - fresh).abs().max() < 1e-9 * FEED
    assert t["cyclone_feed_tph"].to_numpy() == pytest.approx((t["cyclone_underflow_tph"] + t["product_tph"]).to_numpy())


def test_a_cyclone_table_that_leaves_out_the_sized_keys_says_they_are_defaults():
    """A sweep over one cyclone key (`--vary effect_options.classification.cyclone.apex_cm=7,9`) ran the default
    2 x 38-cm cyclone at 30 % solids, not the sized mill's, and the mill overloaded without a word: the note names
    every sized key the table leaves out, with the default that ran and the sized value; a full table says nothing."""
    from twin import get_mill

    partial = Twin("B", mill="industrial", effect_options={"classification": {
        "kind": "hydrocyclone", "cyclone": {"apex_cm": 9.0}}}).notes
    note = [n for n in partial if "replaces mill 'industrial''s sized cyclones whole" in n]
    assert len(note) == 1 and "diameter_cm 38.0 for 40.94" in note[0] and "count 2 for 1" in note[0]
    full = {k: v for k, v in get_mill("industrial").cyclone if v is not None}
    assert not any("replaces" in n for n in Twin("B", mill="industrial", effect_options={"classification": {
        "kind": "hydrocyclone", "cyclone": {**full, "apex_cm": 9.0}}}).notes)


def test_a_runs_cyclone_notes_quote_the_worst_sample_and_blame_units_only_when_they_explain_it():
    """A feed stop's note quoted the stretch's last sample (31 kPa) where the pressure fell to 0.085 kPa, and asked
    whether it was psi: the notes now quote the stretch's worst sample and when; a pressure outside the range
    whose cyclones run within it at the nominal feed is the flow's (no units question), one whose cyclones are
    outside it at the nominal feed too (a survey's 7.7 psi read as kPa) is asked about its units."""
    from types import SimpleNamespace

    import pandas as pd

    from twin import trajectory_notes

    rho = 2.7
    spec = SimpleNamespace(holdup_nominal_t=50.0, feed_nominal_tph=30.0, solids_density_t_m3=rho, coefficients={})
    frame = pd.DataFrame({"time_h": [0.0, 0.5, 1.0, 1.5, 2.0],
                          "cyclone_pressure_kpa": [60.0, 20.0, 0.085, 31.0, 31.0],
                          "underflow_solids_frac": [0.5, 0.86, 0.80, 0.78, 0.77]})
    notes = trajectory_notes(frame, spec, (), nominal_pressure_kpa=60.0)
    (pressure,) = [n for n in notes if "cyclone feed pressure" in n]
    assert pressure.startswith("from 0.5 h to 2 h (4 of 5 samples; at worst, at 1 h) the cyclone feed pressure is "
                               "0.085 kPa")
    assert "feed stop" in pressure and "psi?" not in pressure and "31 kPa" not in pressure
    (rope,) = [n for n in notes if "rope" in n]
    worst_vol_pct = 100 * (0.86 / rho) / (0.86 / rho + 0.14)  # water 1 t/m3; 0.5 by mass is 27 % by volume
    assert "at worst, at 0.5 h" in rope and f"underflow is {worst_vol_pct:.3g} % solids by volume" in rope
    for units in (None, 60.0 / 6.894757):  # unknown, or out of range at the nominal feed too (psi read as kPa)
        (asked,) = [n for n in trajectory_notes(frame, spec, (), nominal_pressure_kpa=units) if "pressure" in n]
        assert "0.085 kPa" in asked and "not psi?" in asked


@pytest.mark.parametrize("kind", ["reverse", "direct"])
def test_every_streams_cumulative_passing_of_the_top_size_is_exactly_100_percent(kind):
    """streams.csv gave 100.00000000000003 % or 99.99999999999999 % passing the top size (and the next, with
    nothing above it): all of a stream passes them, so they are 100 exactly, never above, in the size-by-size
    table and the size snapshots alike; below them the passing is the retained masses' sum, as before."""
    from scenarios.run.streams import _passing, size_by_size

    tw = circuit(kind)
    ss = tw.steady(feed_tph=FEED)
    t = size_by_size(tw.model, ss.x, ss.u, ss.d, batch=False)
    streams = [c.removesuffix("_passing_pct") for c in t.columns if c.endswith("_passing_pct")]
    assert len(streams) >= 5
    for s in streams:
        passing = t[f"{s}_passing_pct"].to_numpy()
        assert passing[0] == 100.0 and passing.max() == 100.0, s
        retained = t[f"{s}_retained_pct"].to_numpy()
        assert passing[1:] == pytest.approx(retained[::-1].cumsum()[::-1][1:], rel=1e-12), s
    assert _passing(tw.spec.grid, ss.psd)[0] == 1.0
