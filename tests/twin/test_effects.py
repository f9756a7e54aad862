"""Effects declare what they provide and need; a model holds exactly what its effects provide,
in an order derived from the declarations, and refuses anything undeclared."""

import numpy as np
import pytest

import twin.effects.registry as registry
from twin import EFFECTS, ModelError, SizeGrid, Twin
from twin.effects import Effect
from twin.effects.base import Option
from twin.effects.registry import build_order, problems

ALL = ["breakage", "transport", "holdup", "speed", "cushioning", "rheology", "power", "classification",
       "slowing_down", "sensor_delay"]
GRID = SizeGrid(top_um=6700.0, ratio=2.0, count=9)


def _model(effects, **kw):
    return Twin(["B", "D"], effects=effects, grid=GRID, n_mixers=2, **kw).model


def _without(effect):
    """The effects of ALL without ``effect`` and every effect that cannot do without it."""
    gone = {effect}
    while True:
        left = [e for e in ALL if e not in gone]
        more = {p.loc[1] for p in problems(left)}
        if not more:
            return left, gone
        gone |= {left[i] for i in more}


@pytest.fixture(scope="module")
def full():
    return _model(ALL)


@pytest.mark.parametrize("effect", [e for e in ALL if e not in ("breakage", "transport")])
def test_dropping_an_effect_drops_exactly_what_it_declares(full, effect):
    left, gone = _without(effect)
    lean = _model(left)
    declared = {o for g in gone for o in EFFECTS[g].outputs}
    assert set(full.outputs) - set(lean.outputs) == declared & set(full.outputs)
    assert set(lean.outputs) <= set(full.outputs)
    assert {full.effect_of[o] for o in set(full.outputs) - set(lean.outputs)} <= gone
    assert [g for g, _ in lean.state_groups] == [g for g, _ in full.state_groups if full.effect_of.get(g) not in gone]
    for name in set(full.z_names) - set(lean.z_names):  # an aggregate leaves only with all its users
        assert set(full.aggregate_users[name]) <= gone, name
    assert all(set(users) <= set(left) for users in lean.aggregate_users.values())


def test_a_lean_model_has_no_algebraic_variables_and_no_load_outputs():
    m = _model(["breakage", "transport"])
    assert m.z.numel() == 0 and m.z_names == []
    assert "load_frac" not in m.outputs and "power_kw" not in m.outputs
    assert set(m.outputs) == set(EFFECTS["transport"].outputs) | set(m.CORE_OUTPUTS)


def test_a_batch_model_has_no_product_only_its_content():
    m = _model(["breakage", "speed"])
    assert "p80_um" not in m.outputs and "content_p80_um" in m.outputs and m.psd_what == "content"
    with pytest.raises(ModelError, match="no product"):
        m.product_psd_function()


def test_every_output_and_state_names_the_effect_that_made_it(full):
    assert set(full.effect_of[o] for o in full.outputs) <= set(ALL) | {"model"}
    assert full.effect_of["p80_measured_um"] == "sensor_delay" and full.effect_of["p80_lag_um"] == "sensor_delay"
    assert full.effect_of["holdup_t"] == "model"


def test_the_order_comes_from_the_declarations_not_the_registry(monkeypatch, full):
    order = build_order(ALL)
    before = {v: i for i, e in enumerate(order) for v in EFFECTS[e].outputs + EFFECTS[e].provides
              + EFFECTS[e].contributes}
    for i, e in enumerate(order):  # every reader after every writer of what it reads
        for v in EFFECTS[e].needs + EFFECTS[e].uses:
            assert all(j < i for j, w in enumerate(order) if v in EFFECTS[w].outputs + EFFECTS[w].provides
                       + EFFECTS[w].contributes), (e, v)
    assert before  # (the declarations are not empty)
    reversed_registry = dict(reversed(list(EFFECTS.items())))
    monkeypatch.setattr(registry, "EFFECTS", reversed_registry)
    assert build_order(ALL) == order
    again = _model(ALL)
    x = full.initial_state([0.6, 0.4]) * 1.3
    u, d = [30.0, 0.72], [0.6, 0.4, 1.1]
    np.testing.assert_allclose(np.asarray(again.f(x, u, d)), np.asarray(full.f(x, u, d)), rtol=1e-12, atol=0)


def test_a_needed_variable_no_effect_provides_names_the_effect_and_who_could():
    with pytest.raises(ModelError, match=r"Effect 'sensor_delay' needs variable 'p80_um', which no listed "
                                         r"effect provides\. It is provided by 'transport'"):
        _model(["breakage", "sensor_delay"])


class _Doubler(Effect):
    name = "doubler"
    outputs = ("load_frac",)

    def apply(self, ctx):
        ctx.output("load_frac", ctx.holdup())


class _Sneaky(Effect):
    name = "sneaky"
    outputs = ("sneaky_frac",)

    def apply(self, ctx):
        ctx.output("sneaky_frac", ctx.get("load_frac"))  # not declared in needs or uses


class _Writer(Effect):
    name = "writer"

    def apply(self, ctx):
        ctx.output("undeclared_kw", 1.0)


class _A(Effect):
    name = "a"
    outputs = ("a_out",)
    needs = ("b_out",)


class _B(Effect):
    name = "b"
    outputs = ("b_out",)
    needs = ("a_out",)


def test_a_variable_provided_twice_names_both_effects():
    reg = dict(EFFECTS, doubler=_Doubler)
    found = problems(["breakage", "transport", "holdup", "doubler"], registry=reg)
    assert any("'load_frac' is provided by both 'holdup' and effect 'doubler'" in p.message for p in found)


def test_reading_or_writing_what_is_not_declared_is_refused(monkeypatch):
    monkeypatch.setattr(registry, "EFFECTS", dict(EFFECTS, sneaky=_Sneaky, writer=_Writer))
    with pytest.raises(ModelError, match="Effect 'sneaky' reads variable 'load_frac' without declaring it"):
        _model(["breakage", "transport", "holdup", "sneaky"])
    with pytest.raises(ModelError, match="Effect 'writer' adds output 'undeclared_kw' without declaring it"):
        _model(["breakage", "transport", "writer"])


def test_a_cycle_of_needs_has_no_build_order():
    with pytest.raises(ModelError, match="cycle"):
        build_order(["a", "b"], registry={"a": _A, "b": _B})


@pytest.mark.parametrize("effect, option, value, allowed", [
    ("classification", "kind", "grte", "one of 'grate', 'hydrocyclone'"),
    ("sensor_delay", "stages", 2.7, r"an integer in \[1, 50\]"),
    ("sensor_delay", "stages", True, r"an integer in \[1, 50\]"),
    ("sensor_delay", "dead_time_h", 0.0, r"a number in \(0, 24\)"),
    ("sensor_delay", "dead_time_h", -0.1, r"a number in \(0, 24\)"),
    ("sensor_delay", "dead_time_h", float("inf"), r"a number in \(0, 24\)"),
    ("power", "model", "bnd", "one of 'bond', 'hogg_fuerstenau'"),
])
def test_option_values_are_checked_against_their_declared_type_and_range(effect, option, value, allowed):
    effects = ["breakage", "transport", "power", "classification", "sensor_delay"]
    found = problems(effects, {effect: {option: value}})
    assert [p.loc for p in found] == [("effect_options", effect, option)]
    assert f"The '{option}' option of effect '{effect}' must be" in found[0].message
    with pytest.raises(ModelError, match=allowed):
        _model(effects, effect_options={effect: {option: value}})


def test_an_integer_is_a_valid_float_option():
    assert Option(1.0, "x", float, lo=0.0).check("e", "x", 2) == 2.0
