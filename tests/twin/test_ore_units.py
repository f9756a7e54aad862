"""Ore data in the wrong unit, or with one label spelt two ways, is refused instead of giving a number.

Each case gave a plausible-looking result before (exit 0): a load in N gave fused silica H = 0.009 GPa;
energies in kWh/t gave E50 = 0.09 J/kg; sizes in um a 21800 mm class; 'B', ' B' and 'b' three ore types.
"""

import numpy as np
import pandas as pd
import pytest

from twin.errors import TwinInputError
from twin.ore.fracture_energy import (FRACTURE_ENERGY_RANGE_J_KG, PARTICLE_SIZE_RANGE_MM, fit_breakage_outcomes,
                                      fit_by_group, read_single_particle, sample_fracture_energies,
                                      validate_single_particle)
from twin.ore.indentation import (HARDNESS_RANGE_GPA, INDENTER_YOUNGS_RANGE_GPA, REDUCED_MODULUS_RANGE_GPA,
                                  Indenter, analyse_curves, oliver_pharr, read_curves, synthesize_curve)

KWH_T_IN_J_KG = 3600.0  # 1 kWh/t = 3.6e6 J / 1e3 kg


def _curve_file(tmp_path, frame, name="curves.csv"):
    p = tmp_path / name
    p.write_text(frame[["curve_id", "depth_nm", "load_mn"]].to_csv(index=False))
    return p


def test_indentation_load_in_newtons_is_refused_with_curve_value_range_and_unit(tmp_path):
    c = synthesize_curve(72.0, 9.0, sample_poisson=0.17).assign(curve_id="fs-1")
    assert analyse_curves(_curve_file(tmp_path, c)).hardness_gpa.iloc[0] == pytest.approx(9.0, rel=1e-3)
    in_n = c.assign(load_mn=c.load_mn / 1000.0)  # 10 mN written as 0.01 (N)
    with pytest.raises(TwinInputError) as err:
        analyse_curves(_curve_file(tmp_path, in_n))
    msg = str(err.value)
    assert "curve_id 'fs-1'" in msg and "hardness 0.009 GPa" in msg
    assert f"[{HARDNESS_RANGE_GPA[0]:g}, {HARDNESS_RANGE_GPA[1]:g}] GPa" in msg
    assert "load in N, not mN" in msg


def test_indentation_load_slip_caught_on_the_hardest_common_mineral_by_the_modulus():
    """Corundum-like H = 30 GPa / 1000 lies inside the hardness range; E_r / 1000 does not."""
    c = synthesize_curve(400.0, 30.0, sample_poisson=0.23)
    assert HARDNESS_RANGE_GPA[0] < 30.0 / 1000.0
    with pytest.raises(TwinInputError, match=r"reduced modulus 0\.\d+ GPa outside \[0.5, 600\] GPa"):
        oliver_pharr(c.load_mn / 1000.0, c.depth_nm, sample_poisson=0.23)


@pytest.mark.parametrize("load_factor, depth_factor, unit", [
    (1e3, 1.0, "load in uN, not mN"),       # uN written as mN: H and E_r x 1000
    (1.0, 1e-3, "depth in um, not nm"),     # um written as nm: H and E_r x 1e6
])
def test_indentation_values_above_every_mineral_name_the_unit(load_factor, depth_factor, unit):
    c = synthesize_curve(33.8, 1.1, sample_poisson=0.25)   # biotite-like, soft
    with pytest.raises(TwinInputError, match=unit):
        oliver_pharr(c.load_mn * load_factor, c.depth_nm * depth_factor)


def test_indentation_ranges_hold_the_minerals_of_the_table():
    """The softest and the stiffest phases of minerals.csv, and diamond under diamond, pass."""
    for E, H, nu in ((3.2, 0.25, 0.30), (305.9, 14.9, 0.15), (1141.0, 100.0, 0.07)):
        r = oliver_pharr(*synthesize_curve(E, H, sample_poisson=nu)[["load_mn", "depth_nm"]].T.to_numpy(),
                         sample_poisson=nu)
        assert HARDNESS_RANGE_GPA[0] < r.hardness_gpa < HARDNESS_RANGE_GPA[1]
        assert REDUCED_MODULUS_RANGE_GPA[0] < r.reduced_modulus_gpa < REDUCED_MODULUS_RANGE_GPA[1]


def test_curve_id_with_a_stray_space_stays_one_curve(tmp_path):
    c = synthesize_curve(72.0, 9.0, sample_poisson=0.17).assign(curve_id="fs-1")
    spaced = c.copy()
    spaced.loc[len(c) // 2:, "curve_id"] = " fs-1"   # split one curve into a loading and an unloading part
    curves = read_curves(_curve_file(tmp_path, spaced))
    assert list(curves) == ["fs-1"] and len(curves["fs-1"]) == len(c)
    cased = c.assign(curve_id=["fs-1"] * (len(c) // 2) + ["FS-1"] * (len(c) - len(c) // 2))
    with pytest.raises(TwinInputError, match=r"'fs-1' \(row 1\) and 'FS-1' \(row \d+\)"):
        read_curves(_curve_file(tmp_path, cased))


def _particles(ore_types, size_mm=21.8, scale=1.0):
    e = sample_fracture_energies(len(ore_types), 55.0, 0.4, random_state=3)
    return pd.DataFrame({"particle_id": [f"p{i}" for i in range(len(ore_types))], "ore_type": ore_types,
                         "size_mm": size_mm, "fracture_energy_j_kg": e * scale})


def test_single_particle_energy_in_kwh_t_is_refused(tmp_path):
    p = tmp_path / "spt.csv"
    _particles(["B"] * 10, scale=1.0 / KWH_T_IN_J_KG).to_csv(p, index=False)
    with pytest.raises(TwinInputError) as err:
        read_single_particle(p)
    msg = str(err.value)
    assert "row 1 (particle_id='p0'): column 'fracture_energy_j_kg'" in msg
    assert f"[{FRACTURE_ENERGY_RANGE_J_KG[0]:g}, {FRACTURE_ENERGY_RANGE_J_KG[1]:g}] J/kg" in msg
    assert "in kWh/t? x 3600" in msg


def test_single_particle_size_in_um_is_refused():
    with pytest.raises(TwinInputError) as err:
        validate_single_particle(_particles(["B"] * 4, size_mm=21800.0))
    msg = str(err.value)
    assert "column 'size_mm'" in msg and "21800.0" in msg and "in um? / 1000 to mm" in msg
    assert f"[{PARTICLE_SIZE_RANGE_MM[0]:g}, {PARTICLE_SIZE_RANGE_MM[1]:g}] mm" in msg
    assert len(validate_single_particle(_particles(["B"] * 4, size_mm=21.8))) == 4


def test_ore_type_spaces_stripped_and_case_twins_refused(tmp_path):
    p = tmp_path / "spt.csv"
    _particles(["B", "B", " B", "B ", "B", "B"]).to_csv(p, index=False)
    fits = fit_by_group(read_single_particle(p))
    assert fits.ore_type.tolist() == ["B"] and fits.n.tolist() == [6]
    _particles(["B", "B", " B", "b ", "B", "B"]).to_csv(p, index=False)
    with pytest.raises(TwinInputError, match=r"'B' \(row 1\) and 'b' \(row 4, 'b ' before stripping\)"):
        read_single_particle(p)
    with pytest.raises(TwinInputError, match=r"column 'ore_type' must be a non-empty label\. Got ' '"):
        validate_single_particle(_particles(["B", " ", "B"]))


@pytest.mark.parametrize("youngs", [1141e9, 1.141])   # diamond in Pa, in TPa
def test_indenter_modulus_in_another_unit_is_refused(youngs):
    """In Pa, the indenter's compliance vanished and fused silica's E came out 67.6 instead of 72 GPa."""
    with pytest.raises(TwinInputError, match=r"'youngs_gpa' parameter of Indenter must be .*\[100, 1300\]"):
        Indenter(youngs_gpa=youngs)
    assert Indenter(youngs_gpa=INDENTER_YOUNGS_RANGE_GPA[0]).youngs_gpa == 100.0


def test_drop_weight_energies_in_kwh_t_are_refused():
    """Drop-weight energies are reported as Ecs in kWh/t: E50 came out 3600x low, labelled J/kg."""
    levels = np.repeat([40.0, 70.0, 110.0, 170.0, 260.0, 400.0], 20)     # J/kg
    broken = sample_fracture_energies(len(levels), 120.0, 0.6, random_state=21) <= levels
    assert fit_breakage_outcomes(levels, broken).e50_j_kg > FRACTURE_ENERGY_RANGE_J_KG[0]
    with pytest.raises(TwinInputError, match=r"energies_j_kg\[0\]' .*in \[1, 100000\] J/kg.*in kWh/t\? x 3600"):
        fit_breakage_outcomes(levels / KWH_T_IN_J_KG, broken)


def test_a_unit_slip_on_every_row_lists_fifty_and_counts_the_rest():
    many = pd.concat([_particles(["B"] * 10, scale=1.0 / KWH_T_IN_J_KG)] * 8, ignore_index=True)
    with pytest.raises(TwinInputError, match=r"80 problem\(s\)") as err:
        validate_single_particle(many)
    assert str(err.value).count("column 'fracture_energy_j_kg'") == 50 and "... and 30 more" in str(err.value)
