import numpy as np
import pytest

from twin.errors import TwinInputError
from twin.solve.simulate import integrate_constant


def test_newton_steady_state_agrees_with_long_integration(twin_b):
    m = twin_b.model
    ss = twin_b.steady(feed_tph=0.035, speed_frac_critical=0.75)
    x_long = integrate_constant(m, m.initial_state(), 40.0, ss.u, ss.d, rtol=1e-11, atol_rel=1e-13)
    assert np.abs(x_long - ss.x).max() / ss.x.sum() < 1e-7
    assert ss.outputs["throughput_tph"] == pytest.approx(0.035, rel=1e-9)


def test_steady_at_constant_load_holds_nominal_holdup(twin_b):
    ss = twin_b.steady_at_constant_load()
    assert ss.outputs["load_frac"] == pytest.approx(1.0, abs=1e-9)
    assert ss.load_status == "stable"
    assert ss.outputs["specific_energy_kwh_t"] == pytest.approx(
        ss.outputs["power_kw"] / ss.feed_tph, rel=1e-6)


def test_more_feed_coarsens_product_and_loads_the_mill(twin_b):
    lo = twin_b.steady(feed_tph=0.025)
    hi = twin_b.steady(feed_tph=0.040)
    assert hi.p80_um > lo.p80_um
    assert hi.outputs["holdup_t"] > lo.outputs["holdup_t"]
    assert hi.outputs["specific_energy_kwh_t"] < lo.outputs["specific_energy_kwh_t"]


def test_smooth_p80_output_is_close_to_exact(twin_b):
    ss = twin_b.steady()
    assert ss.outputs["p80_smooth_um"] == pytest.approx(ss.p80_um, rel=0.013)
    assert ss.outputs["p80_um"] == ss.p80_um and ss.outputs["p80_smooth_um"] != ss.p80_um  # one name, one meaning


def test_steady_state_of_batch_mill_is_refused(batch_b):
    with pytest.raises(TwinInputError, match="needs the 'transport' effect"):
        batch_b.steady()


def test_bad_speed_is_named(twin_b):
    with pytest.raises(TwinInputError, match="'speed_frac_critical' parameter of Twin must be a float in \\(0, 1\\). Got 1.3"):
        twin_b.steady(speed_frac_critical=1.3)


def test_a_denser_ore_of_the_same_breakage_per_volume_runs_the_same_volumes():
    """The hold-up is a volume (powder filling) and the discharge a volume flow (le Roux et al.
    2013, eq. 9): an ore twice as dense that breaks alike per volume (twice the tonnes per kWh, S^E,
    so S = S^E P / H is unchanged) has the same residence time and product at constant load, and
    twice the mass throughput. It fails where the discharge is a fixed mass flow (the residence
    time would double and the product be finer, at the same tonnes per hour). The grate's cut
    is held (its Stokes density term, tested in test_rheology, would hold the denser ore back)."""
    from dataclasses import replace

    from twin import Twin, load_ore
    from twin.effects.classification import grate_density_factor
    from twin.mill import get_mill

    ore = load_ore("B")
    base = Twin(ore)
    params = base.spec.breakage[0].params
    lab = get_mill("lab", base.calibration.record)
    runs = []
    for scale in (1.0, 2.0):
        p = replace(params, se_1mm_t_kwh=params.se_1mm_t_kwh * scale)
        rho = scale * ore.density_t_m3
        held = lab.with_(grate_d50_um=lab.grate_d50_um * grate_density_factor(ore.density_t_m3) / grate_density_factor(rho))
        twin = Twin(ore, ore_breakage={ore.name: p}, solids_density_t_m3=rho, mill=held)
        runs.append(twin.steady_at_constant_load())
    light, heavy = runs
    assert heavy.feed_tph == pytest.approx(2.0 * light.feed_tph, rel=1e-7)
    assert heavy.p80_um == pytest.approx(light.p80_um, rel=1e-7)
    assert heavy.outputs["specific_energy_kwh_t"] == pytest.approx(0.5 * light.outputs["specific_energy_kwh_t"], rel=1e-7)


def test_a_steady_state_carries_what_the_models_do_not_describe():
    """SteadyState.notes (twin.validity), for Python users as for the CLI: 5 t/h into the
    laboratory mill overflows its shell; 0.96 of critical centrifuges; the nominal state has none."""
    from twin import Twin

    lab = Twin("B")
    assert lab.steady(feed_tph=0.031).notes == []
    over = lab.steady(feed_tph=5.0)
    capacity = lab.mill.max_holdup_t(lab.spec.solids_density_t_m3)
    assert over.summary()["holdup_t"] > capacity
    assert [n for n in over.notes if "filled to its shell" in n and f"({capacity:.4g} t)" in n]
    assert [n for n in lab.steady(feed_tph=0.031, speed_frac_critical=0.96).notes if "centrifuges" in n]


def test_a_circuit_whose_water_balance_needs_water_taken_out_says_so():
    """Twenty-four 38-cm cyclones at 30 % solids on the industrial mill at 31 t/h (an earlier
    size-mill chose 16, for a larger mill): ~1 kPa per cyclone, half the feed water bypassed to the underflow,
    so the mill's feed water is negative (water taken out), which no plant runs; it printed
    nothing. The preset's own cluster (sized at its design pressure) and the grate discharge have
    no such note."""
    from twin import Twin

    many = {"classification": {"kind": "hydrocyclone", "cyclone": {"count": 24}}}
    ss = Twin("B", mill="industrial", effect_options=many).steady(feed_tph=31.0, speed_frac_critical=0.70)
    assert ss.outputs["mill_water_m3_h"] < 0
    assert [n for n in ss.notes if "water taken out" in n and "mill_water_m3_h" in n]
    sized = Twin("B", mill="industrial", effect_options={"classification": {"kind": "hydrocyclone"}})
    for tw in (sized, Twin("B", mill="industrial")):
        assert not [n for n in tw.steady(feed_tph=31.0).notes if "water taken out" in n]


def test_a_p80_inside_the_grids_sink_is_said_to_be_extrapolated():
    """Five classes of ratio 2 from 6.7 mm end at 419 um: the lab product (P80 ~200 um on the
    default grid) lies 92 % in the sink, and the P80 printed is the sink's extrapolation (~380
    um), which said nothing. The default grid resolves it: no such note."""
    from twin import SizeGrid, Twin

    coarse = Twin("B", grid=SizeGrid(top_um=6700.0, ratio=2.0, count=5)).steady(feed_tph=0.031)
    fine = Twin("B").steady(feed_tph=0.031)
    assert coarse.p80_um > 1.5 * fine.p80_um  # the extrapolation is far off
    assert [n for n in coarse.notes if "below the finest size class (419 um)" in n and "extrapolated" in n]
    assert not [n for n in fine.notes if "finest size class" in n]


def test_a_trajectory_says_when_it_leaves_what_the_models_describe():
    """Trajectory.notes (twin.validity.trajectory_notes): 5 t/h into the laboratory mill fills it
    past its shell after a while (the share of samples counted from the frame); at the nominal
    feed the hour has no notes."""
    from twin import Twin

    lab = Twin("B")
    assert lab.simulate(1.0, 0.05, feed_tph=0.031).notes == []
    run = lab.simulate(1.0, 0.05, feed_tph=5.0)
    capacity = lab.mill.max_holdup_t(lab.spec.solids_density_t_m3)
    over = run.frame["holdup_t"].to_numpy() > capacity
    (note,) = [n for n in run.notes if "filled to its shell" in n]  # beside the samples' work-index note
    assert 0 < over.mean() < 1 and f"on {over.mean():.0%} of the samples" in note


def test_a_feed_far_below_the_nominal_fails_saying_why():
    """1e-9 t/h into the laboratory mill: Newton fails and the integration over 40 residence times
    (~6e8 h) fails in IDAS; the error was the integrator's alone. It now names the feed against
    the nominal and what to do. 1e-4 of the nominal still solves."""
    from twin import SolverError, Twin

    lab = Twin("B")
    with pytest.raises(SolverError, match=r"feed 1e-09 t/h \(3.2e-08 of the mill's nominal 0.031 t/h\).*"
                                          r"give a feed nearer the mill's nominal"):
        lab.steady(feed_tph=1e-9)
    assert lab.steady(feed_tph=0.031e-4).p80_um > 0
