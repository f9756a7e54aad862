"""The classification and slurry models against their published forms, each written out here from
its source (not through the code's helpers), and the cyclone classes' refusals of inputs that ran
to a wrong number: a wrong constant, exponent or unit conversion in the code fails these tests.

Sources: Plitt (1976, CIM Bull. 69, 114-123) in the metric form of Flintoff, Plitt & Turak (1987,
CIM Bull. 80, 39-50): sizes in cm, flow in L/min per cyclone, phi the feed's solids % by volume,
viscosity in cP, pressure in kPa, the split's head in m of feed slurry. Thomas (1965, J. Colloid
Sci. 20, 267-277) for the slurry's relative viscosity; Stokes' law for the cut sizes' density and
viscosity terms."""

from __future__ import annotations

import math

import pytest

from twin.effects.classification import (KPA_PER_PSI, CycloneSurvey, Hydrocyclone, grate_density_factor,
                                         grate_factor, hydrocyclone_from, slurry_m3_h, solids_volume_pct)
from twin.effects.rheology import (CLAY_CROWDING_MAX, SLURRY_SOLIDS_VOL_FRAC, STOKES_CUT_EXPONENT,
                                   jamming_clay_frac, thomas_relative_viscosity)
from twin.errors import TwinInputError

#: Standard gravity [m/s2] (CGPM 1901), for the split's head.
G = 9.80665
#: The example inputs of the PLITT.P / PLITT.S / PLITT.M / PLITT.D50 functions of the public
#: mineral-processing-functions sheet (Dr-Alireza-Ghasemi on GitHub): a 50-cm cyclone, inlet 5,
#: vortex finder 10, apex 8, free vortex height 15 cm, 300 L/min of a 45 wt % slurry of 2.7 t/m3.
DC, DI, DO, DU, H_CM, Q_LPM, SOLIDS_WT_PCT, RHO_S = 50.0, 5.0, 10.0, 8.0, 15.0, 300.0, 45.0, 2.7


def published_plitt(q_lpm: float, viscosity_cp: float = 1.0) -> dict:
    """Plitt's four equations as Flintoff et al. (1987) write them, at the example's geometry and feed."""
    phi = 100.0 * (SOLIDS_WT_PCT / RHO_S) / (SOLIDS_WT_PCT / RHO_S + (100.0 - SOLIDS_WT_PCT))  # % by volume
    pulp_t_m3 = 100.0 / (SOLIDS_WT_PCT / RHO_S + (100.0 - SOLIDS_WT_PCT))  # 100 t of pulp over its m3
    p_kpa = 1.88 * q_lpm ** 1.78 * math.exp(0.0055 * phi) / (
        DC ** 0.37 * DI ** 0.94 * H_CM ** 0.28 * (DU ** 2 + DO ** 2) ** 0.87)
    d50c_um = (39.7 * DC ** 0.46 * DI ** 0.6 * DO ** 1.21 * viscosity_cp ** 0.5 * math.exp(0.063 * phi)
               / (DU ** 0.71 * H_CM ** 0.38 * q_lpm ** 0.45 * (RHO_S - 1.0) ** 0.5))
    head_m = p_kpa * 1000.0 / (pulp_t_m3 * 1000.0 * G)  # Pa over (kg/m3 m/s2)
    s = (1.9 * (DU / DO) ** 3.31 * H_CM ** 0.54 * (DU ** 2 + DO ** 2) ** 0.36 * math.exp(0.0054 * phi)
         / (head_m ** 0.24 * DC ** 1.11))
    m = 1.94 * math.exp(-1.58 * s / (1.0 + s)) * (DC ** 2 * H_CM / q_lpm) ** 0.15
    return {"pressure_kpa": p_kpa, "d50c_um": d50c_um, "volume_split": s, "sharpness_m": m}


def example_cyclone(count: int = 1, **kw) -> Hydrocyclone:
    return Hydrocyclone(diameter_cm=DC, inlet_cm=DI, vortex_finder_cm=DO, apex_cm=DU, free_vortex_height_cm=H_CM,
                        count=count, feed_solids_frac=SOLIDS_WT_PCT / 100.0, **kw)


@pytest.mark.parametrize("count", [1, 4])
def test_plitts_four_equations_are_flintoffs_metric_form(count):
    """At the example's inputs, 300 L/min to each of ``count`` cyclones (18 m3/h each): a wrong
    coefficient, exponent, unit (m3/h for L/min, the cluster's flow for one cyclone's, kPa for
    the split's head in m) fails this."""
    want = published_plitt(Q_LPM)
    got = example_cyclone(count).plitt(count * Q_LPM * 60.0 / 1000.0, RHO_S)
    for key, value in want.items():
        assert float(got[key]) == pytest.approx(value, rel=1e-12), key


def test_the_cut_grows_as_the_root_of_the_liquids_viscosity_and_each_factor_scales_its_equation():
    """Flintoff et al.'s d50c carries mu^0.5 (cP); each calibration factor multiplies its own
    equation (the split reads the factored pressure's head, the sharpness the factored split)."""
    want = published_plitt(Q_LPM, viscosity_cp=4.0)
    got = example_cyclone(viscosity_cp=4.0).plitt(Q_LPM * 0.06, RHO_S)
    assert float(got["d50c_um"]) == pytest.approx(want["d50c_um"], rel=1e-12)
    assert float(got["d50c_um"]) == pytest.approx(2.0 * published_plitt(Q_LPM)["d50c_um"], rel=1e-12)
    plain = example_cyclone().plitt(Q_LPM * 0.06, RHO_S)
    factored = example_cyclone(d50c_factor=1.5, pressure_factor=2.0, split_factor=0.5).plitt(Q_LPM * 0.06, RHO_S)
    assert float(factored["d50c_um"]) == pytest.approx(1.5 * float(plain["d50c_um"]), rel=1e-12)
    assert float(factored["pressure_kpa"]) == pytest.approx(2.0 * float(plain["pressure_kpa"]), rel=1e-12)
    assert float(factored["volume_split"]) == pytest.approx(0.5 * 2.0 ** -0.24 * float(plain["volume_split"]),
                                                            rel=1e-12)


def test_psi_and_the_feeds_volume_fraction_and_flow_by_their_definitions():
    """1 psi = 1 lbf/in2 = 0.45359237 kg x 9.80665 m/s2 / (0.0254 m)^2 (exact definitions); a
    slurry's solids % by volume and its flow from solids [t/h] and water [m3/h]: the Moly-Cop
    BallSim base case's cyclone feed (1902.5 t/h of 2.8 t/m3 in 1204.2 m3/h of water)."""
    assert KPA_PER_PSI == pytest.approx(0.45359237 * G / 0.0254 ** 2 / 1000.0, rel=1e-15)
    tph, water, rho = 1902.5, 1204.2, 2.8
    survey = CycloneSurvey(feed_solids_tph=tph, feed_water_m3_h=water, solids_density_t_m3=rho, d50c_um=183.3,
                           sharpness=1.34, water_bypass_frac=0.375, pressure_psi=7.7)
    assert survey.kpa == pytest.approx(7.7 * 6.894757, rel=1e-7)
    assert survey.slurry_m3_h == pytest.approx(tph / rho + water, rel=1e-15)
    assert survey.feed_solids_frac == pytest.approx(tph / (tph + water), rel=1e-15)
    vol_pct = 100.0 * (tph / rho) / (tph / rho + water)
    assert solids_volume_pct(survey.feed_solids_frac, rho) == pytest.approx(vol_pct, rel=1e-12)
    cyc = Hydrocyclone(feed_solids_frac=survey.feed_solids_frac)
    assert slurry_m3_h(cyc, tph, rho) == pytest.approx(tph / rho + water, rel=1e-12)


def test_the_grate_is_austins_logistic_curve_with_stokes_density_term():
    """c = 1 / (1 + (x/d50)^k) (Austin, Klimpel & Luckie 1984, ch. 9): a half at d50, 1/(1 + 2^k)
    at twice it; the cut at an ore's density over quartz's (2.65 t/m3) as Stokes' law sets the
    size settling at one velocity, d ~ (rho_s - rho_w)^-1/2."""
    assert float(grate_factor(300.0, 300.0, 2.5)) == pytest.approx(0.5, rel=1e-15)
    assert float(grate_factor(600.0, 300.0, 2.5)) == pytest.approx(1.0 / (1.0 + 2.0 ** 2.5), rel=1e-15)

    def stokes_size(v_m_s, delta_rho_kg_m3, mu_pa_s=1e-3):
        return math.sqrt(18.0 * mu_pa_s * v_m_s / (G * delta_rho_kg_m3))

    for rho in (2.65, 4.0, 7.5):
        want = stokes_size(1e-3, (rho - 1.0) * 1000.0) / stokes_size(1e-3, (2.65 - 1.0) * 1000.0)
        assert grate_density_factor(rho) == pytest.approx(want, rel=1e-12)


def test_thomas_viscosity_and_the_slurrys_constants_from_their_sources():
    """Thomas (1965): mu_r = 1 + 2.5 phi + 10.05 phi^2 + 0.00273 exp(16.6 phi); the mill slurry's
    0.46 is 70 wt % at 2.7 t/m3; the cut grows as sqrt(mu) (Stokes at one settling velocity); the
    largest clay crowding puts the deposit's 40 % clay at jamming, 0.64 by volume."""
    for phi in (0.0, 0.2, 0.46, 0.6):
        want = 1.0 + 2.5 * phi + 10.05 * phi ** 2 + 0.00273 * math.exp(16.6 * phi)
        assert float(thomas_relative_viscosity(phi)) == pytest.approx(want, rel=1e-14)
    assert SLURRY_SOLIDS_VOL_FRAC == pytest.approx((0.7 / 2.7) / (0.7 / 2.7 + 0.3), abs=0.005)
    d = [math.sqrt(18.0 * mu * 1e-3 / (G * 1700.0)) for mu in (1e-3, 4e-3)]
    assert STOKES_CUT_EXPONENT == pytest.approx(math.log(d[1] / d[0]) / math.log(4.0), rel=1e-12)
    assert SLURRY_SOLIDS_VOL_FRAC * (1.0 + CLAY_CROWDING_MAX * 0.40) == pytest.approx(0.64, rel=1e-12)
    assert jamming_clay_frac(CLAY_CROWDING_MAX) == pytest.approx(0.40, rel=1e-12)


# --- inputs that ran to a wrong number with exit 0 ---------------------------------------------

@pytest.mark.parametrize("flow", [-50.0, 0.0, float("nan")])
def test_plitt_refuses_a_flow_that_is_not_positive(flow):
    """-50 m3/h gave a complex d50c (40.5 - 256j um) and pressure; 0 a bare ZeroDivisionError."""
    with pytest.raises(TwinInputError, match=r"'slurry_flow_m3_h' parameter of Hydrocyclone.plitt .*Got"):
        Hydrocyclone().plitt(flow, 2.7)


@pytest.mark.parametrize("rho", [0.9, 1.0])
def test_plitt_refuses_solids_no_denser_than_water(rho):
    """0.9 t/m3 gave d50c = -572j um ((rho_s - 1)^-0.5 of a negative number); 1.0 a ZeroDivisionError."""
    with pytest.raises(TwinInputError, match=r"'solids_density_t_m3' parameter of Hydrocyclone.plitt"):
        Hydrocyclone().plitt(200.0, rho)


@pytest.mark.parametrize("frac, vol_pct", [(0.95, "87.6"), (0.005, "0.186")])
def test_a_feed_solids_frac_outside_the_feeds_range_by_volume_is_refused(frac, vol_pct):
    """feed_solids_vol_pct is held to 1-70 %, but a feed_solids_frac was not: 0.95 (87.6 % by
    volume, a slurry that does not flow) ran to a 5.2-mm d50c, 0.005 to a 21-um one."""
    cyc = Hydrocyclone(feed_solids_frac=frac)
    with pytest.raises(TwinInputError, match=rf"'feed_solids_frac' parameter of Hydrocyclone .*not {vol_pct} %"):
        cyc.plitt(200.0, 2.7)
    assert 1.0 <= Hydrocyclone(feed_solids_frac=0.61).feed_volume_pct(2.8) <= 70.0  # the Moly-Cop feed runs


def test_a_survey_whose_feed_is_not_a_flowing_slurry_is_refused():
    """100 t/h of solids in 0.5 m3/h of water (98.7 % by volume; m3/min for m3/h, say) gave a
    d50c factor of 0.0045 and ran."""
    survey = dict(feed_solids_tph=100.0, feed_water_m3_h=0.5, solids_density_t_m3=2.7, d50c_um=100.0,
                  sharpness=1.5, water_bypass_frac=0.4, pressure_kpa=80.0)
    with pytest.raises(TwinInputError, match=r"'feed_water_m3_h' parameter of CycloneSurvey .*not 98.7 %"):
        CycloneSurvey(**survey)
    with pytest.raises(TwinInputError, match=r"'feed_water_m3_h'"):
        hydrocyclone_from({"count": 2, "survey": survey})


@pytest.mark.parametrize("field", ["inlet_cm", "vortex_finder_cm", "apex_cm"])
def test_an_opening_as_wide_as_the_cyclone_is_refused(field):
    """An inlet, vortex finder or apex of 40 cm on a 38-cm cyclone (a mistyped or mixed-unit
    geometry) ran: the apex to a water bypass of 0.997, the vortex finder to a 709-um cut."""
    with pytest.raises(TwinInputError, match=rf"'{field}' parameter of Hydrocyclone must be below the cyclone's "
                                             r"diameter_cm = 38.0"):
        Hydrocyclone(**{field: 40.0})
    with pytest.raises(TwinInputError, match=rf"'{field}'"):
        hydrocyclone_from({field: 40.0})
