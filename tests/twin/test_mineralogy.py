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


@pytest.mark.parametrize("mill_name", ["lab", "industrial"])
def test_bond_power_is_bonds_own_in_us_units_and_gupta_yans_with_the_balls_density(mill_name):
    """Bond's (1961) power per short ton of balls, 3.1 D_ft^0.3 (3.2 - 3 J) phi (1 - 0.1/2^(9 - 10
    phi)) kW with D in ft, times the ball bed's weight in short tons at its bulk density, computed
    in US units; and Gupta & Yan's (2016, eq. 9.28) 7.33 J phi (1 - 0.937 J) (...) rho_b L D^2.3 with
    rho_b the balls' own density (7.8 t/m3 for steel). The bulk density in the latter gave 0.6x."""
    from twin.mill import get_mill

    m = get_mill(mill_name).with_(power_factor=1.0)
    J, phi, ft, short_t = m.ball_filling_frac, 0.70, 0.3048, 0.90718474
    speed = phi * (1 - 0.1 / 2 ** (9 - 10 * phi))
    d_ft, l_ft = m.diameter_m / ft, m.length_m / ft
    balls_short_t = J * math.pi / 4 * d_ft ** 2 * l_ft * ft ** 3 * m.ball_bulk_density_t_m3 / short_t
    bond_us = 3.1 * d_ft ** 0.3 * (3.2 - 3 * J) * speed * balls_short_t
    assert bond_power_kw(m, phi) == pytest.approx(bond_us, rel=2e-3)
    gupta_yan = 7.33 * J * (1 - 0.937 * J) * speed * m.ball_density_t_m3 * m.length_m * m.diameter_m ** 2.3
    assert bond_power_kw(m, phi) == pytest.approx(gupta_yan, rel=5e-3)


def test_hogg_fuerstenau_power_scales_as_d25_l():
    from twin.mill import INDUSTRIAL_BASE, hogg_fuerstenau_power_kw

    lab = LAB.with_(power_factor=1.0)
    hf = hogg_fuerstenau_power_kw(lab, 0.70)
    big = INDUSTRIAL_BASE.with_(power_factor=1.0)
    ratio = (big.diameter_m / lab.diameter_m) ** 2.5 * big.length_m / lab.length_m
    assert hogg_fuerstenau_power_kw(big, 0.70) == pytest.approx(hf * ratio, rel=1e-12)


def test_power_effect_model_option():
    from twin.errors import ModelError
    from twin.twin import DEFAULT_EFFECTS, Twin

    from twin.mill import hogg_fuerstenau_power_kw

    hf = Twin("B", effect_options={"power": {"model": "hogg_fuerstenau"}}).steady()
    bond = Twin("B").steady()
    # the option swaps the model and nothing else: the same factors (the mill's fitted power factor,
    # the slurry's) multiply both, so their ratio is the models' own (H&F's at 35 deg is 0.59x Bond's
    # in the 0.5-m mill: Bond's correlation is an industrial one)
    speed = LAB.speed_nominal_frac_critical
    ratio = hogg_fuerstenau_power_kw(LAB, speed) / bond_power_kw(LAB, speed)
    assert hf.outputs["power_kw"] / bond.outputs["power_kw"] == pytest.approx(ratio, rel=1e-3)
    with pytest.raises(ModelError, match="'model' option of effect 'power' must be one of"):
        Twin("B", effects=list(DEFAULT_EFFECTS), effect_options={"power": {"model": "morrell"}})
