"""Extended Kalman filter on the twin model: mill contents and ore hardness from plant sensors.

The augmented state is ``z = [x; h]`` with ``x`` the model's states and ``h`` the hardness scale
(the last entry of ``d``, dividing every breakage rate), modelled as a random walk
``h_{k+1} = h_k + w_h`` (the disturbance model of offset-free MPC: Muske & Badgwell 2002,
"Disturbance modeling for offset-free linear model predictive control", J. Process Control 12,
617-632; Pannocchia & Rawlings 2003, AIChE J. 49, 426-437: with as many integrating
disturbances as measured controlled outputs, a converged estimator removes the steady offset).

Filter (Simon, *Optimal State Estimation*, 2006, section 13.2, the discrete EKF): prediction
through ``x_{k+1} = F(x_k, u_k, d_k)`` (:func:`mpc.discretize.rk4_map` over one sample) with the
Jacobian ``A = dF/dz`` from CasADi, ``P <- A P A^T + Q``; update with the measurements present at
this sample, ``K = P C^T (C P C^T + R)^-1``, ``z <- z + K (y - h(z))``, Joseph form
``P <- (I - K C) P (I - K C)^T + K R K^T`` (Simon 2006, eq. 5.19) for numerical symmetry.

Measurements (any may be absent at a sample: pass ``nan``): P80 from the particle-size analyser
(the model's ``p80_measured_um`` when the ``sensor_delay`` effect models the analyser dead time,
else ``p80_um``), mill power [kW] and load (hold-up / nominal). An analyser sampling every few
minutes gives a new value only at its sample instants; the closed loop passes ``nan`` in
between so a held value is not counted twice.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from mpc.discretize import rk4_map
from mpc.errors import MpcInputError

MEASUREMENTS = ("p80_um", "power_kw", "load_frac")
#: Default random-walk intensity of the hardness scale [1/sqrt(h)]: a 1-sigma drift of
#: 0.03 sqrt(24) = 15 % a day (our assumption for ore within a pit). Measured on the reference
#: case (benchmarks/results/mpc_ekf_tuning.md): 0.02-0.03 give the least IAE both through the
#: measured ore change and after an unmeasured +10 % hardness step; 0.1 passes the analyser's
#: noise to the inputs (IAE 14.8 against 9.6 um h).
HARDNESS_NOISE_PER_SQRT_H = 0.03


class Ekf:
    """Extended Kalman filter with a random-walk hardness disturbance.

    Parameters
    ----------
    model : twin.model.Model
        The controller's model (same object as the NMPC's).
    dt_h : float
        Sample period [h].
    x0 : array
        Initial state estimate (model states).
    hardness0 : float
        Initial hardness-scale estimate (1 = as calibrated).
    p80_noise_um, power_noise_kw, load_noise_frac : float
        Measurement noise standard deviations (R diagonal). The power and load defaults are
        well above a plant sensor's noise: they also cover the structural mismatch of a
        coarse controller model (its hold-up and power differ from the plant's by several
        per cent), which would otherwise be explained by a wrong hardness.
    state_noise_rel : float
        Process-noise standard deviation per sample of each state, relative to its scale
        (``max(|x0|, 1e-3 H_nom)``).
    hardness_noise_per_sqrt_h : float
        Random-walk intensity of the hardness scale [1/sqrt(h)]: its variance grows by
        ``hardness_noise_per_sqrt_h^2 dt_h`` per sample. Larger: faster, noisier estimate.
    p0_rel, hardness_p0 : float
        Initial standard deviations (relative for the states, absolute for the hardness).
    rk4_substeps : int
        RK4 steps per sample.
    hardness_bounds : tuple
        The estimate is clipped to this range.
    """

    def __init__(self, model, dt_h: float, x0, hardness0: float = 1.0, p80_noise_um: float = 3.0,
                 power_noise_kw: float = 30.0, load_noise_frac: float = 0.1,
                 state_noise_rel: float = 1e-4,
                 hardness_noise_per_sqrt_h: float = HARDNESS_NOISE_PER_SQRT_H,
                 p0_rel: float = 0.05, hardness_p0: float = 0.1, rk4_substeps: int = 3,
                 hardness_bounds: tuple = (0.3, 3.0)):
        self.model = model
        if not (np.isfinite(dt_h) and dt_h > 0):
            raise MpcInputError(f"The 'dt_h' parameter of Ekf must be a float > 0. Got {dt_h!r}.")
        self.dt_h = float(dt_h)
        for name, v in (("p80_noise_um", p80_noise_um), ("power_noise_kw", power_noise_kw),
                        ("load_noise_frac", load_noise_frac), ("state_noise_rel", state_noise_rel),
                        ("hardness_noise_per_sqrt_h", hardness_noise_per_sqrt_h),
                        ("p0_rel", p0_rel), ("hardness_p0", hardness_p0)):
            if not (np.isfinite(v) and v > 0):
                raise MpcInputError(f"The '{name}' parameter of Ekf must be a float > 0. Got {v!r}.")
        self.nx = model.f.size1_in(0)
        self.nd = model.f.size1_in(2)
        x0 = np.asarray(x0, float).reshape(-1)
        if x0.size != self.nx or not np.all(np.isfinite(x0)):
            raise MpcInputError(f"The 'x0' parameter of Ekf must be {self.nx} finite values. "
                                f"Got {x0.size}.")
        self.hardness_bounds = tuple(float(v) for v in hardness_bounds)
        self.p80_output = "p80_measured_um" if "p80_measured_um" in model.outputs else "p80_um"
        self.scale = np.maximum(np.abs(x0), 1e-3 * model.spec.holdup_nominal_t)
        # the analyser-lag states (after the masses) get a hundredth of the mass states' noise,
        # so a P80 offset is explained by hardness (offset-free), not by the lag chain
        n_mass = getattr(model, "n_mass", self.nx)
        rel = np.full(self.nx, float(state_noise_rel))
        rel[n_mass:] *= 0.01
        self.q = np.diag(np.r_[(rel * self.scale) ** 2,
                               hardness_noise_per_sqrt_h ** 2 * self.dt_h])
        self.r_diag = np.array([p80_noise_um, power_noise_kw, load_noise_frac], float) ** 2
        self._x0, self._h0 = x0.copy(), float(hardness0)
        self._p0 = np.diag(np.r_[(p0_rel * self.scale) ** 2, hardness_p0 ** 2])
        # symbolic prediction and measurement with their Jacobians (built once)
        F = rk4_map(model.f, self.dt_h, rk4_substeps, name="ekf_F").expand()
        z = ca.SX.sym("z", self.nx + 1)
        u = ca.SX.sym("u", model.f.size1_in(1))
        db = ca.SX.sym("db", self.nd - 1)  # known blend fractions
        d = ca.vertcat(db, z[-1])
        zn = ca.vertcat(F(z[:-1], u, d), z[-1])
        y = ca.vertcat(model.outputs[self.p80_output](z[:-1], u, d),
                       model.outputs["power_kw"](z[:-1], u, d),
                       model.outputs["load_frac"](z[:-1], u, d))
        self._pred = ca.Function("ekf_pred", [z, u, db], [zn, ca.jacobian(zn, z)])
        self._meas = ca.Function("ekf_meas", [z, u, db], [y, ca.jacobian(y, z)])
        self.reset()

    def reset(self, x0=None, hardness0: float | None = None) -> None:
        """Back to the initial estimate and covariance."""
        x = self._x0 if x0 is None else np.asarray(x0, float).reshape(-1)
        h = self._h0 if hardness0 is None else float(hardness0)
        self.z = np.r_[x, h]
        self.P = self._p0.copy()
        self.innovation = np.full(3, np.nan)

    @property
    def x_est(self) -> np.ndarray:
        return self.z[:-1].copy()

    @property
    def hardness_est(self) -> float:
        return float(self.z[-1])

    def make_step(self, y_meas, u, d_known):
        """One sample: predict over the last period with the input ``u`` and known
        disturbances ``d_known`` applied over it (blend fractions; a trailing hardness entry,
        if given, is ignored), then update with ``y_meas = [p80_um, power_kw, load_frac]``
        (``nan`` for a measurement absent at this sample). Returns ``(x_est, d_est)`` with
        ``d_est = [blend..., hardness_est]``."""
        u = np.asarray(u, float).reshape(-1)
        db = np.asarray(d_known, float).reshape(-1)[: self.nd - 1]
        y = np.asarray(y_meas, float).reshape(-1)
        if y.size != 3:
            raise MpcInputError(f"The 'y_meas' parameter of Ekf.make_step must be "
                                f"[p80_um, power_kw, load_frac]. Got {y.size} values.")
        zn, a = self._pred(self.z, u, db)
        self.z = np.asarray(zn, float).ravel()
        a = np.asarray(a, float)
        self.P = a @ self.P @ a.T + self.q
        ok = np.isfinite(y)
        self.innovation = np.full(3, np.nan)
        if ok.any():
            yh, c = self._meas(self.z, u, db)
            yh, c = np.asarray(yh, float).ravel()[ok], np.asarray(c, float)[ok]
            r = np.diag(self.r_diag[ok])
            s = c @ self.P @ c.T + r
            k = np.linalg.solve(s, c @ self.P).T
            e = y[ok] - yh
            self.innovation[ok] = e
            self.z = self.z + k @ e
            ikc = np.eye(self.z.size) - k @ c
            self.P = ikc @ self.P @ ikc.T + k @ r @ k.T
        self.P = 0.5 * (self.P + self.P.T)
        n_mass = getattr(self.model, "n_mass", self.nx)
        self.z[:n_mass] = np.maximum(self.z[:n_mass], 0.0)
        self.z[-1] = float(np.clip(self.z[-1], *self.hardness_bounds))
        return self.x_est, np.r_[db, self.z[-1]]
