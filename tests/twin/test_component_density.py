"""A mill fills by volume and its classifiers settle by density: each ore in a twin is held and classified at its
own density, not the listed ores' equal-share blend's. A feed of B ground as 195.9 um in a twin that also listed a
pyrite-rich ore (and 203.6 um alone): an ore the mill is never fed changed its product."""

import numpy as np
import pytest

from twin import Mineralogy, Twin
from twin.ore import Texture

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
