"""What `grindtwin steady` reads and answers: a user's ore file is taken as written or refused
before any work, naming the file, the key, the value and what is allowed."""

import pytest

from twin import TwinInputError
from twin.ore.ores import load_ore

TEXTURE = "[texture]\nmean_grain_um = 125.0\nuniformity = 0.6\nassociation_entropy = 0.8\n"
MINERALOGY = "[mineralogy]\nquartz = 40.0\nbiotite = 30.0\nk_feldspar = 30.0\n"


def _ore(tmp_path, text, name="mine"):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def test_an_ore_file_is_read_as_written(tmp_path):
    """The control: every number of the file is the ore's."""
    ore = load_ore(_ore(tmp_path, MINERALOGY + TEXTURE))
    assert ore.wt_pct == {"quartz": 40.0, "biotite": 30.0, "k_feldspar": 30.0}
    assert (ore.texture.mean_grain_um, ore.texture.uniformity, ore.texture.association_entropy) == (125.0, 0.6, 0.8)


@pytest.mark.parametrize("key", ["uniformity", "association_entropy"])
def test_a_texture_key_left_out_is_refused_not_defaulted(tmp_path, key):
    """Without association_entropy the ore took Texture's 0.5 silently (its textural index, which
    the table calibration and the surrogate read, moved with it); a scene's texture requires all three."""
    text = MINERALOGY + "".join(line + "\n" for line in TEXTURE.splitlines() if not line.startswith(key))
    path = _ore(tmp_path, text)
    with pytest.raises(TwinInputError, match=rf"{path}: \[texture\] of ore 'mine': missing {key}\. Allowed and "
                                             "required: mean_grain_um, uniformity, association_entropy"):
        load_ore(path)


def test_a_misspelt_texture_key_is_named_with_the_one_it_left_out(tmp_path):
    path = _ore(tmp_path, MINERALOGY + TEXTURE.replace("uniformity", "uniformty"))
    with pytest.raises(TwinInputError, match="unknown key uniformty; missing uniformity"):
        load_ore(path)


@pytest.mark.parametrize("section, line, shown", [
    ("mineralogy", "quartz = true", "quartz = True"),  # read as 1 wt%: with 99 wt% beside it, accepted
    ("mineralogy", 'quartz = "1"', "quartz = '1'"),
    ("texture", 'mean_grain_um = "125"', "mean_grain_um = '125'"),  # a TypeError traceback later
])
def test_a_value_that_is_not_a_number_is_refused(tmp_path, section, line, shown):
    key = line.split(" = ")[0]
    mineralogy = MINERALOGY.replace("quartz = 40.0", "quartz = 1.0").replace("biotite = 30.0", "biotite = 69.0")
    text = mineralogy + TEXTURE
    text = text.replace(next(k for k in text.splitlines() if k.startswith(key + " =")), line)
    path = _ore(tmp_path, text)
    with pytest.raises(TwinInputError, match=rf"\[{section}\] of ore 'mine': {shown} must be a number"):
        load_ore(path)
    # the same file with the number it meant loads: the refusal is of the type alone
    assert load_ore(_ore(tmp_path, mineralogy + TEXTURE, "meant")).wt_pct["quartz"] == 1.0


def test_a_mineralogy_that_is_not_a_table_is_refused(tmp_path):
    path = _ore(tmp_path, "mineralogy = 5\n" + TEXTURE)
    with pytest.raises(TwinInputError, match="mineralogy must be a table"):
        load_ore(path)


def test_an_out_of_range_value_names_the_file(tmp_path):
    path = _ore(tmp_path, MINERALOGY + TEXTURE.replace("association_entropy = 0.8", "association_entropy = 1.5"))
    with pytest.raises(TwinInputError, match=rf"{path}: ore 'mine': The 'association_entropy' parameter of Texture "
                                             r"must be a float in \[0, 1\]\. Got 1\.5"):
        load_ore(path)


@pytest.mark.parametrize("mill", ["lab", "industrial"])
@pytest.mark.parametrize("extra", [("sensor_delay",), ("feed_inventory", "sensor_delay")])
def test_a_stopped_feed_settles_the_other_states_in_a_few_newton_steps(monkeypatch, mill, extra):
    """At zero feed Newton solves the states beside the masses (lags, feed inventory) with the masses held at zero:
    it solved the masses too, their round-off (1e-41 t) stepping below zero cut each step to 1e-3 of itself, and
    the lab mill's analyser lags failed after 60 steps ("Steady state not found at zero feed"), the industrial
    mill's took 26, as the calibration's last digits fell. The lags' equations are linear: a few steps."""
    import twin.solve.steady as steady
    from twin import DEFAULT_EFFECTS, Twin

    tw = Twin("B", mill=mill, effects=[*DEFAULT_EFFECTS, *extra])
    real, calls = steady._jacobian_evaluator(tw.model), []

    def counted(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(steady, "_jacobian_evaluator", lambda model: counted)
    ss = tw.steady(feed_tph=0.0)
    assert len(calls) <= 5 and ss.outputs["holdup_t"] == 0.0
    assert ss.outputs["p80_smooth_um"] != ss.outputs["p80_smooth_um"]  # undefined (NaN): no product


def test_a_stopped_feed_is_steady_in_every_state():
    """At zero feed the masses were set to zero and every other state left at its initial guess:
    the feed inventory kept 0.031 t (dI/dt = F - I/tau gives I = F tau = 0) and the analyser's lag
    200 um, a residual of ~7e3. Now every state is steady, and a P80 of no product is undefined."""
    import math

    import numpy as np

    from twin import DEFAULT_EFFECTS, Twin

    tw = Twin("B", effects=[*DEFAULT_EFFECTS, "feed_inventory", "sensor_delay"])
    tau_h = tw.model.spec.effect_options.get("feed_inventory", {}).get("time_constant_h", 1.0)
    lag_rate_per_h = 3 / tw.model.parameters["analyser_dead_time_h"][0]  # 3 lags of dead time / 3
    n_t = tw.model.n_mass + 1  # the masses and the feed inventory [t]; then the lags [um]
    for feed in (0.031, 0.0):
        ss = tw.steady(feed_tph=feed)
        f = np.abs(np.asarray(tw.model.f(ss.x, ss.u, ss.d))).ravel()
        assert f[:n_t].max() < 1e-9 * tw.mill.feed_nominal_tph  # t/h
        assert f[n_t:].max() < 1e-9 * 1000.0 * lag_rate_per_h  # um/h: the lags within 1e-6 um
        assert ss.outputs["feed_inventory_t"] == pytest.approx(feed * tau_h, abs=1e-12)
    assert ss.outputs["holdup_t"] == 0.0 and math.isnan(ss.p80_um)
    assert math.isnan(ss.outputs["p80_measured_um"]) and math.isnan(ss.outputs["content_p80_um"])
    # nor are the empty mill's minerals and slurry (its viscosity read 14.2); with ore it has them
    from twin.solve.steady import CONTENT_OUTPUTS

    clay = Twin("D")
    assert all(math.isnan(clay.steady(feed_tph=0.0).outputs[k]) for k in CONTENT_OUTPUTS)
    assert all(np.isfinite(clay.steady(feed_tph=0.031).outputs[k]) for k in CONTENT_OUTPUTS)


@pytest.mark.parametrize("grain", [0.001, 0.05, 2e4])
def test_a_grain_size_no_rock_has_is_refused(tmp_path, grain):
    """0.001 um gave a textural index of 447 (table calibration: P80 307 against 204) with no word:
    a unit slip (mm or nm for um) is refused, naming the field and the range; the range's ends pass."""
    from twin.ore import MEAN_GRAIN_RANGE_UM, Texture

    with pytest.raises(TwinInputError, match=r"'mean_grain_um' parameter of Texture must be a float in \[1, 10000\]"):
        Texture(grain)
    assert [Texture(g).mean_grain_um for g in MEAN_GRAIN_RANGE_UM] == list(MEAN_GRAIN_RANGE_UM)


def test_round_off_masses_in_a_guess_do_not_slow_newton(monkeypatch):
    """A guess whose empty classes (above the feed's top size) hold round-off masses (1e-45 to 1e-20 t, as an
    integration leaves them) took 8-9 Newton steps where the same guess with zeros took 4-5: each such mass with a
    round-off negative step bounded the step at 95 % of the way to zero (down to 1e-3 of it). Masses at round-off
    are now set to zero where they step below it; the steady state is the same."""
    import numpy as np

    import twin.solve.steady as steady
    from twin import Twin

    tw = Twin("B", mill="industrial")
    model, nm = tw.model, tw.model.n_mass
    ss = tw.steady()
    u, d = tw._u(tw.mill.feed_nominal_tph, None), tw._d(None, 1.0)
    empty = np.nonzero(np.asarray(ss.x)[:nm] == 0.0)[0]
    assert empty.size > 0
    real, calls = steady._jacobian_evaluator(model), []

    def counted(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(steady, "_jacobian_evaluator", lambda model: counted)
    rng = np.random.default_rng(0)
    for _ in range(4):
        guess = np.array(ss.x, float)
        guess[:nm] *= 1.0 + 0.3 * rng.standard_normal(nm).clip(-2.0, 2.0)
        steps = {}
        for tiny in (False, True):
            g = guess.copy()
            g[empty] = 10.0 ** rng.uniform(-45.0, -20.0, empty.size) if tiny else 0.0
            calls.clear()
            x, _, ok = steady._newton(model, g, u, d)
            assert ok and np.allclose(x, ss.x, rtol=1e-8, atol=1e-12 * model.spec.holdup_nominal_t)
            steps[tiny] = len(calls)
        assert steps[True] <= steps[False] + 1, steps
