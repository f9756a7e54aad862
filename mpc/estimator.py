"""Extended Kalman filter on the twin model: mill contents and ore hardness from plant sensors.

The augmented state is ``z = [x; h; b]`` with ``x`` the model's states, ``h`` the hardness scale
(the last entry of ``d``, dividing every breakage rate) and ``b`` a bias of the P80 measurement
[um], each a random walk ``h_{k+1} = h_k + w_h`` (the disturbance model of offset-free MPC:
Muske & Badgwell 2002,
"Disturbance modeling for offset-free linear model predictive control", J. Process Control 12,
617-632; Pannocchia & Rawlings 2003, AIChE J. 49, 426-437: with as many integrating
disturbances as measured controlled outputs, a converged estimator removes the steady offset).
The disturbance model (:data:`DISTURBANCE_MODELS`) names what absorbs the plant/model mismatch:
``"hardness"`` (``z = [x; h]``: everything, including a coarse model's structural P80 error, is
read as ore hardness), ``"p80_bias"`` (``z = [x; b]``: hardness held at ``hardness0``; the P80
analyser reads ``P80(x) + b``) or ``"hardness+p80_bias"`` (both: the bias takes the slow P80
mismatch, hardness what also moves load and power).

Filter (Simon, *Optimal State Estimation*, 2006, section 13.2, the discrete EKF): prediction
through ``x_{k+1} = F(x_k, u_k, d_k)`` (:func:`mpc.discretize.rk4_map` over one sample) with the
Jacobian ``A = dF/dz`` from CasADi, ``P <- A P A^T + Q``; update with the measurements present at
this sample, ``K = P C^T (C P C^T + R)^-1``, ``z <- z + K (y - h(z))``, Joseph form
``P <- (I - K C) P (I - K C)^T + K R K^T`` (Simon 2006, eq. 5.19) for numerical symmetry.

Measurements (any may be absent at a sample: pass ``nan``): P80 from the particle-size analyser
(the model's ``p80_measured_um`` when the ``sensor_delay`` effect models the analyser dead time,
else ``p80_um``), mill power [kW] and load (hold-up / nominal). A model whose P80 moves less than
the plant's may carry a P80 gain ``g`` identified on the plant (a step test's steady gain over
the model's): the analyser then reads ``ref + g (P80(x) - ref) + b`` about a reference P80
``ref``, and the controller is handed the bias that holds the plant at its target
(:meth:`Ekf.controller_p80_bias_um`). An analyser sampling every few
minutes gives a new value only at its sample instants; the closed loop passes ``nan`` in
between so a held value is not counted twice.

Ore hardness drifts slowly within a pit and jumps at an ore change: a :class:`ChangeDetector` in
front of the filter lets a slow hardness walk (little analyser noise passed to the inputs) still
follow a jump.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from mpc.codegen import compiled
from mpc.discretize import rk4_sensitivity_map
from mpc.errors import MpcInputError, MpcSolverError, is_blend, is_real
from twin.ore import blend_sum_tolerance

MEASUREMENTS = ("p80_um", "power_kw", "load_frac")
#: Default random-walk intensity of the hardness scale [1/sqrt(h)]: a 1-sigma drift of
#: 0.03 sqrt(24) = 15 % a day (our assumption for ore within a pit): a statement about the ore,
#: not a tuning. Less passes less analyser noise to the inputs, more follows an unmeasured
#: hardness change faster (the trade-off: benchmarks/results/mpc_ekf_tuning.md).
HARDNESS_NOISE_PER_SQRT_H = 0.03
#: Default random-walk intensity of the P80 bias [um/sqrt(h)]: a 1-sigma drift of 5 um in an
#: hour (our assumption: the structural error of a coarse model moves with the operating point
#: over hours, not minutes).
P80_BIAS_NOISE_UM_PER_SQRT_H = 5.0
DISTURBANCE_MODELS = ("hardness", "p80_bias", "hardness+p80_bias")
#: Default RK4 steps per sample of the filter's prediction, the NMPC's default
#: (:attr:`mpc.nmpc.NmpcSettings.rk4_substeps`: stable for the 15-class model at 0.05 h). Explicit
#: RK4 past its stability limit amplifies the fastest mode every step, and the covariance with it
#: (``A P A^T``): the filter diverges. A caller that knows the stable count of its model (a scene's
#: ``controller.rk4_substeps``, checked by the runner) passes at least that.
RK4_SUBSTEPS = 3


@dataclass(frozen=True)
class ChangeDetector:
    """A two-sided CUSUM (Page 1954, Biometrika 41, 100-115) on the P80 analyser's innovation in units of
    its noise. On an alarm the filter is rewound to the sample where the alarming sum last left zero, the
    hardness variance raised by a jump's prior, and rerun over the samples kept.

    ``drift`` and ``threshold``: the CUSUM's k and h in units of the analyser's noise sqrt(R) (0.5 and 4:
    one false alarm per ~170 samples without a change, a 1-sigma shift found in ~8, for innovations of that
    standard deviation; Montgomery, *Introduction to Statistical Quality Control*, the tabular CUSUM's average
    run lengths). The filter's own uncertainty widens the innovations (sqrt(C P C^T + R): 1.07 sqrt(R) on a
    settled small twin, ~105 samples between false alarms). ``jump_sd``: the jump's prior standard
    deviation relative to the hardness estimate (ore types differ in hardness by tens of per cent).
    ``buffer``: samples kept to rewind over (20: 1 h at 3-min samples)."""

    drift: float = 0.5
    threshold: float = 4.0
    jump_sd: float = 0.15
    buffer: int = 20

    def __post_init__(self):
        for name in ("drift", "threshold", "jump_sd"):
            v = getattr(self, name)
            if not (is_real(v) and np.isfinite(v) and v > 0):
                raise MpcInputError(f"The '{name}' parameter of ChangeDetector must be a float > 0. Got {v!r}.")
        if isinstance(self.buffer, bool) or not isinstance(self.buffer, (int, np.integer)) or self.buffer < 1:
            raise MpcInputError(f"The 'buffer' parameter of ChangeDetector must be an int >= 1. Got {self.buffer!r}.")


class Ekf:
    """Extended Kalman filter with random-walk disturbances (hardness scale, P80 bias).

    Parameters
    ----------
    model : twin.model.Model
        The controller's model (same object as the NMPC's).
    dt_h : float
        Sample period [h].
    x0 : array
        Initial state estimate (model states).
    hardness0 : float
        Initial hardness-scale estimate (1 = as calibrated); the fixed value when the
        disturbance model has no hardness.
    p80_noise_um, power_noise_kw, load_noise_frac : float
        Measurement noise standard deviations (R diagonal). The power and load defaults are
        well above a plant sensor's noise: they also cover the structural mismatch of a
        coarse controller model (its hold-up and power differ from the plant's by several
        per cent), which would otherwise be explained by a wrong hardness.
    state_noise_rel : float
        Process-noise standard deviation per sample of each state, relative to its scale
        (``max(|x0|, 1e-3 H_nom)``).
    hardness_noise_per_sqrt_h, p80_bias_noise_um_per_sqrt_h : float
        Random-walk intensities of the hardness scale [1/sqrt(h)] and of the P80 bias
        [um/sqrt(h)]: a variance growing by ``intensity^2 dt_h`` per sample.
    p0_rel, hardness_p0, p80_bias_p0_um : float
        Initial standard deviations (relative for the states, absolute for the disturbances).
    rk4_substeps : int
        RK4 steps per sample (:data:`RK4_SUBSTEPS`); at least the stable count of the model at
        its operating points, else the prediction and the covariance grow without bound.
    hardness_bounds : tuple
        The estimate is clipped to this range.
    disturbance_model : str
        One of :data:`DISTURBANCE_MODELS`.
    p80_gain, p80_reference_um : float
        The analyser reads ``p80_reference_um + p80_gain (P80(x) - p80_reference_um)`` (plus the
        bias): the plant's P80 departs ``p80_gain`` times as far from the reference as the
        model's (module docstring). Default 1, the model's P80 itself; a reference [um] is
        needed with any other gain.
    codegen : str
        The filter step compiled (:func:`mpc.codegen.compiled` mode).
    change_detector : ChangeDetector or None
        A CUSUM in front of the filter that lets the hardness jump (needs a disturbance model with
        the hardness).
    """

    def __init__(self, model, dt_h: float, x0, hardness0: float = 1.0, p80_noise_um: float = 3.0,
                 power_noise_kw: float = 30.0, load_noise_frac: float = 0.1,
                 state_noise_rel: float = 1e-4,
                 hardness_noise_per_sqrt_h: float = HARDNESS_NOISE_PER_SQRT_H,
                 p0_rel: float = 0.05, hardness_p0: float = 0.1, rk4_substeps: int = RK4_SUBSTEPS,
                 hardness_bounds: tuple = (0.3, 3.0), disturbance_model: str = "hardness",
                 p80_bias_noise_um_per_sqrt_h: float = P80_BIAS_NOISE_UM_PER_SQRT_H,
                 p80_bias_p0_um: float = 10.0, p80_gain: float = 1.0, p80_reference_um: float | None = None,
                 codegen: str = "auto", change_detector: ChangeDetector | None = None):
        self.model = model
        if not (is_real(dt_h) and np.isfinite(dt_h) and dt_h > 0):
            raise MpcInputError(f"The 'dt_h' parameter of Ekf must be a float > 0. Got {dt_h!r}.")
        if disturbance_model not in DISTURBANCE_MODELS:
            raise MpcInputError(f"The 'disturbance_model' parameter of Ekf must be one of "
                                f"{DISTURBANCE_MODELS}. Got {disturbance_model!r}.")
        self.dt_h = float(dt_h)
        for name, v in (("p80_noise_um", p80_noise_um), ("power_noise_kw", power_noise_kw),
                        ("load_noise_frac", load_noise_frac), ("state_noise_rel", state_noise_rel),
                        ("hardness_noise_per_sqrt_h", hardness_noise_per_sqrt_h),
                        ("p80_bias_noise_um_per_sqrt_h", p80_bias_noise_um_per_sqrt_h),
                        ("p0_rel", p0_rel), ("hardness_p0", hardness_p0), ("p80_bias_p0_um", p80_bias_p0_um)):
            if not (is_real(v) and np.isfinite(v) and v > 0):
                raise MpcInputError(f"The '{name}' parameter of Ekf must be a float > 0. Got {v!r}.")
        self.p80_gain, self.p80_reference_um = _p80_gain(p80_gain, p80_reference_um)
        self.disturbance_model = disturbance_model
        self.has_hardness = "hardness" in disturbance_model
        self.has_p80_bias = "p80_bias" in disturbance_model
        if change_detector is not None and (not isinstance(change_detector, ChangeDetector) or not self.has_hardness):
            raise MpcInputError(f"The 'change_detector' parameter of Ekf must be a ChangeDetector, with a disturbance "
                                f"model that estimates the hardness. Got {change_detector!r} with "
                                f"{disturbance_model!r}.")
        self.change_detector = change_detector
        self.nx = model.f.size1_in(0)
        self.nd = model.f.size1_in(2)
        x0 = np.asarray(x0, float).reshape(-1)
        if x0.size != self.nx or not np.all(np.isfinite(x0)):
            raise MpcInputError(f"The 'x0' parameter of Ekf must be {self.nx} finite values. "
                                f"Got {x0.size}.")
        self.hardness_bounds = tuple(float(v) for v in hardness_bounds)
        lo_h, hi_h = self.hardness_bounds if len(self.hardness_bounds) == 2 else (np.nan, np.nan)
        if not 0 < lo_h < hi_h < np.inf:
            raise MpcInputError(f"The 'hardness_bounds' parameter of Ekf must be (lo, hi) with 0 < lo < hi, finite. "
                                f"Got {hardness_bounds!r}.")
        if not lo_h <= float(hardness0) <= hi_h:
            raise MpcInputError(f"The 'hardness0' parameter of Ekf must lie in hardness_bounds [{lo_h:g}, {hi_h:g}]. "
                                f"Got {hardness0!r}.")
        self.p80_output = "p80_measured_um" if "p80_measured_um" in model.outputs else "p80_um"
        self.scale = np.maximum(np.abs(x0), 1e-3 * model.spec.holdup_nominal_t)
        # the analyser-lag states (after the masses) get a hundredth of the mass states' noise,
        # so a P80 offset is explained by the disturbances (offset-free), not by the lag chain
        self.n_mass = getattr(model, "n_mass", self.nx)
        rel = np.full(self.nx, float(state_noise_rel))
        rel[self.n_mass:] *= 0.01
        q_d = ([hardness_noise_per_sqrt_h ** 2 * self.dt_h] if self.has_hardness else []) + \
              ([p80_bias_noise_um_per_sqrt_h ** 2 * self.dt_h] if self.has_p80_bias else [])
        self.q = np.diag(np.r_[(rel * self.scale) ** 2, q_d])
        self.r_diag = np.array([p80_noise_um, power_noise_kw, load_noise_frac], float) ** 2
        self._x0, self._h0 = x0.copy(), float(hardness0)
        p0_d = ([hardness_p0 ** 2] if self.has_hardness else []) + ([p80_bias_p0_um ** 2] if self.has_p80_bias else [])
        self._p0 = np.diag(np.r_[(p0_rel * self.scale) ** 2, p0_d])
        if not isinstance(rk4_substeps, (int, np.integer)) or isinstance(rk4_substeps, bool) or rk4_substeps < 1:
            raise MpcInputError(f"The 'rk4_substeps' parameter of Ekf must be an int >= 1. Got {rk4_substeps!r}.")
        self.rk4_substeps = int(rk4_substeps)
        self.step_function = self._step_function(self.rk4_substeps)
        self._step, self.build_report = compiled(self.step_function, codegen)
        self.reset()

    def _step_function(self, rk4_substeps: int) -> ca.Function:
        """``ekf_step(z, P, u, db, y, mask) -> (z+, P+, innovation)``: one predict + update
        (module docstring), measurements with ``mask = 0`` left out (their row of C is zero and
        their innovation 0, which is the update without them); the estimator's whole arithmetic,
        shared by this class and the exported C controller."""
        m, nx, nd = self.model, self.nx, self.nd
        nz = self.q.shape[0]
        F = rk4_sensitivity_map(m, self.dt_h, rk4_substeps, name="ekf_F", with_d=True)
        z, P = ca.MX.sym("z", nz), ca.MX.sym("P", nz, nz)
        u, db = ca.MX.sym("u", m.f.size1_in(1)), ca.MX.sym("db", nd - 1)
        y, mask = ca.MX.sym("y", 3), ca.MX.sym("mask", 3)
        h = z[nx] if self.has_hardness else ca.MX(self._h0)
        x_next, a, _, dd = F(z[:nx], u, ca.vertcat(db, h))
        nd_z = nz - nx
        top = [a] + ([dd[:, -1]] if self.has_hardness else []) + ([ca.MX(nx, 1)] if self.has_p80_bias else [])
        a_z = ca.vertcat(ca.horzcat(*top), ca.horzcat(ca.MX(nd_z, nx), ca.DM.eye(nd_z)))
        zp = ca.vertcat(x_next, z[nx:])
        pp = ca.mtimes([a_z, P, a_z.T]) + ca.DM(self.q)
        ys, us, dbs = ca.SX.sym("z", nz), ca.SX.sym("u", u.numel()), ca.SX.sym("db", nd - 1)
        d_s = ca.vertcat(dbs, ys[nx] if self.has_hardness else self._h0)
        yh = ca.vertcat(self._analyser_p80(m.outputs[self.p80_output](ys[:nx], us, d_s),
                                           ys[-1] if self.has_p80_bias else 0),
                        m.outputs["power_kw"](ys[:nx], us, d_s), m.outputs["load_frac"](ys[:nx], us, d_s))
        meas = ca.Function("ekf_meas", [ys, us, dbs], [yh, ca.jacobian(yh, ys)])
        yhat, c = meas(zp, u, db)
        c = ca.mtimes(ca.diag(mask), c)
        e = mask * (y - yhat)
        r = ca.diag(ca.DM(self.r_diag))
        pct = ca.mtimes(pp, c.T)
        k = ca.solve(ca.mtimes(c, pct) + r, pct.T).T
        ikc = ca.DM.eye(nz) - ca.mtimes(k, c)
        pn = ca.mtimes([ikc, pp, ikc.T]) + ca.mtimes([k, r, k.T])
        zn = zp + ca.mtimes(k, e)
        lo = np.r_[np.zeros(self.n_mass), -np.inf * np.ones(nz - self.n_mass)]
        hi = np.inf * np.ones(nz)
        if self.has_hardness:
            lo[nx], hi[nx] = self.hardness_bounds
        zn = ca.fmin(ca.fmax(zn, ca.DM(np.maximum(lo, -1e300))), ca.DM(np.minimum(hi, 1e300)))
        return ca.Function("ekf_step", [z, P, u, db, y, mask], [zn, 0.5 * (pn + pn.T), e],
                           ["z", "P", "u", "db", "y", "mask"], ["z_next", "P_next", "innovation"])

    def reset(self, x0=None, hardness0: float | None = None) -> None:
        """Back to the initial estimate and covariance."""
        x = self._x0 if x0 is None else np.asarray(x0, float).reshape(-1)
        h = self._h0 if hardness0 is None else float(hardness0)
        if hardness0 is not None and not self.has_hardness:
            self._h0 = h
        self.z = np.r_[x, [h] if self.has_hardness else [], [0.0] if self.has_p80_bias else []]
        self.P = self._p0.copy()
        self.innovation = np.full(3, np.nan)
        self._kept = []  # the change detector's samples: (z, P before it, its step's arguments)
        #: The samples (counted from the last reset, 0 the first) each detected jump was placed at.
        self.jumps: list[int] = []
        self._cusum = {"up": 0.0, "down": 0.0, "up_from": 0, "down_from": 0, "n": 0}

    @property
    def x_est(self) -> np.ndarray:
        return self.z[: self.nx].copy()

    @property
    def hardness_est(self) -> float:
        """The estimated hardness scale (the fixed ``hardness0`` when not estimated)."""
        return float(self.z[self.nx]) if self.has_hardness else self._h0

    @property
    def p80_bias_um(self) -> float:
        """The estimated P80 bias [um] (0 when not modelled): the plant's P80 minus the model's."""
        return float(self.z[-1]) if self.has_p80_bias else 0.0

    def _analyser_p80(self, p80_model_um, bias_um):
        """What the analyser reads when the model's P80 is ``p80_model_um`` (module docstring)."""
        if self.p80_gain == 1.0:
            return p80_model_um + bias_um
        ref = self.p80_reference_um
        return ref + self.p80_gain * (p80_model_um - ref) + bias_um

    def plant_p80_um(self, p80_model_um: float) -> float:
        """The plant's P80 [um] the estimate says goes with the model's ``p80_model_um`` (the
        current P80 bias and the P80 gain applied)."""
        return float(self._analyser_p80(float(p80_model_um), self.p80_bias_um))

    def controller_p80_bias_um(self, target_p80_um: float) -> float:
        """The P80 bias to hand the controller (which holds the model's P80 at ``target - bias``)
        so that the plant's P80 sits at ``target_p80_um``: the P80 bias itself at gain 1, else
        ``target - (ref + (target - b - ref) / g)``."""
        if self.p80_gain == 1.0:
            return self.p80_bias_um
        ref, target = self.p80_reference_um, float(target_p80_um)
        return target - (ref + (target - self.p80_bias_um - ref) / self.p80_gain)

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
        nu, d_all = self.model.f.size1_in(1), np.asarray(d_known, float).reshape(-1)
        if u.size != nu or not np.all(np.isfinite(u)):
            raise MpcInputError(f"The 'u' parameter of Ekf.make_step must be {nu} finite values "
                                f"[feed_tph, speed_frac_critical]. Got {u.tolist()}.")
        if d_all.size not in (self.nd - 1, self.nd) or not is_blend(db):
            raise MpcInputError(f"The 'd_known' parameter of Ekf.make_step must be the {self.nd - 1} blend "
                                f"fractions (a trailing hardness is ignored), finite, in [0, 1], summing to 1 within "
                                f"{blend_sum_tolerance(db.size):g}. Got {d_all.tolist()}.")
        db = db / db.sum()  # rescaled to sum to 1, as the twin's blend
        if not (u[0] >= 0 and 0 < u[1] < 1):  # a feed of -100 t/h emptied the estimated mill, with no word
            raise MpcInputError(f"The 'u' parameter of Ekf.make_step must be the applied feed [t/h] >= 0 and speed "
                                f"[fraction of critical] in (0, 1). Got {u.tolist()}.")
        ok = np.isfinite(y)
        args = (u, db, np.where(ok, y, 0.0), ok.astype(float))
        z, P, e = self._run(self.z, self.P, [args])
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(P))):  # it was kept, and every later step with it
            raise MpcSolverError(f"Ekf.make_step: the update left a non-finite estimate or covariance (y_meas "
                                 f"{y.tolist()}, u {u.tolist()}): the estimate is left as it was before this step; "
                                 "reset() returns to the initial estimate")
        if self.change_detector is not None:
            self._kept.append((self.z.copy(), self.P.copy(), args))
            del self._kept[:-self.change_detector.buffer]
            self._cusum["n"] += 1  # samples, with or without an analyser value: the rewind's index
        self.z, self.P = z, P
        if self.change_detector is not None and ok[0]:
            e = self._detect(e)
        self.innovation = np.where(ok, e, np.nan)
        return self.x_est, np.r_[db, self.hardness_est]

    def _run(self, z, P, steps):
        """The filter over ``steps`` (each its step's arguments) from ``(z, P)``: ``(z, P, last innovation)``."""
        for args in steps:
            zn, pn, e = self._step(z, P, *args)
            z, P = np.asarray(zn, float).ravel(), np.asarray(pn, float)
        return z, P, np.asarray(e, float).ravel()

    def _detect(self, e):
        """The change detector's CUSUM on this sample's P80 innovation ``e[0]``; on an alarm the rewind and
        rerun (:class:`ChangeDetector`). Returns the innovation of this sample as the filter now has it."""
        det, c = self.change_detector, self._cusum
        v = e[0] / self.r_diag[0] ** 0.5
        for side, sign in (("up", 1.0), ("down", -1.0)):
            c[side] = max(0.0, c[side] + sign * v - det.drift)
            if c[side] == 0.0:
                c[side + "_from"] = c["n"]
        side = max(("up", "down"), key=lambda k: c[k])
        if not c[side] > det.threshold:
            return e
        first = max(0, c[side + "_from"] - (c["n"] - len(self._kept)))
        self.jumps.append(c["n"] - len(self._kept) + first)
        z, P = self._kept[first][0].copy(), self._kept[first][1].copy()
        P[self.nx, self.nx] += (det.jump_sd * self.hardness_est) ** 2
        self.z, self.P, e = self._run(z, P, [k[2] for k in self._kept[first:]])
        c.update(up=0.0, down=0.0, up_from=c["n"], down_from=c["n"])
        return e


def _p80_gain(gain, reference_um) -> tuple[float, float | None]:
    """``(gain, reference)`` checked: a finite gain > 0; a finite reference > 0 with any gain but 1."""
    g = float(gain)
    if not (np.isfinite(g) and g > 0):
        raise MpcInputError(f"The 'p80_gain' parameter of Ekf must be a float > 0. Got {gain!r}.")
    if reference_um is None:
        if g != 1.0:
            raise MpcInputError(f"The 'p80_reference_um' parameter of Ekf is needed with a 'p80_gain' other "
                                f"than 1 (the P80 the gain maps deviations from). Got p80_gain {g!r} and no "
                                "reference.")
        return g, None
    ref = float(reference_um)
    if not (np.isfinite(ref) and ref > 0):
        raise MpcInputError(f"The 'p80_reference_um' parameter of Ekf must be a float > 0. Got {reference_um!r}.")
    return g, ref
