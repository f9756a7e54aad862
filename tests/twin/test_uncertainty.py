"""The DEM's particle scatter carried to the twin by the bootstrap (twin.calibration.uncertainty):
paired resampling, intervals that shrink with more particles, the replicates the file keeps and
the intervals of a steady state."""

import json
import math

import numpy as np
import pytest

from twin.calibration import law_e50_j_kg, load_calibration, steady_intervals
from twin.calibration.dem_map import dem_breakage
from twin.calibration.uncertainty import intervals, replicate_laws, resample_dem
from twin.ore.ores import load_ore


@pytest.fixture(scope="module")
def cal():
    return load_calibration("dem")


def test_resampling_draws_the_same_packings_for_every_ore(cal):
    ores = resample_dem(cal.record["dem"], np.random.default_rng(1))
    dem = cal.record["dem"]["ores"]
    picks = {}
    for name, o in ores.items():
        own = list(dem[name]["specific_fracture_energy_J_kg"])
        picks[name] = [own.index(e) for e in o["specific_fracture_energy_J_kg"]]
    assert len({tuple(p) for p in picks.values()}) == 1  # one set of packing indices
    assert len(set(picks["B"])) < len(picks["B"])  # with replacement


def _width(values):
    lo, hi = np.percentile(values, [5, 95])
    return hi - lo


def _scatter(dem: dict, n: int) -> float:
    """Pooled s.d. of ln(fracture energy) about each ore's mean, over the first n packings."""
    res = []
    for o in dem["ores"].values():
        e = np.log(o["specific_fracture_energy_J_kg"][:n])
        res += list(e - e.mean())
    return float(np.std(res, ddof=len(dem["ores"])))


def test_intervals_shrink_when_particles_are_added(cal):
    """Bootstrap over the first 8 packings against all of them (>= 30): the 90 % interval of
    ln E50 and of ln S^E(1 mm) of Type B, per unit of the packings' own scatter, narrows roughly
    as 1/sqrt(n) (the first 8 packings need not scatter as much as all of them)."""
    dem, law = cal.record["dem"], cal.record["law"]
    n_all = min(len(o["specific_fracture_energy_J_kg"]) for o in dem["ores"].values())
    b = load_ore("B")
    widths = {}
    for n in (8, n_all):
        reps = replicate_laws(dem, law, 60, seed=5, n_particles=n)
        e50 = [math.log(law_e50_j_kg({**law, **r}, b)) for r in reps]
        se = [math.log(dem_breakage(b, {**law, **r}).se_1mm_t_kwh) for r in reps[:20]]
        widths[n] = (_width(e50) / _scatter(dem, n), _width(se) / _scatter(dem, n))
    ratio = math.sqrt(n_all / 8)
    for k in range(2):
        assert widths[n_all][k] < widths[8][k] / (0.6 * ratio), widths


def test_the_file_keeps_its_replicates_and_their_refits(cal):
    boot = cal.record["bootstrap"]
    assert boot["n"] == len(boot["replicates"]) >= 50
    ok = [r for r in boot["replicates"] if r["success"]]
    assert len(ok) >= 0.9 * boot["n"]
    for r in ok:
        assert set(r["values"]) == set(cal.record["fit"]["parameters_fitted"])
        assert r["max_abs_error_pct"] < 10.0
    # the replicates differ from each other: the scatter is really carried
    assert np.std([r["energy"]["c0"] for r in ok]) > 0


def test_percentile_intervals():
    out = intervals([{"x": float(v)} for v in range(101)], level=0.90)
    assert out["x"] == pytest.approx((5.0, 50.0, 95.0))


def test_steady_intervals_bracket_the_nominal_answer(cal):
    from twin import Twin

    unc = steady_intervals("B", cal, "lab", 0.031, 0.70, n=20)  # the fewest a 90 % interval takes
    assert unc["n"] + unc["failed"] == 20 and unc["n"] >= 18
    reps = cal.record["bootstrap"]["replicates"]
    last = [i for i, r in enumerate(reps) if r.get("success", True)][19]  # the 20th converged one
    assert unc["unconverged"] == sum(not r.get("success", True) for r in reps[:last])  # said, not dropped silently
    nominal = Twin("B", calibration=cal).steady(0.031, 0.70)
    lo, mid, hi = unc["intervals"]["p80_um"]
    assert lo < hi and lo <= nominal.p80_um * 1.02 and nominal.p80_um <= hi * 1.02
    assert unc["intervals"]["throughput_tph"][0] == pytest.approx(0.031, rel=1e-9)  # the given feed


def test_intervals_on_another_mill_scale_the_breakage_as_the_twin_does(cal):
    """On the industrial mill the replicates' S and b are scaled from the calibrated (lab) mill
    as :class:`twin.Twin` scales them: unscaled, the replicates' P80 was ~3x the twin's own."""
    from twin import Twin

    unc = steady_intervals("B", cal, "industrial", 31.0, 0.70, n=20)
    nominal = Twin("B", mill="industrial", calibration=cal).steady(31.0, 0.70)
    lo, mid, hi = unc["intervals"]["p80_um"]
    assert mid == pytest.approx(nominal.p80_um, rel=0.05)
    assert unc["intervals"]["load_frac"][1] == pytest.approx(float(nominal.outputs["load_frac"]), rel=0.02)



def test_remembered_breakage_follows_its_inputs(cal):
    """dem_breakage remembers its answers: a changed law, capture scale or ore is a new answer,
    the same inputs the same one."""
    law = cal.record["law"]
    b, d = load_ore("B"), load_ore("D")
    first = dem_breakage(b, law)
    assert dem_breakage(b, law) == first and dem_breakage(d, law) != first
    assert dem_breakage(b, law, 2.0).se_1mm_t_kwh == 2.0 * first.se_1mm_t_kwh
    other = {**law, "energy": {**law["energy"], "sigma": 1.5 * law["energy"]["sigma"]}}
    assert dem_breakage(b, other).se_1mm_t_kwh != first.se_1mm_t_kwh
    law_copy = json.loads(json.dumps(law))  # a law read again: equal, so the same answer
    assert dem_breakage(b, law_copy) == first
    law_copy["energy"]["sigma"] *= 1.5  # the same dict, changed in place: not the answer remembered
    assert dem_breakage(b, law_copy) == dem_breakage(b, other)
