"""A mill fills by volume and its classifiers settle by density: each ore in a twin is held and classified at its
own density, not the listed ores' equal-share blend's. A feed of B ground as 195.9 um in a twin that also listed a
pyrite-rich ore (and 203.6 um alone): an ore the mill is never fed changed its product."""

import numpy as np
import pytest

from twin import Mineralogy, Twin
from twin.ore import Texture
from twin.twin import DEFAULT_EFFECTS

#: A dense ore (60 wt% pyrite, 3.69 t/m3) beside B (2.90 t/m3).
PYRITE_RICH = Mineralogy({"pyrite": 60.0, "quartz": 40.0}, Texture(mean_grain_um=125.0), name="PY")


@pytest.mark.parametrize("mill, feed_tph, options", [
    ("lab", 0.031, None), ("industrial", 23.0, {"classification": {"kind": "hydrocyclone"}})],
    ids=["lab grate", "industrial cyclones"])
def test_a_feed_of_one_ore_grinds_alike_whatever_other_ores_the_twin_lists(mill, feed_tph, options):
    b_only = Twin(["B"], mill=mill, effect_options=options)
    alone = b_only.steady(feed_tph=feed_tph, blend={"B": 1.0})
    listed = Twin(["B", PYRITE_RICH], mill=mill, effect_options=options)
    assert listed.spec.solids_density_t_m3 > 1.1 * b_only.spec.solids_density_t_m3  # the nominal blend is denser
    beside = listed.steady(feed_tph=feed_tph, blend={"B": 1.0})
    assert beside.p80_um == pytest.approx(alone.p80_um, rel=1e-9)
    for key in ("holdup_t", "load_frac", "throughput_tph", "power_kw") + (
            ("cyclone_d50c_um", "cyclone_pressure_kpa", "circulating_load_frac") if options else ()):
        assert beside.outputs[key] == pytest.approx(alone.outputs[key], rel=1e-9), key
    if options:  # the roping note reads the underflow's own density: it said nothing beside the dense ore
        roping = [[n for n in ss.notes if "hydrocyclones rope" in n] for ss in (alone, beside)]
        assert len(roping[0]) == 1 and roping[1] == roping[0]


def test_a_load_is_the_contents_volume_over_the_nominal_hold_ups():
    """At constant load a 20/80 blend of B and the pyrite-rich ore (denser than the nominal 50/50)
    holds the nominal hold-up's volume (Σ m / ρ of
    its ores' own densities, from the state's masses), more tonnes than the nominal hold-up's; the load output
    and the mill's mass balance say the same."""
    twin = Twin(["B", PYRITE_RICH])
    ss = twin.steady_at_constant_load(blend={"B": 0.2, "PY": 0.8})
    c, n_mix, n_cls = twin.model.shape
    masses = ss.x[:twin.model.n_mass].reshape(c, n_mix, n_cls).sum(axis=(1, 2))
    rho = [o.density_t_m3 for o in twin.blend.ores]
    volume_m3 = float(np.sum(masses / rho))
    assert volume_m3 == pytest.approx(twin.spec.holdup_nominal_t / twin.spec.solids_density_t_m3, rel=1e-9)
    assert ss.outputs["load_frac"] == pytest.approx(1.0, rel=1e-9)
    assert ss.outputs["holdup_t"] == pytest.approx(masses.sum(), rel=1e-12)
    assert masses.sum() > 1.05 * twin.spec.holdup_nominal_t
    # the default start, a mill full of unground feed, is full by volume too
    x0 = twin.model.initial_state([0.2, 0.8])
    m0 = x0[:twin.model.n_mass].reshape(c, n_mix, n_cls).sum(axis=(1, 2))
    assert float(np.sum(m0 / rho)) == pytest.approx(volume_m3, rel=1e-12)


def _two_ores_in_the_mill(twin):
    """A state holding the same mass of each ore in every mixer and size class (the industrial default
    start, split equally), and the twin's u and d at nominal feed, blend 50/50."""
    c, n_mix, n_cls = twin.model.shape
    x = twin.model.initial_state([0.5, 0.5])
    m = twin.model.mass_array(x)
    x[:twin.model.n_mass] = np.broadcast_to(m.mean(axis=0), m.shape).ravel()
    return x, twin.model.u_vector(twin.mill.feed_nominal_tph), twin.model.d_vector([0.5, 0.5])


def test_each_ore_is_cut_by_the_cyclones_at_its_own_density():
    """Two ores of the same breakage but different density in one cyclone feed: each has its own partition curve,
    its d50 the stream's d50c x ((rho_k - 1) / (rho_stream - 1))^-1/2 (Stokes; Laplante & Finch 1984): the
    product per size class is the sum of the ores' own overflows, computed here from the model's outputs and
    the densities. With one cut for both (as before) the product at 120 um was 1.3x this."""
    from twin.effects.classification import corrected_partition

    twin = Twin(["B", PYRITE_RICH], mill="industrial", effect_options={"classification": {"kind": "hydrocyclone"}})
    x, u, d = _two_ores_in_the_mill(twin)
    model, grid = twin.model, twin.spec.grid
    rho = [o.density_t_m3 for o in twin.blend.ores]
    rho_stream = 2.0 / (1.0 / rho[0] + 1.0 / rho[1])  # equal masses of each
    d50 = model.evaluate("cyclone_d50c_um", x, u, d)
    m = model.evaluate("cyclone_sharpness", x, u, d)
    rs = model.evaluate("cyclone_water_bypass_frac", x, u, d)  # the solids bypass of this cyclone: the water's
    each = model.evaluate("cyclone_feed_tph", x, u, d) / 2.0
    expected = sum((1.0 - rs) * (1.0 - corrected_partition(grid.mid_um / (d50 * ((r - 1.0) / (rho_stream - 1.0))
                                                                             ** -0.5), m)) * each for r in rho)
    product = model.evaluate("product_tph", x, u, d)
    assert product == pytest.approx(expected, rel=1e-6)
    assert not product == pytest.approx(2.0 * (1.0 - rs) * (1.0 - corrected_partition(grid.mid_um / d50, m)) * each,
                                        rel=0.05)


def test_each_ore_is_held_by_the_grate_at_its_own_density():
    """The lab mill's grate: each ore's discharge factor is the grate's at its own density (d50 stated for
    quartz, x ((rho_k - 1) / (1.65))^-1/2): from equal contents of the two ores, the product of each size class
    over the last mixer's content and the two factors' sum is one discharge rate for every class (with one factor
    for both, as before, it varied by class)."""
    from twin.effects.classification import grate_factor

    no_slurry = [e for e in DEFAULT_EFFECTS if e != "rheology"]  # the slurry's own factor on the cut left out
    twin = Twin(["B", PYRITE_RICH], mill="lab", effects=no_slurry)
    x, u, d = _two_ores_in_the_mill(twin)
    mill, grid = twin.mill, twin.spec.grid
    factors = [grate_factor(grid.mid_um, mill.grate_d50_um * ((o.density_t_m3 - 1.0) / (2.65 - 1.0)) ** -0.5,
                            mill.grate_sharpness)[1:-1] for o in twin.blend.ores]  # the sink always leaves
    content = twin.model.mass_array(x)[0, -1, 1:-1]  # each ore's, in the last mixer (the top class holds none)
    rate_h = twin.model.evaluate("product_tph", x, u, d)[1:-1] / (content * (factors[0] + factors[1]))
    assert rate_h == pytest.approx(np.full(rate_h.size, rate_h[0]), rel=1e-9)
    assert np.all(factors[1] <= factors[0]) and (factors[1] / factors[0]).min() < 0.2  # the dense ore is held back


def _same_breakage_in_cyclones() -> tuple[Twin, Twin]:
    """Twins of B and the pyrite-rich ore with B's breakage both, in the industrial cyclone circuit: each ore held
    and cut at its own density, and both at the first's blend density."""
    options = {"classification": {"kind": "hydrocyclone"}}
    same = Twin(["B"], mill="industrial", effect_options=options)
    breakage = same.scaled_breakage(same.calibration.breakage(same.blend.ores[0]))
    ores = {"B": breakage, "PY": breakage}
    own = Twin(["B", PYRITE_RICH], mill="industrial", effect_options=options, ore_breakage=ores)
    return own, Twin(["B", PYRITE_RICH], mill="industrial", effect_options=options, ore_breakage=ores,
                     solids_density_t_m3=own.spec.solids_density_t_m3)


def test_each_ores_product_is_reported_and_a_dense_ore_is_ground_finer():
    """SteadyState.ore_p80_um: each ore's product P80. The ores' products add up to the product, class by class;
    two ores of the same breakage in the cyclone circuit grind alike when the twin holds them at one density, and
    the denser one finer when each is held and cut at its own (the overgrinding of a dense mineral in a closed
    circuit: Laplante & Finch 1984). The summary lists them where more than one ore makes a product."""
    own, one = _same_breakage_in_cyclones()
    by_own, by_one = (t.steady(feed_tph=23.0, blend={"B": 0.5, "PY": 0.5}) for t in (own, one))
    flows = np.asarray(own.model.outputs["ore_product_tph"](by_own.x, by_own.u, by_own.d), float)
    assert flows.sum(axis=1) == pytest.approx(by_own.psd, rel=1e-12, abs=1e-15)
    assert by_one.ore_p80_um["PY"] == pytest.approx(by_one.ore_p80_um["B"], rel=1e-9)
    assert by_own.ore_p80_um["PY"] < 0.95 * by_own.ore_p80_um["B"]
    assert by_own.ore_p80_um["PY"] < by_own.p80_um < by_own.ore_p80_um["B"]
    assert {k: v for k, v in by_own.summary().items() if k.startswith("ore_")} == {
        "ore_B_p80_um": by_own.ore_p80_um["B"], "ore_PY_p80_um": by_own.ore_p80_um["PY"],
        "ore_B_circulating_load_frac": by_own.ore_circulating_load_frac["B"],
        "ore_PY_circulating_load_frac": by_own.ore_circulating_load_frac["PY"]}
    alone = own.steady(feed_tph=23.0, blend={"B": 1.0, "PY": 0.0})
    assert np.isnan(alone.ore_p80_um["PY"]) and not any(k.startswith("ore_") for k in alone.summary())


def test_each_ores_product_p80_is_in_a_runs_frame_and_a_closed_loops_rows():
    """A run's frame and the closed loop's plant readings carry each ore's product P80 beside the product's: at a
    steady state they are SteadyState.ore_p80_um; through a blend step the product's P80 lies between its ores' at
    every sample (the product's passing at any size is its ores' passing weighted by their flows, and P80
    interpolates passing linearly in log size); a twin of one ore has no such column."""
    from mpc.plants.twin_plant import TwinPlant

    twin = Twin(["B", PYRITE_RICH], mill="industrial", effect_options={"classification": {"kind": "hydrocyclone"}})
    ss = twin.steady(feed_tph=23.0, blend={"B": 0.5, "PY": 0.5})
    keys = {"B": "ore_B_p80_um", "PY": "ore_PY_p80_um"}
    run = twin.simulate(0.5, 0.05, feed_tph=23.0, x0=ss.x,
                        blend=lambda t: {"B": 0.5, "PY": 0.5} if t < 0.1 else {"B": 0.2, "PY": 0.8})
    frame = run.frame
    for ore, key in keys.items():
        assert frame[key].iloc[0] == pytest.approx(ss.ore_p80_um[ore], rel=1e-9)
    ores = frame[list(keys.values())].to_numpy()
    assert np.all(ores.min(axis=1) * (1 - 1e-12) <= frame["p80_um"]) and np.all(frame["p80_um"] <= ores.max(axis=1)
                                                                              * (1 + 1e-12))
    assert frame["ore_PY_p80_um"].iloc[-1] != pytest.approx(frame["ore_PY_p80_um"].iloc[0], rel=1e-3)  # it moved
    reading = TwinPlant(twin.model).measure(ss.x, ss.u, ss.d)
    assert reading["p80_um"] == pytest.approx(ss.p80_um, rel=1e-12)
    assert {ore: reading[key] for ore, key in keys.items()} == pytest.approx(ss.ore_p80_um, rel=1e-12)
    single = Twin(["B"], mill="industrial", effect_options={"classification": {"kind": "hydrocyclone"}})
    one = single.simulate(0.1, 0.05, feed_tph=23.0).frame
    assert not [c for c in one.columns if c.startswith("ore_")]
    alone = single.steady(feed_tph=23.0)
    assert not [k for k in TwinPlant(single.model).measure(alone.x, alone.u, alone.d) if k.startswith("ore_")]


def test_each_ores_circulating_load_adds_up_and_a_dense_ore_circulates_more():
    """SteadyState.ore_circulating_load_frac and a run's ``ore_<name>_circulating_load_frac``: each ore's cyclone
    underflow over its fresh feed. Weighted by the ores' shares of the feed they add up to the circuit's circulating
    load (the underflow is the ores' underflows); the denser ore, cut finer (Plitt 1976: d50c ~ (rho_s - 1)^-0.5),
    circulates more (the build-up of a dense mineral in a closed circuit: Laplante & Finch 1984), and as much as B
    when the twin holds both at one density. An ore not fed has none (NaN); a run's first row and a closed loop's
    plant reading at the steady state are the steady state's."""
    own, one = _same_breakage_in_cyclones()
    shares = {"B": 0.3, "PY": 0.7}
    by_own, by_one = (t.steady(feed_tph=23.0, blend=shares) for t in (own, one))
    for ss in (by_own, by_one):
        loads = ss.ore_circulating_load_frac
        total = sum(shares[o] * loads[o] for o in shares)
        assert total == pytest.approx(ss.outputs["circulating_load_frac"], rel=1e-9)
    assert by_one.ore_circulating_load_frac["PY"] == pytest.approx(by_one.ore_circulating_load_frac["B"], rel=1e-9)
    assert by_own.ore_circulating_load_frac["PY"] > 1.03 * by_own.ore_circulating_load_frac["B"]
    alone = own.steady(feed_tph=23.0, blend={"B": 1.0, "PY": 0.0})
    assert np.isnan(alone.ore_circulating_load_frac["PY"])
    assert alone.ore_circulating_load_frac["B"] == pytest.approx(alone.outputs["circulating_load_frac"], rel=1e-9)
    frame = own.simulate(0.1, 0.05, feed_tph=23.0, x0=by_own.x, blend=shares).frame
    for ore in shares:
        assert frame[f"ore_{ore}_circulating_load_frac"].iloc[0] == pytest.approx(
            by_own.ore_circulating_load_frac[ore], rel=1e-9)
    assert not [k for k in Twin(["B", PYRITE_RICH]).steady().summary() if "circulating" in k]  # no cyclones
    from mpc.plants.twin_plant import TwinPlant

    reading = TwinPlant(own.model).measure(by_own.x, by_own.u, by_own.d)  # a closed loop's row
    assert {ore: reading[f"ore_{ore}_circulating_load_frac"] for ore in shares} == pytest.approx(
        by_own.ore_circulating_load_frac, rel=1e-12)


def test_a_density_given_by_ore_replaces_that_ores_only():
    """``solids_density_t_m3`` as a dict by ore: those ores' densities, each ore still at its own (its own mineral
    density given changes nothing; a number holds every ore at it); a name the twin does not list is refused."""
    from twin import TwinError

    blend = {"B": 0.6, "PY": 0.4}
    alone = Twin(["B", PYRITE_RICH]).steady(feed_tph=0.031, blend=blend)
    given = Twin(["B", PYRITE_RICH], solids_density_t_m3={"B": Twin("B").blend.ores[0].density_t_m3})
    assert given.steady(feed_tph=0.031, blend=blend).p80_um == pytest.approx(alone.p80_um, rel=1e-12)
    one = Twin(["B", PYRITE_RICH], solids_density_t_m3=given.spec.solids_density_t_m3)
    assert not one.steady(feed_tph=0.031, blend=blend).p80_um == pytest.approx(alone.p80_um, rel=1e-4)
    with pytest.raises(TwinError, match="names of this twin's components"):
        Twin(["B", PYRITE_RICH], solids_density_t_m3={"C": 2.7})
