"""Model assembly from effects: only listed effects are in the model; mass balance closes for
every effect combination; errors for unknown or incompatible effects."""

import itertools
import re
import time

import casadi as ca
import numpy as np
import pytest

from twin.errors import ModelError, SolverError
from twin.sizes import SizeGrid
from twin.twin import DEFAULT_EFFECTS, Twin

OPTIONAL = ["holdup", "speed", "cushioning", "slowing_down", "power", "sensor_delay", "classification"]


def _structural_balance(model, rng):
    """d(hold-up)/dt - (feed - product) at random states and inputs, relative to the flows."""
    worst = 0.0
    has_flow = "throughput_tph" in model.outputs
    for _ in range(3):
        x = model.initial_state(load_frac=rng.uniform(0.1, 2.0)) * rng.uniform(0.5, 1.5, model.n_x)
        u = np.array([rng.uniform(0.0, 0.06), rng.uniform(0.5, 0.95)])
        d = model.d_vector(None, rng.uniform(0.5, 2.0))
        dh = float(np.sum(np.asarray(model.f(x, u, d)).ravel()[: model.n_mass]))
        out = float(model.outputs["throughput_tph"](x, u, d)) if has_flow else 0.0
        inflow = u[0] if "transport" in model.effect_names else 0.0
        worst = max(worst, abs(dh - (inflow - out)) / (inflow + out + 1e-3))
    return worst


@pytest.mark.parametrize("kind", ["grate", "hydrocyclone"])
def test_mass_balance_closes_structurally_for_every_effect_combination(kind):
    rng = np.random.default_rng(7)
    count = 0
    for r in range(len(OPTIONAL) + 1):
        for combo in itertools.combinations(OPTIONAL, r):
            if kind == "hydrocyclone" and "classification" not in combo:
                continue
            effects = ["breakage", "transport", *combo]
            opts = {"classification": {"kind": kind}} if "classification" in combo else {}
            t = Twin(["B", "D"], effects=effects, effect_options=opts, n_mixers=2)
            assert _structural_balance(t.model, rng) < 1e-12, effects
            count += 1
    assert count >= 64


@pytest.mark.parametrize("effects", [
    ["breakage", "transport"],
    list(DEFAULT_EFFECTS),
    [*DEFAULT_EFFECTS, "slowing_down", "sensor_delay"],
])
def test_integrated_mass_balance_closes(effects):
    t = Twin(["B", "D"], effects=effects)
    blend = lambda th: [1.0, 0.0] if th < 1.0 else [0.6, 0.4]  # noqa: E731
    feed = lambda th: 0.031 if th < 2.0 else 0.045  # noqa: E731
    run = t.simulate(4.0, 1 / 30, feed_tph=feed, blend=blend, rtol=1e-11, atol_rel=1e-13)
    assert run.mass_balance_error() < 1e-9
    assert run.states[:, : t.model.n_mass].min() >= 0.0


def test_hydrocyclone_circuit_reports_circulating_load():
    t = Twin("B", mill="industrial", effects=["breakage", "transport", "holdup", "power", "classification"],
             effect_options={"classification": {"kind": "hydrocyclone"}})
    ss = t.steady(feed_tph=25.0)  # the calibrated rates hold 25 t/h of B; 60 t/h overloads the circuit (below)
    assert 0.5 < ss.outputs["circulating_load_frac"] < 6.0
    assert ss.outputs["throughput_tph"] == pytest.approx(25.0, rel=1e-8)


def test_a_circuit_with_no_steady_state_is_said_to_overload():
    """At twice the sized feed the circuit has no steady state (its hold-up grows without bound):
    the error says the mill overloads, with the hold-up it reached and what its shell holds."""
    t = Twin("B", mill="industrial", effects=["breakage", "transport", "holdup", "power", "classification"],
             effect_options={"classification": {"kind": "hydrocyclone"}})
    shell = t.model.spec.mill.max_holdup_t(t.model.spec.solids_density_t_m3)
    with pytest.raises(SolverError, match="The mill overloads") as err:
        t.steady(feed_tph=60.0)
    held = float(re.search(r"by then it held ([0-9.e+]+) t of ore", str(err.value)).group(1))
    assert held > shell and f"filled to its shell ({shell:.3g} t)" in str(err.value)


def test_dropping_an_effect_removes_its_states_terms_and_outputs():
    full = Twin("B", effects=[*DEFAULT_EFFECTS, "sensor_delay"]).model
    no_delay = Twin("B", effects=list(DEFAULT_EFFECTS)).model
    assert full.n_x == no_delay.n_x + 3 and "p80_measured_um" not in no_delay.outputs
    no_cush = Twin("B", effects=[e for e in DEFAULT_EFFECTS if e != "cushioning"]).model
    assert "soft_frac" not in no_cush.outputs and "cushioning_rate_coeff" not in no_cush.parameters
    assert no_cush.n_instructions < no_delay.n_instructions
    no_power = Twin("B", effects=[e for e in DEFAULT_EFFECTS if e != "power"]).model
    assert "power_kw" not in no_power.outputs and "specific_energy_kwh_t" not in no_power.outputs


def _eval_seconds(model, n=4000):
    """Median time of the right-hand side evaluated at n points in one call (no Python overhead)."""
    x, u, d = model.initial_state(), model.u_vector(0.031), model.d_vector()
    batch = model.f.map(n)
    args = (np.tile(x[:, None], (1, n)), np.tile(u[:, None], (1, n)), np.tile(d[:, None], (1, n)))
    times = []
    for _ in range(7):
        t0 = time.perf_counter()
        batch(*args)
        times.append(time.perf_counter() - t0)
    return np.median(times)


def test_fewer_effects_make_a_cheaper_model():
    # a coarse grid, so the effects' terms are a visible share next to the n^2 breakage terms
    grid = SizeGrid(top_um=6700.0, ratio=2.0, count=12)
    full = Twin(["B", "D"], grid=grid, effects=[*DEFAULT_EFFECTS, "slowing_down", "sensor_delay"]).model
    lean = Twin(["B", "D"], grid=grid, effects=["breakage", "transport"]).model
    assert lean.n_instructions < 0.75 * full.n_instructions
    assert lean.n_x < full.n_x
    assert _eval_seconds(lean) < _eval_seconds(full)


def test_describe_lists_effects_states_parameters_and_sources(twin_b):
    text = twin_b.model.describe()
    for name in DEFAULT_EFFECTS:
        assert name in text
    assert "Herbst & Fuerstenau" in text and "mass [t] x75" in text and "grate_d50_um" in text


def test_unknown_effect_is_named_with_close_matches():
    with pytest.raises(ModelError, match="Unknown effect 'cushoning'.*Did you mean 'cushioning'"):
        Twin("B", effects=["breakage", "cushoning"])


def test_missing_requirement_is_named():
    with pytest.raises(ModelError, match="'holdup' requires effect 'transport'"):
        Twin("B", effects=["breakage", "holdup"])


def test_unknown_effect_option_is_named():
    with pytest.raises(ModelError, match="Unknown option 'knd' of effect 'classification'"):
        Twin("B", effect_options={"classification": {"knd": "grate"}})


def test_outputs_are_casadi_functions_of_x_u_d(twin_b):
    m = twin_b.model
    for name in ("p80_um", "holdup_t", "power_kw", "specific_energy_kwh_t", "load_frac"):
        fn = m.outputs[name]
        assert isinstance(fn, ca.Function) and fn.name_in() == ["x", "u", "d"]
    passing = m.passing_function(210.0)
    ss = twin_b.steady()
    assert 0.0 < float(passing(ss.x, ss.u, ss.d)) < 1.0


def test_evaluate_returns_floats_for_scalar_outputs_and_arrays_otherwise(twin_b):
    m = twin_b.model
    ss = twin_b.steady()
    assert isinstance(m.evaluate("holdup_t", ss.x, ss.u, ss.d), float)
    assert m.evaluate("psd_frac", ss.x, ss.u, ss.d).shape == (m.spec.grid.count,)
    with pytest.raises(Exception, match="Unknown output 'p8_um'.*Did you mean 'p80_um'"):
        m.evaluate("p8_um", ss.x, ss.u, ss.d)
