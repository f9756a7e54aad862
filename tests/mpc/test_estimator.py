import numpy as np
import pytest

from mpc.errors import MpcInputError
from mpc.estimator import Ekf
from twin.solve.simulate import step


def test_ekf_converges_to_a_hardness_step(ctrl_twin):
    """Plant = the estimator's own model with hardness 1.2 from t = 0 (estimator starts at 1.0);
    noisy P80 every sample: the estimate ends within 0.04 of 1.2 (and did not start there)."""
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    ekf = Ekf(m, 0.05, ss.x, p80_noise_um=1.0)
    rng = np.random.default_rng(3)
    d_plant = m.d_vector([1.0, 0.0], 1.2)
    x = ss.x.copy()
    hs = []
    for _ in range(60):
        x, _, _ = step(m, x, ss.u, d_plant, 0.05)
        def out(name):  # (Model.evaluate fails on a 1x1 output under numpy 2)
            return float(m.outputs[name](x, ss.u, d_plant))

        y = [out("p80_measured_um") + rng.normal(0, 1.0), out("power_kw"), out("load_frac")]
        _, d_est = ekf.make_step(y, ss.u, [1.0, 0.0])
        hs.append(d_est[-1])
    assert abs(hs[0] - 1.2) > 0.05
    assert abs(np.mean(hs[-10:]) - 1.2) < 0.04


def test_ekf_rejects_bad_input(ctrl_twin):
    m = ctrl_twin.model
    with pytest.raises(MpcInputError, match="dt_h"):
        Ekf(m, -1.0, m.initial_state([1.0, 0.0]))
    ekf = Ekf(m, 0.05, m.initial_state([1.0, 0.0]))
    with pytest.raises(MpcInputError, match="y_meas"):
        ekf.make_step([1.0, 2.0], [27.0, 0.7], [1.0, 0.0])
    z0 = ekf.z.copy()
    # a NaN or missing input or blend wrecked the estimate for good (the bounds clamp turned NaN
    # into finite garbage); now refused before the filter moves
    for u, d, name in (([np.nan, 0.7], [1.0, 0.0], "'u'"), ([28.0], [1.0, 0.0], "'u'"),
                       ([27.0, 0.7], [np.nan, 1.0], "'d_known'"), ([27.0, 0.7], [1.0], "'d_known'")):
        with pytest.raises(MpcInputError, match=name):
            ekf.make_step([210.0, 180.0, 1.0], u, d)
    assert np.array_equal(ekf.z, z0)
    with pytest.raises(MpcInputError, match="hardness_bounds"):
        Ekf(m, 0.05, m.initial_state([1.0, 0.0]), hardness_bounds=(3.0, 0.3))
    with pytest.raises(MpcInputError, match="hardness0"):
        Ekf(m, 0.05, m.initial_state([1.0, 0.0]), hardness0=10.0)


def test_an_update_that_leaves_a_non_finite_covariance_is_refused_and_not_kept(ctrl_twin):
    """A P80 of 1e9 um (a stuck analyser's count) drove the estimate to 1e6 and the next update's covariance to
    NaN; the EKF kept it and every later step ran from it, without a word (the exported C resets, the
    scene's loop too). Now the update is refused, the estimate left as it was, and reset() goes back."""
    from mpc.errors import MpcSolverError

    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    ekf = Ekf(m, 0.05, ss.x, p80_noise_um=1.0)
    refused = 0
    for y in ([1e9, 1e9, 1e9], [210.0, np.nan, np.nan], [210.0, np.nan, np.nan]):
        z, P = ekf.z.copy(), ekf.P.copy()
        try:
            ekf.make_step(y, ss.u, [1.0, 0.0])
        except MpcSolverError as exc:
            refused += 1
            assert "non-finite estimate or covariance" in str(exc)
            assert np.array_equal(ekf.z, z) and np.array_equal(ekf.P, P)  # nothing kept
        assert np.all(np.isfinite(ekf.z)) and np.all(np.isfinite(ekf.P))
    assert refused >= 1
    ekf.reset()
    ekf.make_step([210.0, np.nan, np.nan], ss.u, [1.0, 0.0])
    assert np.all(np.isfinite(ekf.P))


@pytest.mark.parametrize("gain", [1.0, 2.0])
def test_ekf_reads_the_analyser_through_its_p80_gain(ctrl_twin, gain):
    """A plant whose P80 sits 6 um above the model's steady one, read by an EKF whose P80 gain
    is g about that steady P80: the estimate moves the model's P80 by 6/g um (the hardness
    takes it), and what it believes the plant reads is the measurement (the test can fail: at
    g = 2 the model moves half as far as at g = 1)."""
    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])
    ref = float(m.outputs["p80_measured_um"](ss.x, ss.u, ss.d))
    ekf = Ekf(m, 0.05, ss.x, p80_noise_um=1.0, hardness_noise_per_sqrt_h=0.1, p80_gain=gain, p80_reference_um=ref)
    for _ in range(120):
        x_est, d_est = ekf.make_step([ref + 6.0, np.nan, np.nan], ss.u, [1.0, 0.0])
    p80_model = float(m.outputs["p80_measured_um"](x_est, ss.u, d_est))
    assert p80_model - ref == pytest.approx(6.0 / gain, abs=0.1)
    assert ekf.plant_p80_um(p80_model) == pytest.approx(ref + 6.0, abs=0.1)


@pytest.mark.parametrize("model", ["hardness", "hardness+p80_bias"])
def test_the_controller_bias_puts_the_plant_at_its_target(ctrl_twin, model):
    """The model held at target - controller bias reads as the target on the plant, whatever
    the gain, reference and bias; at gain 1 the controller bias is the P80 bias itself."""
    m = ctrl_twin.model
    x0 = m.initial_state([1.0, 0.0])
    for gain, ref, bias, target in [(1.0, None, 4.0, 200.0), (1.9, 94.0, 0.0, 94.0), (1.9, 94.0, -3.0, 90.0),
                                    (0.6, 210.0, 7.0, 215.0)]:
        ekf = Ekf(m, 0.05, x0, disturbance_model=model, p80_gain=gain, p80_reference_um=ref)
        if ekf.has_p80_bias:
            ekf.z[-1] = bias
        b = ekf.controller_p80_bias_um(target)
        assert ekf.plant_p80_um(target - b) == pytest.approx(target, abs=1e-9)
        if gain == 1.0:
            assert b == ekf.p80_bias_um


def test_ekf_refuses_a_bad_p80_gain(ctrl_twin):
    x0 = ctrl_twin.model.initial_state([1.0, 0.0])
    with pytest.raises(MpcInputError, match="'p80_gain'.*Got 0.0"):
        Ekf(ctrl_twin.model, 0.05, x0, p80_gain=0.0, p80_reference_um=94.0)
    with pytest.raises(MpcInputError, match="'p80_reference_um'.*needed"):
        Ekf(ctrl_twin.model, 0.05, x0, p80_gain=2.0)
    with pytest.raises(MpcInputError, match="'p80_reference_um'.*Got -1"):
        Ekf(ctrl_twin.model, 0.05, x0, p80_gain=2.0, p80_reference_um=-1.0)


def _hardness_run(m, ss, ekf, h_after, n_before=10, n_after=25, noise_um=0.0, every=1):
    """The estimator's own model as the plant, hardness 1.0 then ``h_after``, its P80 read every ``every``
    samples; the estimates per sample."""
    rng = np.random.default_rng(5)
    x, hs = ss.x.copy(), []
    for k in range(n_before + n_after):
        d_plant = m.d_vector([1.0, 0.0], 1.0 if k < n_before else h_after)
        x, _, _ = step(m, x, ss.u, d_plant, 0.05)
        y = [float(m.outputs[name](x, ss.u, d_plant)) for name in ("p80_measured_um", "power_kw", "load_frac")]
        y[0] += rng.normal(0, noise_um) if noise_um else 0.0
        hs.append(ekf.make_step([y[0] if k % every == 0 else np.nan, np.nan, np.nan], ss.u, [1.0, 0.0])[1][-1])
    return np.array(hs)


def test_change_detector_places_a_jump_where_it_happened_and_follows_it(ctrl_twin):
    """A CUSUM in front of the filter (Page 1954): a +25 % hardness jump at sample 10, the analyser read every
    second sample with 3 um noise: the detector places the jump at sample 10 or the next (where its sum
    left zero), rewinds there and the estimate follows to within 0.03. Without a change and without noise
    it leaves the filter as it is, bit for bit."""
    from mpc import ChangeDetector

    m = ctrl_twin.model
    ss = ctrl_twin.steady(feed_tph=27.0, speed_frac_critical=0.70, blend=[1.0, 0.0])

    def ekf(det):
        return Ekf(m, 0.05, ss.x, p80_noise_um=3.0, hardness_noise_per_sqrt_h=0.03, change_detector=det)

    assert np.array_equal(_hardness_run(m, ss, ekf(None), 1.0), _hardness_run(m, ss, ekf(ChangeDetector()), 1.0))
    est = ekf(ChangeDetector())
    hs = _hardness_run(m, ss, est, 1.25, noise_um=3.0, every=2)
    assert est.jumps and est.jumps[0] in (10, 11)
    assert abs(hs[-1] - 1.25) < 0.03


def test_change_detector_refuses_what_it_cannot_use(ctrl_twin):
    from mpc import ChangeDetector

    for kw, name in ((dict(drift=0.0), "drift"), (dict(threshold=float("nan")), "threshold"),
                     (dict(jump_sd=True), "jump_sd"), (dict(buffer=0), "buffer"), (dict(buffer=2.5), "buffer")):
        with pytest.raises(MpcInputError, match=f"'{name}' parameter of ChangeDetector"):
            ChangeDetector(**kw)
    x0 = ctrl_twin.model.initial_state([1.0, 0.0])
    with pytest.raises(MpcInputError, match="'change_detector' parameter of Ekf .* estimates the hardness"):
        Ekf(ctrl_twin.model, 0.05, x0, disturbance_model="p80_bias", change_detector=ChangeDetector())


def test_a_blend_of_rounded_fractions_is_estimated_on_rescaled_to_sum_to_one(ctrl_twin):
    """d_known = [0.6004, 0.4] (within the twin's tolerance) fed the model 0.04 % more ore than the feed; now it
    is rescaled to sum to 1, as the twin rescales a blend: the estimate of the rescaled blend's."""
    m = ctrl_twin.model
    rounded = np.array([0.6004, 0.4])
    estimates = []
    for blend in (rounded, rounded / rounded.sum()):
        ekf = Ekf(m, 0.05, m.initial_state([0.6, 0.4]), p80_noise_um=1.0)
        estimates.append(ekf.make_step([210.0, np.nan, np.nan], [27.0, 0.7], blend)[0])
    assert np.allclose(estimates[0], estimates[1], rtol=1e-12, atol=0)
