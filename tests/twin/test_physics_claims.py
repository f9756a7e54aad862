"""MISSION.md's physics claims as predictions of the default calibration (the DEM chain), each
beside a plausible wrong model under which the same check fails: the checks discriminate.

All at MISSION.md's laboratory conditions: the lab mill at 70 % of critical speed, constant
load (the table's throughput) unless a feed rate is named."""

import numpy as np
import pytest

from twin import BreakageParams, Mineralogy, Twin, load_ore
from twin.sizes import pxx_um
from twin.twin import DEFAULT_EFFECTS

#: A blend interaction counts when a component's content P80 moves by more than this share.
INTERACTION_MIN_REL = 0.02


def _at_load(ore, **twin_kwargs):
    ss = Twin(ore, **twin_kwargs).steady_at_constant_load(0.70)
    return {"p80_um": ss.p80_um, "energy": ss.outputs["specific_energy_kwh_t"], "throughput": ss.feed_tph}


def pyrite_for_biotite(points: float = 15.0) -> Mineralogy:
    """Type B with ``points`` wt% more pyrite and as much less biotite (scenarios/pyrite_surge.toml)."""
    b = load_ore("B")
    wt = dict(b.wt_pct, pyrite=b.wt_pct["pyrite"] + points, biotite=b.wt_pct["biotite"] - points)
    return Mineralogy(wt, b.texture, name="B_pyrite")


def pyrite_claim(**twin_kwargs) -> dict:
    """MISSION.md: energy up and product (slightly) finer when pyrite replaces biotite in Type B;
    ``slows``: the throughput at constant load falls too (issue 12's reading of a harder ore);
    ``volume_throughput``: the change of the ore volume ground per hour (tonnes over density)."""
    ores = load_ore("B"), pyrite_for_biotite()
    ref, pyr = (_at_load(o, **twin_kwargs) for o in ores)
    change = {k: pyr[k] / ref[k] - 1.0 for k in ref}
    change["holds"] = change["energy"] > 0 and change["p80_um"] < 0
    change["slows"] = change["throughput"] < 0
    change["volume_throughput"] = (1.0 + change["throughput"]) * ores[0].density_t_m3 / ores[1].density_t_m3 - 1.0
    return change


def clay_claim(**twin_kwargs) -> dict:
    """From quartz-rich A to clay-rich D (a mixing path): energy falls at every step, by 30-60 %
    in all (MISSION.md: up to ~45 %), while the product coarsens."""
    a, d = load_ore("A"), load_ore("D")
    path = [a, a.mix(d, 0.75), a.mix(d, 0.5), a.mix(d, 0.25), d]
    kpis = [_at_load(o, **twin_kwargs) for o in path]
    energy = [k["energy"] for k in kpis]
    cut = 1.0 - energy[-1] / energy[0]
    holds = all(np.diff(energy) < 0) and 0.30 <= cut <= 0.60 and kpis[-1]["p80_um"] > 1.1 * kpis[0]["p80_um"]
    return {"energy_cut": cut, "p80_a_um": kpis[0]["p80_um"], "p80_d_um": kpis[-1]["p80_um"], "holds": holds}


def _mineralogy_blind(ore, coefficients):
    """A wrong map: every ore breaks like Type B (the DEM chain's B parameters)."""
    return Twin("B").calibration.breakage(load_ore("B"))


#: The wrong model's effects: no soft charge (cushioning) and no slurry rheology.
BLIND_EFFECTS = [e for e in DEFAULT_EFFECTS if e not in ("cushioning", "rheology")]


def test_pyrite_for_biotite_raises_energy_and_refines_slightly():
    claim = pyrite_claim()
    assert claim["holds"], claim
    assert claim["p80_um"] > -0.15  # "slightly" finer


def test_pyrite_for_biotite_slows_the_mill_in_tonnes_and_more_in_volume():
    """Issue 12: pyrite for biotite lowers the throughput at constant load. The constant load is
    a volume (the nominal powder filling) and the mill discharges a volume flow (le Roux et al.
    2013, eq. 9; twin.mill.Mill.free_discharge_tph), so the ore's 5.9 % higher density (3.07
    against 2.90 t/m3) alone adds as many tonnes per hour; the harder ore (hardness index 8.0 ->
    10.1 GPa) breaking more slowly, which the lost mica cushioning only partly offsets, and the
    grate holding the denser ore back take more than that away: the tonnes fall, the ore volume
    ground per hour falls further."""
    claim = pyrite_claim()
    assert claim["volume_throughput"] < claim["throughput"] < 0, claim


def test_pyrite_for_biotite_leaves_the_power_and_raises_the_energy_by_the_tonnes():
    """The power follows the slurry's clay (twin.effects.rheology), which pyrite for biotite does
    not change, so the energy rise is exactly the same power over fewer tonnes:
    1 / (1 + throughput change) - 1. Fails on a model whose power moves with the mica."""
    claim = pyrite_claim()
    assert claim["energy"] == pytest.approx(1.0 / (1.0 + claim["throughput"]) - 1.0, rel=1e-9)


def test_pyrite_claim_fails_without_the_grate_holding_dense_ore_back(monkeypatch):
    """With the grate a cut by size only (no Stokes density term), the harder pyrite ore still
    costs more energy but leaves coarser: the refinement is the dense ore's hold-back."""
    import twin.effects.classification as classification

    monkeypatch.setattr(classification, "STOKES_DENSITY_EXPONENT", 0.0)
    claim = pyrite_claim()
    assert not claim["holds"] and claim["p80_um"] > 0, claim


def test_pyrite_claim_fails_for_a_mineralogy_blind_twin():
    assert not pyrite_claim(effects=BLIND_EFFECTS, breakage_map=_mineralogy_blind)["holds"]


def test_pyrite_claim_fails_for_the_plain_table_regression():
    """The 'table' calibration fits hardness out of the rates, and its S^E is per tonne whatever the
    density: the denser pyrite ore, at the same filling, shares the power among more tonnes and
    its product coarsens where the DEM chain's refines."""
    claim = pyrite_claim(calibration="table")
    assert not claim["holds"] and claim["p80_um"] > 0, claim


def test_quartz_to_clay_cuts_energy_and_coarsens():
    claim = clay_claim()
    assert claim["holds"], claim


def test_clay_claim_fails_without_the_mineralogy_and_the_soft_charge():
    assert not clay_claim(effects=BLIND_EFFECTS, breakage_map=_mineralogy_blind)["holds"]


def _component_content_p80(twin, ss):
    m = twin.model.mass_array(ss.x)
    return [pxx_um(twin.grid, m[c].sum(axis=0)) for c in range(m.shape[0])]


def blend_interaction(shared_charge: bool = True) -> dict:
    """Each component's mill-content P80 in a 50 % B / 50 % D blend over its P80 when ground
    alone, at the same feed rate and speed. ``shared_charge=False`` is the wrong model: each
    ore in its own mill, the products mixed."""
    feed, speed = 0.031, 0.70
    alone = [Twin(o) for o in ("B", "D")]
    single = [_component_content_p80(t, t.steady(feed, speed))[0] for t in alone]
    if shared_charge:
        blend = Twin(["B", "D"])
        in_blend = _component_content_p80(blend, blend.steady(feed, speed, blend=[0.5, 0.5]))
    else:
        in_blend = single
    return {"B": in_blend[0] / single[0] - 1.0, "D": in_blend[1] / single[1] - 1.0}


def test_blend_components_interact_through_the_shared_charge():
    """D's clay and mica cushion B and thicken the slurry: B is ground coarser in the blend than
    alone; D, in a harder, thinner charge, finer."""
    r = blend_interaction()
    assert r["B"] > INTERACTION_MIN_REL and r["D"] < -INTERACTION_MIN_REL, r
    wrong = blend_interaction(shared_charge=False)
    assert not (wrong["B"] > INTERACTION_MIN_REL and wrong["D"] < -INTERACTION_MIN_REL)


def test_blends_use_only_the_single_type_calibrations():
    """Nothing in the calibration is fitted to a blend: each component of a blend twin breaks
    with exactly the parameters of its single-type twin."""
    blend = Twin(["A", "C"])
    for c, name in enumerate(("A", "C")):
        assert blend.spec.breakage[c].params == Twin(name).spec.breakage[0].params
        assert isinstance(blend.spec.breakage[c].params, BreakageParams)
    assert not any("blend" in k for k in blend.calibration.fitted)
