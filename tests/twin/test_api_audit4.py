"""A notebook user's slips with the twin's Python API: runs that said less than their steady states, two threads
in one twin, masses and speeds of the wrong shape or unit, lists edited after the check, errors in another
function's names, a twin sent to a worker process."""

import multiprocessing
import pickle
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np
import pytest

from twin import BreakageParams, SizeGrid, TabulatedPSD, Twin, TwinInputError, pxx_um
from twin.mill import LAB, bond_power_kw, hogg_fuerstenau_power_kw, power_kw
from twin.ore.ores import Blend


def test_a_run_states_its_steady_states_notes_over_its_samples(twin_b):
    """A run held at a steady state whose P80 lies in the grid's sink and whose operating work index is no
    ore's said nothing (Trajectory.notes []), its steady state both: the notes are read off the samples now."""
    ss = twin_b.steady(hardness_scale=1e-4)
    assert any("below the finest size class" in n for n in ss.notes)
    run = twin_b.simulate(0.2, 0.05, hardness_scale=1e-4, x0=ss.x)
    assert any(n.startswith("from 0 h to 0.2 h (5 of 5 samples)") and "below the finest size class" in n
               for n in run.notes)
    assert any("operating work index is 1.69 kWh/t" in n for n in run.notes)
    assert twin_b.simulate(0.1, 0.05).notes == []  # the calibrated point: nothing to say
    # a starved mill's work index is no ore's either: the note asked about the rates' units alone
    (starved,) = [n for n in twin_b.steady(feed_tph=0.003).notes if "operating work index" in n]
    assert "Or is the feed far from what the mill takes (its load is 0.267 of its nominal)?" in starved


def test_two_threads_simulating_on_one_twin_agree_with_one(twin_b):
    """The cached integrators were shared: two threads in one twin crashed the process (2 runs of 3) or
    raised IDAS's NaN error. Their calls now take turns."""
    serial = {f: twin_b.simulate(0.2, 0.05, feed_tph=f).frame["p80_um"].iloc[-1] for f in (0.025, 0.04)}
    with ThreadPoolExecutor(2) as ex:
        out = list(ex.map(lambda f: (f, twin_b.simulate(0.2, 0.05, feed_tph=f).frame["p80_um"].iloc[-1]),
                          [0.025, 0.04] * 3))
    assert all(v == serial[f] for f, v in out)


def test_pxx_refuses_masses_that_are_not_one_per_class():
    """10 masses for 25 classes gave 1061 um for 988, a 2-D array 18 um, a negative class 4030 um, a NaN an
    IndexError, and percent 0.8 (a fraction) P0.8 = 3 um: each refused, naming what is wrong."""
    grid = SizeGrid()
    m = np.exp(-0.3 * np.arange(grid.count))
    p80 = pxx_um(grid, m)
    for bad, match in ((m[:10], r"shape \(25,\)"), (np.vstack([m, m]), r"shape \(25,\)"),
                       (np.r_[-0.5, 1.5, np.zeros(23)], "masses >= 0"), (np.r_[np.nan, m[1:]], "finite")):
        with pytest.raises(TwinInputError, match=match):
            pxx_um(grid, bad)
    with pytest.raises(TwinInputError, match="'percent' parameter of pxx_um"):
        pxx_um(grid, m, 0.8)
    assert pxx_um(grid, np.r_[m[:-1], -1e-12]) == pytest.approx(pxx_um(grid, np.r_[m[:-1], 0.0]), rel=1e-9)  # round-off
    plan_end = np.r_[m[:-1], -2e-4 * m.sum()]  # a controller's plan ends so (its states are unbounded): taken
    assert np.isfinite(pxx_um(grid, plan_end))
    assert 900 < p80 < 6700


@pytest.mark.parametrize("fn", [bond_power_kw, hogg_fuerstenau_power_kw, power_kw])
def test_the_power_models_refuse_a_speed_that_is_no_fraction_of_critical(fn):
    """70 typed for 0.70 drew -5.9e208 kW in Bond's equation; -0.5 and 1.5 negative power."""
    assert fn(LAB, 0.7) > 0
    for speed in (70, -0.5, 1.5, float("nan")):  # 1.0 is allowed: the plausible power ranges reach it
        with pytest.raises(TwinInputError, match="'speed_frac_critical' parameter"):
            fn(LAB, speed)
    with pytest.raises(TwinInputError, match="'ball_diameter_m' parameter of Mill.critical_speed_rpm"):
        LAB.critical_speed_rpm(25)  # mm for m: a bare math domain error


def test_a_list_given_to_a_frozen_object_is_copied_after_its_check():
    """The caller's list was kept: editing it later put a band [5, 0.1] on the mill and a passing of 5.0 at
    600 um in the table, past their checks."""
    band = [0.8, 1.2]
    mill = LAB.with_(stable_band=band)
    band[:] = [5.0, 0.1]
    assert mill.stable_band == (0.8, 1.2)
    sizes, passing = [75, 150, 300, 600, 1200, 2400, 4800], [0.1, 0.2, 0.35, 0.5, 0.7, 0.9, 1.0]
    psd = TabulatedPSD(sizes, passing)
    passing[3] = 5.0
    assert float(psd.passing(600)) == pytest.approx(0.5)


def test_moly_cop_parameters_are_named_as_given_and_a_blend_of_numbers_is_refused():
    """beta0 = 20 was refused as "'phi' parameter of BreakageParams"; Blend((1, 2), ...) raised AttributeError."""
    with pytest.raises(TwinInputError, match=r"'beta0' parameter of BreakageParams.energy_specific \(Austin's phi\)"):
        BreakageParams.energy_specific(0.0097, 1.0, 2.0, 3000.0, 20.0, 0.3, 4.0)
    with pytest.raises(TwinInputError, match="'alpha2' parameter"):
        BreakageParams.energy_specific(0.0097, 1.0, -2.0, 3000.0, 0.5, 0.3, 4.0)
    with pytest.raises(TwinInputError, match="'ores' of Blend must be ore names"):
        Blend((1, 2), (0.5, 0.5))


def test_an_ore_harder_than_every_reference_ore_is_noted_though_its_energy_group_is_inside(tmp_path):
    """70 % pyrite (hardness index 12.8 GPa against the reference ores' 4.4-9.65) has an energy group Pi inside
    the fitted range: the dem calibration noted nothing. The properties its strength index reads are
    compared one by one now."""
    from twin.calibration import load_calibration
    from twin.ore import load_ore, reference_ores

    path = tmp_path / "pyrite.toml"
    path.write_text('mineralogy = { quartz = 20.0, pyrite = 70.0, kaolinite = 10.0 }\n'
                    'texture = { mean_grain_um = 150.0, uniformity = 0.6, association_entropy = 0.5 }\n')
    ore = load_ore(path)
    cal = load_calibration("dem")
    notes = cal.extrapolation_notes([ore])
    assert [n for n in notes if "hardness index 12.8 GPa lies outside the 4.41-9.65 GPa" in n]
    assert not [n for n in notes if "energy group Pi" in n]  # the one input compared before
    assert cal.extrapolation_notes(list(reference_ores().values())) == []


def test_a_twin_pickles_and_a_worker_process_gets_its_steady_state_to_the_bit(tmp_path):
    """A Twin in a process pool (a sweep in Python) raised CasADi's "Cannot pickle SX objects": it pickles as the
    arguments it was made with and is rebuilt from them, so a worker's steady state is the parent's to the bit,
    with ore breakage given directly, effect options, a grid and mixers of its own kept; its calibration and
    its sized mill as read (the files they were read from are gone when the pickle is loaded)."""
    from twin.calibration.files import DEM_CALIBRATION_PATH
    from twin.mill import INDUSTRIAL_PRESET_PATH

    given = BreakageParams.energy_specific(0.009686, 0.659, 2.5, 7093.0, 0.4, 0.65, 4.0)
    own, preset = tmp_path / "own.json", tmp_path / "preset.json"
    own.write_bytes(DEM_CALIBRATION_PATH.read_bytes())
    preset.write_bytes(INDUSTRIAL_PRESET_PATH.read_bytes())
    twin = Twin(["B", "D"], mill=str(preset), effect_options={"classification": {"kind": "hydrocyclone"}},
                ore_breakage={"D": given}, grid=SizeGrid(count=24), mixer_volume_fracs=(0.7, 0.15, 0.15),
                calibration=own)
    here = twin.steady(feed_tph=23.0, blend={"B": 0.3, "D": 0.7})
    pickled = pickle.dumps(twin)
    own.unlink()
    preset.unlink()
    again = pickle.loads(pickled)
    assert again.spec.grid.count == 24 and again.spec.mixer_fracs == twin.spec.mixer_fracs
    assert again.steady(feed_tph=23.0, blend={"B": 0.3, "D": 0.7}).p80_um == here.p80_um
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        there = pool.submit(twin.steady, feed_tph=23.0, blend={"B": 0.3, "D": 0.7}).result()
    assert there.p80_um == here.p80_um and np.array_equal(there.x, here.x)
    assert there.ore_p80_um == here.ore_p80_um and there.notes == here.notes
