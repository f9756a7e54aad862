"""The baselines an MPC is judged against: no control (fixed inputs) and the reactive practice,
a PI from measured P80 to feed rate tuned by SIMC on the linearised plant."""

from __future__ import annotations

import numpy as np

from mpc.linear import Fopdt, feed_step_fopdt
from mpc.pi import DiscretePI
from mpc.results import ControllerStepResult
from mpc.sensors import Sensors


class FixedInputs:
    """No control: the inputs stay at ``u_fixed`` (e.g. the steady-state setpoints)."""

    def __init__(self, u_fixed):
        self.u_fixed = np.asarray(u_fixed, float).reshape(-1)

    def make_step(self, x_est, d_preview, u_prev, y_meas=None) -> ControllerStepResult:
        return ControllerStepResult(True, "fixed", 0.0, 0, 0.0, self.u_fixed.copy())


class PiFeedback:
    """The reactive practice: a :class:`mpc.pi.DiscretePI` from measured P80 to feed rate, the
    speed held at ``speed_frac_critical``. Before the first analyser reading the input is held."""

    def __init__(self, pi, speed_frac_critical: float):
        self.pi = pi
        self.speed = float(speed_frac_critical)

    def make_step(self, x_est, d_preview, u_prev, y_meas=None) -> ControllerStepResult:
        if y_meas is None or not np.isfinite(y_meas):
            return ControllerStepResult(True, "no measurement", 0.0, 0, 0.0,
                                        [float(np.asarray(u_prev)[0]), self.speed])
        feed = self.pi.make_step(float(y_meas))
        r = self.pi.last_result
        return ControllerStepResult(True, r.status, r.cost, 0, r.solve_time_s, [feed, self.speed])


def pi_baseline(plant_model, steady, sensors: Sensors, dt_h: float, target_p80_um: float,
                feed_tph_min: float = 20.0, feed_tph_max: float = 45.0,
                feed_rate_max_tph_per_h: float = 20.0, tau_c_h: float | None = None):
    """PI P80 -> feed tuned by SIMC (Skogestad 2003) on the linearised plant at ``steady``
    (``plant_model``: a twin's model, or any model with ``f(x, u, d)`` and ``outputs['p80_um']``
    such as :class:`mpc.plants.leroux.LeRouxCircuit`; ``steady``: a :class:`twin.solve.steady.SteadyState`
    or anything with its ``x``, ``u``, ``d``): FOPDT fit of the feed -> P80 step response
    (:func:`mpc.linear.feed_step_fopdt`), its dead time increased by the analyser dead time
    plus half the sampling period (the mean delay of a sample-and-hold; Seborg et al. 2011,
    sec. 17.1). Returns ``(PiFeedback, Fopdt)``."""
    f = feed_step_fopdt(plant_model, steady.x, steady.u, steady.d)
    f = Fopdt(f.gain, f.tau_h, f.delay_h + sensors.p80_dead_time_h
              + 0.5 * sensors.p80_sample_period_h, f.rms_error)
    pi = DiscretePI.from_fopdt(f, dt_h, target_p80_um, float(steady.u[0]), tau_c_h=tau_c_h,
                               u_min=feed_tph_min, u_max=feed_tph_max,
                               du_max=feed_rate_max_tph_per_h * dt_h)
    return PiFeedback(pi, float(steady.u[1])), f
