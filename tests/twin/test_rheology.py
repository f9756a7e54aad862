"""Slurry rheology (twin.effects.rheology), the grate's Stokes density term and the mill's
discharge factor: present only when listed, exact limits, mass balance, the direction
MISSION.md's soft ores need (clay ore leaves coarser and faster at constant load), and the
power following the slurry's clay, not its mica."""

import numpy as np
import pytest

import twin.effects.classification as classification
from twin import Mineralogy, load_ore
from twin.calibration import load_calibration
from twin.effects.rheology import SLURRY_SOLIDS_VOL_FRAC, slurry_power_factor, thomas_relative_viscosity
from twin.errors import ModelError
from twin.mill import DISCHARGE_REFERENCE_DENSITY_T_M3, LAB, bond_power_kw
from twin.twin import DEFAULT_EFFECTS, Twin

from .test_model import _structural_balance
from .test_physics_claims import pyrite_for_biotite

NO_RHEOLOGY = [e for e in DEFAULT_EFFECTS if e != "rheology"]


def _calibration(**coefficients):
    return load_calibration().with_values(coefficients=coefficients)


def test_rheology_is_in_the_model_only_when_listed():
    with_it = Twin("D", effects=list(DEFAULT_EFFECTS)).model
    without = Twin("D", effects=NO_RHEOLOGY).model
    assert "slurry_relative_viscosity" in with_it.outputs and "clay_crowding_coeff" in with_it.parameters
    assert "slurry_relative_viscosity" not in without.outputs and "clay_crowding_coeff" not in without.parameters
    with pytest.raises(ModelError, match="'rheology' requires effect 'classification'"):
        Twin("D", effects=[e for e in DEFAULT_EFFECTS if e != "classification"])


def test_no_clay_crowding_gives_exactly_the_model_without_rheology():
    cal = _calibration(clay_crowding_coeff=0.0)
    a = Twin("D", effects=list(DEFAULT_EFFECTS), calibration=cal).steady_at_constant_load()
    b = Twin("D", effects=NO_RHEOLOGY, calibration=cal).steady_at_constant_load()
    assert a.outputs["slurry_relative_viscosity"] == pytest.approx(
        float(thomas_relative_viscosity(SLURRY_SOLIDS_VOL_FRAC)), rel=1e-12)
    assert a.p80_um == pytest.approx(b.p80_um, rel=1e-9)
    assert a.feed_tph == pytest.approx(b.feed_tph, rel=1e-9)


def test_thomas_viscosity_rises_faster_than_einstein_and_steepens():
    phi = np.linspace(0.05, 0.55, 11)
    mu = np.array([float(thomas_relative_viscosity(p)) for p in phi])
    assert np.all(mu > 1.0 + 2.5 * phi)  # crowding adds to Einstein's dilute limit
    assert np.all(np.diff(mu, 2) > 0)  # convex: thick slurries stiffen fast


def test_clay_carries_a_coarser_product_out_faster_at_constant_load():
    gain = {}
    for ore in ("A", "D"):
        with_it = Twin(ore, effects=list(DEFAULT_EFFECTS)).steady_at_constant_load()
        without = Twin(ore, effects=NO_RHEOLOGY).steady_at_constant_load()
        assert with_it.p80_um > without.p80_um, ore
        gain[ore] = with_it.feed_tph / without.feed_tph
    assert gain["D"] > gain["A"] > 1.0  # the clay-rich ore gains most


def test_clay_fraction_is_that_of_the_hold_up_in_a_blend():
    t = Twin(["A", "D"], effects=list(DEFAULT_EFFECTS))
    ss = t.steady(blend=[0.5, 0.5])
    m = np.asarray(ss.x)[: t.model.n_mass].reshape(t.model.shape)
    held = m.sum(axis=(1, 2))
    expected = float(np.dot(held, t.spec.clay_frac) / held.sum())
    assert ss.outputs["clay_frac"] == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("kind", ["grate", "hydrocyclone"])
def test_mass_balance_closes_with_rheology(kind):
    rng = np.random.default_rng(3)
    t = Twin(["B", "D"], effects=["breakage", "transport", "holdup", "classification", "rheology"],
             effect_options={"classification": {"kind": kind}}, n_mixers=2)
    assert _structural_balance(t.model, rng) < 1e-12


@pytest.mark.parametrize("factor", [0.5, 1.0, 2.3, 9.0])
def test_discharge_factor_sets_the_load_by_the_discharge_law(factor):
    # no grate: every mixer discharges f Q_nom (rho_s / rho_quartz) (H_k / H_nom,k)^2 (a volume
    # flow stated for quartz), so at the nominal feed each mixer, and the mill, holds
    # (f rho_s / rho_quartz)^-1/2 of nominal (to the smooth floor of the empty-mill guard)
    t = Twin("B", mill=LAB.with_(discharge_factor=factor), effects=["breakage", "transport", "holdup"])
    ss = t.steady(feed_tph=LAB.feed_nominal_tph)
    volume_factor = factor * t.spec.solids_density_t_m3 / DISCHARGE_REFERENCE_DENSITY_T_M3
    assert ss.outputs["load_frac"] == pytest.approx(volume_factor ** -0.5, rel=1e-5)


def test_power_is_bonds_over_one_plus_k_times_the_slurry_thickening():
    """At any state the power is Bond's at the speed over 1 + k (mu_r / mu_r0 - 1), mu_r the
    slurry's relative viscosity (an output) and mu_r0 that of a clay-free slurry."""
    for ore in ("A", "D"):
        t = Twin(ore)
        ss = t.steady_at_constant_load(0.65)
        thickening = ss.outputs["slurry_relative_viscosity"] / float(thomas_relative_viscosity(SLURRY_SOLIDS_VOL_FRAC))
        expected = bond_power_kw(t.mill, 0.65) * slurry_power_factor(thickening, t.coefficients["slurry_power_coeff"])
        assert thickening > 1.0 and ss.outputs["power_kw"] == pytest.approx(expected, rel=1e-12), ore


def test_mica_does_not_lower_the_power_clay_does():
    """Biotite for quartz in Type B (the same clay) leaves the power exactly as it is; clay for
    quartz lowers it. The test fails where mica cushions the power (the previous model's
    1 / (1 + k phi_soft), which the table's ores A and B contradict: the same power at 2 and 18 %
    biotite)."""
    b = load_ore("B")

    def swapped(mineral, points=10.0):
        wt = dict(b.wt_pct, quartz=b.wt_pct["quartz"] - points, **{mineral: b.wt_pct[mineral] + points})
        return Mineralogy(wt, b.texture, name=f"B_{mineral}")

    power = {name: Twin(o).steady(feed_tph=0.031).outputs["power_kw"]
             for name, o in (("B", b), ("mica", swapped("biotite")), ("clay", swapped("kaolinite")))}
    assert power["mica"] == pytest.approx(power["B"], rel=1e-12)
    assert power["clay"] < 0.99 * power["B"]


def test_grate_cut_scales_with_the_ore_density_as_stokes():
    rho_q = DISCHARGE_REFERENCE_DENSITY_T_M3
    assert classification.grate_density_factor(rho_q) == pytest.approx(1.0, rel=1e-15)
    for rho in (2.0, 3.07, 5.0):
        expected = ((rho - 1.0) / (rho_q - 1.0)) ** -0.5
        assert classification.grate_density_factor(rho) == pytest.approx(expected, rel=1e-15)
        t = Twin("B", solids_density_t_m3=rho)
        assert t.model.parameters["grate_density_factor"][0] == pytest.approx(expected, rel=1e-15)


def test_the_grate_holds_the_denser_pyrite_ore_back(monkeypatch):
    """Pyrite for biotite in Type B at constant load: with the grate's Stokes density term the
    denser ore leaves finer and stays longer than without it (exponent 0: a cut by size only)."""
    def kpis():
        ss = Twin(pyrite_for_biotite()).steady_at_constant_load(0.70)
        return ss.p80_um, ss.outputs["holdup_t"] / ss.feed_tph

    p80_with, tau_with = kpis()
    monkeypatch.setattr(classification, "STOKES_DENSITY_EXPONENT", 0.0)
    p80_without, tau_without = kpis()
    assert p80_with < p80_without and tau_with > tau_without


def test_no_calibration_crowds_a_slurry_of_the_deposit_past_jamming():
    """The clay-crowding bound brings the deposit's clay-richest slurry (40 % clay) exactly to
    random close packing, and both shipped calibrations (and their fits' bounds) stay within it."""
    from twin.calibration import DEM_FITTED
    from twin.calibration.table import BOUNDS
    from twin.effects.rheology import CLAY_CROWDING_MAX, DEPOSIT_MAX_CLAY_FRAC, JAMMING_VOL_FRAC

    assert SLURRY_SOLIDS_VOL_FRAC * (1.0 + CLAY_CROWDING_MAX * DEPOSIT_MAX_CLAY_FRAC) == pytest.approx(
        JAMMING_VOL_FRAC, rel=1e-15)
    assert DEM_FITTED["clay_crowding_coeff"]["bounds"][1] == BOUNDS["clay_crowding_coeff"][1] == CLAY_CROWDING_MAX
    for name in ("dem", "table"):
        k = load_calibration(name).coefficients["clay_crowding_coeff"]
        assert 0.0 <= k <= CLAY_CROWDING_MAX * (1.0 + 1e-12), name
