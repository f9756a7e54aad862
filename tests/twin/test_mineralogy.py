import math

import pytest

from twin.errors import TwinInputError
from twin.mill import LAB, bond_power_kw
from twin.ore.mineralogy import Mineralogy, Texture
from twin.ore.minerals import mineral_table, source_table
from twin.ore.ores import Blend, load_ore, reference_ores

REQUIRED = ["quartz", "k_feldspar", "plagioclase", "biotite", "muscovite", "chlorite", "kaolinite",
            "illite", "pyrite", "chalcopyrite", "bornite", "magnetite", "calcite"]


def test_table_has_required_minerals_each_value_sourced():
    table, sources = mineral_table(), source_table()
    for name in REQUIRED:
        m = table[name]
        for prop in ("density", "hardness", "modulus"):
            assert m.sources[prop] in sources
        if not math.isnan(m.bond_wi_kwh_t):
            assert m.sources["bond_wi"] in sources


def test_hardness_index_is_the_weighted_sum():
    m = Mineralogy({"quartz": 50.0, "kaolinite": 50.0}, Texture(100.0))
    t = mineral_table()
    assert m.hardness_index_gpa == pytest.approx(0.5 * t["quartz"].vickers_gpa + 0.5 * t["kaolinite"].vickers_gpa)


def test_reference_ores_lie_in_mission_table_ranges():
    ranges = {"A": ((55, 65), (0, 5), (8, 12), (180, 250)), "B": ((35, 45), (5, 10), (12, 18), (100, 150)),
              "C": ((20, 30), (25, 35), (5, 10), (50, 80)), "D": ((15, 25), (30, 40), (8, 15), (30, 60))}
    for name, ore in reference_ores().items():
        (q0, q1), (c0, c1), (s0, s1), (g0, g1) = ranges[name]
        assert q0 <= 100 * ore.fraction("quartz") <= q1
        assert c0 <= 100 * ore.clay_frac <= c1
        assert s0 <= 100 * ore.sulfide_frac <= s1
        assert g0 <= ore.texture.mean_grain_um <= g1
    h = [reference_ores()[k].hardness_index_gpa for k in "ABCD"]
    assert h == sorted(h, reverse=True)  # A hardest, D softest


def test_unknown_mineral_suggests_close_match():
    with pytest.raises(TwinInputError, match="Unknown mineral 'qartz'.*Did you mean 'quartz'"):
        Mineralogy({"qartz": 100.0})


def test_sum_must_be_100_within_tolerance():
    with pytest.raises(TwinInputError, match="must sum to 100 within 0.5 wt%. Got 97.000"):
        Mineralogy({"quartz": 97.0})
    assert Mineralogy({"quartz": 99.8}).fraction("quartz") == pytest.approx(1.0)


def test_negative_wt_is_rejected():
    with pytest.raises(TwinInputError, match=r"'wt_pct\[pyrite\]' parameter of Mineralogy must be a finite number >= 0"):
        Mineralogy({"quartz": 101.0, "pyrite": -1.0})


def test_blend_parse_and_validation():
    b = Blend.parse("B=0.6,D=0.4")
    assert b.names == ["B", "D"] and b.fractions == (0.6, 0.4)
    with pytest.raises(TwinInputError, match="must sum to 1"):
        Blend.parse("B=0.6,D=0.3")
    with pytest.raises(TwinInputError, match="reference type .*Got 'E'"):
        load_ore("E")


def test_bond_power_of_lab_mill_is_a_few_hundred_watts():
    # Bond's equation (before any calibration factor): 0.5 m x 0.3 m, J = 0.35, 70 % critical
    assert 0.25 < bond_power_kw(LAB.with_(power_factor=1.0), 0.70) < 0.45


def test_hogg_fuerstenau_power_agrees_with_bond_for_the_lab_mill_and_scales_as_d25_l():
    from twin.mill import INDUSTRIAL_BASE, hogg_fuerstenau_power_kw

    lab = LAB.with_(power_factor=1.0)
    hf, bond = hogg_fuerstenau_power_kw(lab, 0.70), bond_power_kw(lab, 0.70)
    assert hf == pytest.approx(bond, rel=0.05)  # two independent published models, 0.5 m mill
    big = INDUSTRIAL_BASE.with_(power_factor=1.0)
    ratio = (big.diameter_m / lab.diameter_m) ** 2.5 * big.length_m / lab.length_m
    assert hogg_fuerstenau_power_kw(big, 0.70) == pytest.approx(hf * ratio, rel=1e-12)


def test_power_effect_model_option():
    from twin.errors import ModelError
    from twin.twin import DEFAULT_EFFECTS, Twin

    hf = Twin("B", effect_options={"power": {"model": "hogg_fuerstenau"}}).steady()
    bond = Twin("B").steady()
    assert hf.outputs["power_kw"] == pytest.approx(bond.outputs["power_kw"], rel=0.05)
    with pytest.raises(ModelError, match="'model' option of effect 'power' must be one of"):
        Twin("B", effects=list(DEFAULT_EFFECTS), effect_options={"power": {"model": "morrell"}})
