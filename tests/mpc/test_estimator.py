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
