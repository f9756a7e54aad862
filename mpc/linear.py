"""Linear analysis of a CasADi model and a condensed linear MPC.

Works on the generic model contract of the twin (and of :mod:`mpc.plants.leroux`): a casadi.Function
``f(x, u, d) -> xdot`` (time in hours) and output functions ``outputs[name](x, u, d) -> y``.

- :func:`linearize` - Jacobians at an operating point into a continuous ``control.StateSpace``
  in deviation variables (``dx = x - x_ss``, ``du = u - u_ss``, ``dy = y - y_ss``);
- :func:`discretize` - zero-order-hold sampling (``control.sample_system``, method ``"zoh"``);
- :func:`gain_table` - steady-state gain and dominant time constant of every input-output
  channel, as a pandas DataFrame;
- :func:`step_moments` / :func:`step_test` - steady gain and mean response time of a channel,
  exact from the transfer function: ``K = G(0)``, ``T = -G'(0) / G(0)``, the first moment of
  the impulse response over its area, equal to the area between the normalised step response
  and 1 (method of moments, Seborg et al. 2011, *Process Dynamics and Control*, 3rd ed.,
  sec. 6.2: the mean times of lags in series add, a FOPDT's is ``tau + theta``);
- :func:`fit_fopdt` / :func:`fopdt_from_model` - first-order-plus-dead-time fit of a step
  response (least squares, started from the two-point estimate ``tau = 1.5 (t63 - t28)``,
  ``theta = t63 - tau``, exact for a FOPDT since it reaches 28.3 % = 1 - exp(-1/3) of its
  final value at ``theta + tau/3`` and 63.2 % at ``theta + tau``);
- :class:`LinearMPC` - linear MPC on a discrete ``StateSpace``, condensed to a QP in the
  input sequence (Maciejowski, *Predictive Control with Constraints*, 2002, ch. 3; Rawlings,
  Mayne & Diehl, *Model Predictive Control*, 2nd ed., section 1.3). Without constraints its
  first move is ``u0 = -K x0``; with a long horizon ``K`` tends to the discrete LQR gain, and
  with the Riccati solution as terminal weight it equals it for any horizon (Rawlings et al.,
  section 1.3.3).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np
import pandas as pd
import scipy.linalg
import scipy.optimize

from mpc.errors import MpcInputError
from mpc.qpsol import conic
from mpc.results import ControllerStepResult

if TYPE_CHECKING:
    import control


def _control():
    """python-control, imported on first use: it loads matplotlib and scipy.signal (over a second
    at every start of the command line); only the linear tools below use it."""
    import control

    return control


# --------------------------------------------------------------------------- linearisation
@dataclass(frozen=True)
class OperatingPoint:
    """An operating point ``(x_ss, u_ss, d_ss)`` and the outputs ``y_ss`` there."""

    x_ss: np.ndarray
    u_ss: np.ndarray
    d_ss: np.ndarray
    y_ss: np.ndarray
    output_names: tuple[str, ...]


def _as_vec(name: str, value, size: int | None = None) -> np.ndarray:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if size is not None and arr.size != size:
        raise MpcInputError(f"The '{name}' parameter must have {size} entries. Got {arr.size}.")
    if not np.all(np.isfinite(arr)):
        raise MpcInputError(f"The '{name}' parameter must be finite. Got {arr!r}.")
    return arr


def linearize(
    f: ca.Function,
    outputs: dict[str, ca.Function],
    x_ss,
    u_ss,
    d_ss,
    output_names,
    input_names: tuple[str, ...] = ("feed_tph", "speed_frac_critical"),
    include_disturbances: bool = False,
    disturbance_names: tuple[str, ...] | None = None,
    steady_tol: float | None = 1e-6,
) -> tuple[control.StateSpace, OperatingPoint]:
    """Linearise ``f`` and the chosen outputs at ``(x_ss, u_ss, d_ss)``.

    Returns a continuous-time ``control.StateSpace`` (time unit: hour) in deviation variables
    with inputs ``u`` (and, if ``include_disturbances``, then ``d``, named by
    ``disturbance_names``), outputs in the order of
    ``output_names``, and the :class:`OperatingPoint`. If ``steady_tol`` is not None the point
    must be a steady state: ``max |f(x_ss, u_ss, d_ss)| <= steady_tol``.
    """
    nx, nu, nd = f.size1_in(0), f.size1_in(1), f.size1_in(2)
    x_ss = _as_vec("x_ss", x_ss, nx)
    u_ss = _as_vec("u_ss", u_ss, nu)
    d_ss = _as_vec("d_ss", d_ss, nd)
    output_names = tuple(output_names)
    if not output_names:
        raise MpcInputError("The 'output_names' parameter must name at least one output. Got ().")
    unknown = [n for n in output_names if n not in outputs]
    if unknown:
        raise MpcInputError(
            f"The 'output_names' parameter has unknown outputs {unknown}; "
            f"allowed: {sorted(outputs)}."
        )
    vector = [n for n in output_names
              if outputs[n].size1_out(0) * outputs[n].size2_out(0) != 1]
    if vector:
        raise MpcInputError(f"The 'output_names' parameter must name scalar outputs; "
                            f"{vector} are vectors.")
    if len(input_names) != nu:
        raise MpcInputError(
            f"The 'input_names' parameter must have {nu} names. Got {len(input_names)}."
        )
    if steady_tol is not None:
        res = float(np.abs(np.array(f(x_ss, u_ss, d_ss))).max())
        if not res <= steady_tol:
            raise MpcInputError(
                f"The operating point must be a steady state: max |f| must be <= {steady_tol}. "
                f"Got {res:.3g}."
            )
    x = ca.SX.sym("x", nx)
    u = ca.SX.sym("u", nu)
    d = ca.SX.sym("d", nd)
    xdot = f(x, u, d)
    y = ca.vertcat(*[outputs[n](x, u, d) for n in output_names])
    jac = ca.Function(
        "linearize_jacobians",
        [x, u, d],
        [ca.jacobian(xdot, x), ca.jacobian(xdot, u), ca.jacobian(xdot, d),
         ca.jacobian(y, x), ca.jacobian(y, u), ca.jacobian(y, d), y],
    )
    a, b, bd, c, dd, ddist, y0 = (np.array(m, dtype=float) for m in jac(x_ss, u_ss, d_ss))
    inputs = list(input_names)
    if include_disturbances:
        b = np.hstack([b, bd])
        dd = np.hstack([dd, ddist])
        dn = tuple(f"d{i}" for i in range(nd)) if disturbance_names is None else tuple(disturbance_names)
        if len(dn) != nd:
            raise MpcInputError(f"The 'disturbance_names' parameter must have {nd} names. "
                                f"Got {len(dn)}.")
        inputs += list(dn)
    sys = _control().ss(a, b, c, dd, inputs=inputs, outputs=list(output_names),
                        states=[f"x{i}" for i in range(nx)], name="linearized")
    op = OperatingPoint(x_ss, u_ss, d_ss, y0.reshape(-1), output_names)
    return sys, op


def discretize(sys_c: control.StateSpace, dt_h: float) -> control.StateSpace:
    """Zero-order-hold discretisation with sample period ``dt_h`` (hours)."""
    if not (np.isfinite(dt_h) and dt_h > 0):
        raise MpcInputError(f"The 'dt_h' parameter must be a float > 0. Got {dt_h!r}.")
    if not _control().isctime(sys_c, strict=True):
        raise MpcInputError("The 'sys_c' parameter must be a continuous-time StateSpace.")
    return _control().sample_system(sys_c, dt_h, method="zoh")


# --------------------------------------------------------------------------- gains, tau
def _step_channel(sys_c: control.StateSpace, i_in: int, i_out: int, t_h: np.ndarray):
    siso = _control().ss(sys_c.A, sys_c.B[:, [i_in]], sys_c.C[[i_out], :], sys_c.D[[i_out], [i_in]])
    resp = _control().step_response(siso, T=t_h)
    return np.asarray(resp.outputs, dtype=float).reshape(-1)


def gain_table(sys_c: control.StateSpace, horizon_factor: float = 6.0,
               n_points: int = 4001) -> pd.DataFrame:
    """Steady-state gain and time constants of every input-output channel.

    Columns: ``input``, ``output``, ``gain`` (output units per input unit),
    ``tau_dominant_h`` (time constant ``-1/Re(lambda)`` of the slowest mode whose share of the
    channel's steady-state gain is at least 5 %, from the modal decomposition of ``A``) and
    ``t63_h`` (time for the step response to reach 63.2 % of its final value).
    The system must be asymptotically stable.
    """
    a, b, c, d = (np.asarray(m, dtype=float) for m in (sys_c.A, sys_c.B, sys_c.C, sys_c.D))
    lam, v = np.linalg.eig(a)
    if np.any(lam.real >= 0):
        raise MpcInputError(
            "The 'sys_c' parameter of gain_table must be asymptotically stable. "
            f"Got eigenvalues with Re >= 0: {lam[lam.real >= 0]}."
        )
    w = np.linalg.inv(v)
    gains = d - c @ np.linalg.solve(a, b)
    # round-off zeros (e.g. a conserved quantity) to exact zeros, relative to the channel scale
    scale = np.abs(d) + np.abs(c) @ np.abs(np.linalg.solve(a, b))
    gains[np.abs(gains) <= 1e-10 * scale] = 0.0
    tau_max = float(np.max(-1.0 / lam.real))
    t_h = np.linspace(0.0, horizon_factor * tau_max, n_points)
    rows = []
    for j, iname in enumerate(sys_c.input_labels):
        for i, oname in enumerate(sys_c.output_labels):
            share = np.real(-(c[i, :] @ v) * (w @ b[:, j]) / lam)  # DC contribution per mode
            total = np.sum(np.abs(share))
            if total > 0:
                significant = np.abs(share) >= 0.05 * total
                tau_dom = float(np.max(-1.0 / lam.real[significant]))
            else:
                tau_dom = float("nan")
            yv = _step_channel(sys_c, j, i, t_h)
            k = gains[i, j]
            if k != 0 and np.isfinite(k):
                reached = np.nonzero(yv / k >= 1.0 - np.exp(-1.0))[0]
                t63 = float(t_h[reached[0]]) if reached.size else float("nan")
            else:
                t63 = float("nan")
            rows.append({"input": iname, "output": oname, "gain": float(k),
                         "tau_dominant_h": tau_dom, "t63_h": t63})
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- moments
@dataclass(frozen=True)
class StepMoments:
    """Steady gain and mean response time of one channel (module docstring)."""

    gain: float
    """``G(0)``, output units per input unit."""
    mean_time_h: float
    """``-G'(0) / G(0)`` [h]: the area between the normalised step response and 1."""


def _channel(sys_c: control.StateSpace, input_name: str, output_name: str) -> tuple[int, int]:
    if input_name not in sys_c.input_labels:
        raise MpcInputError(
            f"The 'input_name' parameter must be one of {sys_c.input_labels}. Got {input_name!r}."
        )
    if output_name not in sys_c.output_labels:
        raise MpcInputError(
            f"The 'output_name' parameter must be one of {sys_c.output_labels}. "
            f"Got {output_name!r}."
        )
    return sys_c.input_labels.index(input_name), sys_c.output_labels.index(output_name)


def step_moments(sys_c: control.StateSpace, input_name: str, output_name: str) -> StepMoments:
    """Gain and mean response time of a continuous, asymptotically stable channel, from
    ``G(s) = C (sI - A)^-1 B + D``: ``G(0) = D - C A^-1 B`` and ``G'(0) = -C A^-2 B``."""
    if not _control().isctime(sys_c, strict=True):
        raise MpcInputError("The 'sys_c' parameter of step_moments must be a continuous-time StateSpace.")
    j, i = _channel(sys_c, input_name, output_name)
    a, b, c, d = (np.asarray(m, dtype=float) for m in (sys_c.A, sys_c.B, sys_c.C, sys_c.D))
    lam = np.linalg.eigvals(a)
    if np.any(lam.real >= 0):
        raise MpcInputError("The 'sys_c' parameter of step_moments must be asymptotically stable. "
                            f"Got eigenvalues with Re >= 0: {lam[lam.real >= 0]}.")
    a_inv_b = np.linalg.solve(a, b[:, j])
    gain = float(d[i, j] - c[i] @ a_inv_b)
    if gain == 0.0:
        raise MpcInputError(f"The channel {input_name} -> {output_name} has zero steady gain: "
                            "its mean response time is undefined.")
    return StepMoments(gain, float(c[i] @ np.linalg.solve(a, a_inv_b)) / gain)


def step_test(model, x_ss, u_ss, d_ss, input_name: str, output_name: str = "p80_um",
              steady_tol: float = 1e-4) -> StepMoments:
    """A step test on ``model`` (anything with ``f(x, u, d)`` and ``outputs``: a twin's model or
    :class:`mpc.plants.leroux.LeRouxCircuit`) at its steady state: :func:`step_moments` of the
    linearised ``input_name -> output_name`` channel."""
    sys_c, _ = linearize(model.f, model.outputs, x_ss, u_ss, d_ss, [output_name], steady_tol=steady_tol)
    return step_moments(sys_c, input_name, output_name)


# --------------------------------------------------------------------------- FOPDT
@dataclass(frozen=True)
class Fopdt:
    """First order plus dead time ``G(s) = gain exp(-delay_h s) / (tau_h s + 1)``."""

    gain: float
    tau_h: float
    delay_h: float
    rms_error: float = float("nan")

    def step(self, t_h, du: float = 1.0) -> np.ndarray:
        """Response to a step of size ``du`` applied at t = 0."""
        t = np.asarray(t_h, dtype=float)
        s = np.clip(t - self.delay_h, 0.0, None)
        return self.gain * du * (1.0 - np.exp(-s / self.tau_h))


def fit_fopdt(t_h, y, du: float = 1.0) -> Fopdt:
    """Fit a FOPDT model to a step response ``y(t)`` (deviation from the initial value).

    Least squares (``scipy.optimize.least_squares``) on gain, time constant and delay, started
    from the two-point estimate (28.3 % and 63.2 % times, see the module docstring).
    ``rms_error`` is the RMS residual in output units.
    """
    t = _as_vec("t_h", t_h)
    yv = _as_vec("y", y, t.size)
    if t.size < 5 or np.any(np.diff(t) <= 0):
        raise MpcInputError("The 't_h' parameter must be increasing with >= 5 points.")
    if not (np.isfinite(du) and du != 0):
        raise MpcInputError(f"The 'du' parameter must be a finite nonzero float. Got {du!r}.")
    yn = yv / du
    k0 = float(np.mean(yn[-max(3, t.size // 50):]))
    if k0 == 0:
        raise MpcInputError("The step response must have a nonzero final value. Got 0.")
    frac = yn / k0

    def first_time(level):
        idx = np.nonzero(frac >= level)[0]
        return float(t[idx[0]]) if idx.size else float(t[-1])

    t28, t63 = first_time(0.283), first_time(0.632)
    tau0 = max(1.5 * (t63 - t28), 1e-6 * (t[-1] - t[0]) + 1e-12)
    th0 = max(t63 - tau0, 0.0)

    def resid(p):
        return Fopdt(p[0], p[1], p[2]).step(t) - yn

    sol = scipy.optimize.least_squares(
        resid, x0=[k0, tau0, th0],
        bounds=([-np.inf, 1e-9, 0.0], [np.inf, np.inf, t[-1]]), x_scale="jac",
        xtol=1e-12, ftol=1e-12, gtol=1e-12,
    )
    kf, tf, thf = sol.x
    rms = float(np.sqrt(np.mean((resid(sol.x) * du) ** 2)))
    return Fopdt(float(kf), float(tf), float(thf), rms)


def fopdt_from_model(sys_c: control.StateSpace, input_name: str, output_name: str,
                     t_final_h: float | None = None, n_points: int = 2001) -> Fopdt:
    """FOPDT fit of the unit-step response of one channel of a linear(ised) model."""
    j, i = _channel(sys_c, input_name, output_name)
    if t_final_h is None:
        lam = np.linalg.eigvals(np.asarray(sys_c.A, dtype=float))
        t_final_h = 6.0 * float(np.max(-1.0 / lam.real))
    t = np.linspace(0.0, t_final_h, n_points)
    return fit_fopdt(t, _step_channel(sys_c, j, i, t))


def feed_step_fopdt(model, x_ss, u_ss, d_ss, output_name: str = "p80_um",
                    steady_tol: float = 1e-4) -> Fopdt:
    """A feed step test on ``model`` (anything with ``f(x, u, d)`` and ``outputs``: a twin's model
    or :class:`mpc.plants.leroux.LeRouxCircuit`) at its steady state ``(x_ss, u_ss, d_ss)``: the
    FOPDT fit of the linearised ``feed_tph -> output_name`` step response."""
    sys_c, _ = linearize(model.f, model.outputs, x_ss, u_ss, d_ss, [output_name], steady_tol=steady_tol)
    return fopdt_from_model(sys_c, "feed_tph", output_name)


# --------------------------------------------------------------------------- targets
def steady_target(sys: control.StateSpace, y_ref: dict[str, float], u_ref=None,
                  u_weight=None) -> tuple[np.ndarray, np.ndarray]:
    """Steady state ``(x_s, u_s)`` of a linear model whose named outputs equal ``y_ref``.

    Among all steady states meeting the targets, picks the one with the least weighted input
    move ``(u_s - u_ref)' W (u_s - u_ref)`` (target calculation of Muske & Rawlings 1993; see
    Rawlings, Mayne & Diehl, section 1.5), in closed form from the steady-state gain ``G``:
    ``u_s = u_ref + W^-1 G' (G W^-1 G')^-1 (y_ref - G u_ref)``. Continuous models use
    ``A x + B u = 0``, discrete ones ``x = A x + B u``; the model must have no integrating
    mode. Deviation coordinates, like the model.
    """
    a, b, c, d = (np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))
    nx, nu = b.shape
    unknown = [n for n in y_ref if n not in sys.output_labels]
    if unknown or not y_ref:
        raise MpcInputError(f"The 'y_ref' parameter must name outputs among "
                            f"{sys.output_labels}. Got {list(y_ref)}.")
    rows = [sys.output_labels.index(n) for n in y_ref]
    yv = np.array([float(y_ref[n]) for n in y_ref])
    u_ref = np.zeros(nu) if u_ref is None else _as_vec("u_ref", u_ref, nu)
    w = np.eye(nu) if u_weight is None else np.atleast_2d(np.asarray(u_weight, dtype=float))
    a_eq = a - np.eye(nx) if _control().isdtime(sys, strict=True) else a
    if np.linalg.matrix_rank(a_eq) < nx:
        raise MpcInputError("The 'sys' parameter of steady_target must have no integrating "
                            "mode (A - I, or A in continuous time, must be invertible).")
    xu = -np.linalg.solve(a_eq, b)  # x_s = xu u_s
    g = (c @ xu + d)[rows]  # steady-state gain of the targeted outputs
    if w.shape != (nu, nu) or np.min(np.linalg.eigvalsh(0.5 * (w + w.T))) <= 0:
        raise MpcInputError(f"The 'u_weight' parameter must be a positive definite "
                            f"{nu}x{nu} matrix. Got {w!r}.")
    winv_gt = np.linalg.solve(w, g.T)
    m = g @ winv_gt
    if np.linalg.matrix_rank(m) < len(rows):
        raise MpcInputError(f"The 'y_ref' targets {y_ref} cannot be met at steady state by "
                            "this model (steady-state gain matrix is rank deficient).")
    u_s = u_ref + winv_gt @ np.linalg.solve(m, yv - g @ u_ref)
    return xu @ u_s, u_s


# --------------------------------------------------------------------------- linear MPC
def _mat(name: str, value, shape: tuple[int, int]) -> np.ndarray:
    arr = np.atleast_2d(np.asarray(value, dtype=float))
    if arr.shape != shape:
        raise MpcInputError(f"The '{name}' parameter must have shape {shape}. Got {arr.shape}.")
    if not np.all(np.isfinite(arr)):
        raise MpcInputError(f"The '{name}' parameter must be finite. Got {arr!r}.")
    return arr


def _bound(name: str, value, size: int, default: float) -> np.ndarray:
    if value is None:
        return np.full(size, default)
    arr = np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy()
    if np.any(np.isnan(arr)):
        raise MpcInputError(f"The '{name}' parameter must not contain NaN. Got {arr!r}.")
    return arr


class LinearMPC:
    """Linear MPC on a discrete state-space model, condensed to a QP in the inputs.

    Minimises, over ``u_0 .. u_{N-1}``,
    ``sum_{k<N} (x_k - x_ref)' Q (x_k - x_ref) + (u_k - u_ref)' R (u_k - u_ref)
    + (x_N - x_ref)' P (x_N - x_ref)`` subject to ``x_{k+1} = A x_k + B u_k`` and, optionally,
    ``u_min <= u_k <= u_max``, ``|u_k - u_{k-1}| <= du_max`` (with ``u_{-1}`` the input applied
    at the previous step) and ``x_min <= x_k <= x_max`` for ``k = 1..N``. All quantities are in
    the model's (deviation) coordinates.

    Parameters
    ----------
    sys_d : control.StateSpace
        Discrete-time model (``A``, ``B`` are used).
    q, r : array_like
        State and input weights (symmetric, ``Q >= 0``, ``R > 0``).
    horizon : int
        Prediction and control horizon ``N``.
    terminal : ``"q"``, ``"dare"`` or array_like
        Terminal weight ``P``: ``Q``, the solution of the discrete algebraic Riccati equation,
        or a given matrix.
    u_min, u_max, du_max, x_min, x_max : array_like, optional
        Bounds (scalars broadcast). ``None`` means unbounded.
    solver : str
        CasADi QP plugin (``"qpoases"`` default; ``"osqp"``, ``"hpipm"``, ... as installed).

    When the QP fails (infeasible, solver error, or a solution violating the constraints
    beyond tolerance) :meth:`make_step` says so (``success=False``, solver status) and applies
    a fallback: the previous plan shifted by one step (``"shifted_plan"``; repeated failures
    keep shifting, the last move repeated), or, without a previous plan, the previous input
    held (``"hold_input"``).
    """

    def __init__(self, sys_d: control.StateSpace, q, r, horizon: int, terminal="q",
                 u_min=None, u_max=None, du_max=None, x_min=None, x_max=None,
                 solver: str = "qpoases"):
        if not isinstance(sys_d, _control().StateSpace) or not _control().isdtime(sys_d, strict=True):
            raise MpcInputError("The 'sys_d' parameter of LinearMPC must be a discrete-time "
                                f"control.StateSpace. Got {sys_d!r}.")
        if not (isinstance(horizon, (int, np.integer)) and horizon >= 1):
            raise MpcInputError(f"The 'horizon' parameter of LinearMPC must be an int >= 1. "
                                f"Got {horizon!r}.")
        a = np.asarray(sys_d.A, dtype=float)
        b = np.asarray(sys_d.B, dtype=float)
        nx, nu = b.shape
        q = _mat("q", q, (nx, nx))
        r = _mat("r", r, (nu, nu))
        if np.min(np.linalg.eigvalsh(0.5 * (r + r.T))) <= 0:
            raise MpcInputError("The 'r' parameter of LinearMPC must be positive definite.")
        if isinstance(terminal, str):
            if terminal == "q":
                p = q
            elif terminal == "dare":
                p = scipy.linalg.solve_discrete_are(a, b, q, r)
            else:
                raise MpcInputError("The 'terminal' parameter of LinearMPC must be 'q', 'dare' "
                                    f"or a matrix. Got {terminal!r}.")
        else:
            p = _mat("terminal", terminal, (nx, nx))
        if not ca.has_conic(solver):
            raise MpcInputError(f"The 'solver' parameter of LinearMPC must be a CasADi QP "
                                f"plugin that is installed. Got {solver!r}.")
        self.a, self.b, self.q, self.r, self.p = a, b, q, r, p
        self.nx, self.nu, self.horizon = nx, nu, int(horizon)
        self.dt = sys_d.dt
        self.u_min = _bound("u_min", u_min, nu, -np.inf)
        self.u_max = _bound("u_max", u_max, nu, np.inf)
        self.du_max = _bound("du_max", du_max, nu, np.inf)
        self.x_min = _bound("x_min", x_min, nx, -np.inf)
        self.x_max = _bound("x_max", x_max, nx, np.inf)
        if np.any(self.u_min > self.u_max) or np.any(self.x_min > self.x_max):
            raise MpcInputError("The lower bounds of LinearMPC must not exceed the upper bounds.")
        if np.any(self.du_max < 0):
            raise MpcInputError(f"The 'du_max' parameter must be >= 0. Got {self.du_max!r}.")
        self._condense()
        self._build_qp(solver)
        self.u_prev = np.zeros(nu)
        self._plan: np.ndarray | None = None

    # Condensed prediction X = Phi x0 + Gamma U, X = [x_1; ...; x_N]
    def _condense(self) -> None:
        a, b, n, nx, nu = self.a, self.b, self.horizon, self.nx, self.nu
        phi = np.zeros((n * nx, nx))
        gam = np.zeros((n * nx, n * nu))
        ak = np.eye(nx)
        powers = []
        for k in range(n):
            powers.append(ak)  # A^k
            ak = a @ ak
            phi[k * nx:(k + 1) * nx] = ak  # A^{k+1}
        for k in range(n):  # block row k: x_{k+1}
            for j in range(k + 1):
                gam[k * nx:(k + 1) * nx, j * nu:(j + 1) * nu] = powers[k - j] @ b
        qbar = scipy.linalg.block_diag(*([self.q] * (n - 1) + [self.p]))
        rbar = scipy.linalg.block_diag(*([self.r] * n))
        self._phi, self._gam, self._qbar, self._rbar = phi, gam, qbar, rbar
        self._h = 2.0 * (gam.T @ qbar @ gam + rbar)
        self._h = 0.5 * (self._h + self._h.T)
        # rate constraint rows: D U - e u_prev, D = I - shift
        dmat = np.eye(n * nu) - np.eye(n * nu, k=-nu)
        rows = [dmat]
        self._has_x = bool(np.any(np.isfinite(self.x_min)) or np.any(np.isfinite(self.x_max)))
        if self._has_x:
            rows.append(gam)
        self._amat = np.vstack(rows)

    def _build_qp(self, solver: str) -> None:
        hs = ca.DM(self._h).sparsity()
        asp = ca.DM(self._amat).sparsity()
        if solver in ("hpipm", "fatrop"):
            raise MpcInputError(f"The 'solver' parameter of LinearMPC must be a QP solver for "
                                f"a condensed (dense) QP; {solver!r} needs the sparse OCP "
                                "structure. Use 'qpoases', 'osqp', 'daqp', 'proxqp', 'qrqp' or "
                                "'highs'.")
        opts: dict = {"error_on_fail": False}
        if solver == "qpoases":
            opts["printLevel"] = "none"
        elif solver == "osqp":
            opts["osqp"] = {"verbose": False, "eps_abs": 1e-9, "eps_rel": 1e-9,
                            "polishing": False, "max_iter": 20000}
        elif solver == "qrqp":
            opts["print_iter"] = False
            opts["print_header"] = False
        self._solver_name = solver
        self._qp = conic("linear_mpc", solver, {"h": hs, "a": asp}, opts)

    def unconstrained_gain(self) -> np.ndarray:
        """``K`` with ``u_0 = -K x_0`` for the unconstrained problem (regulation to 0)."""
        f = 2.0 * self._gam.T @ self._qbar @ self._phi
        full = np.linalg.solve(self._h, f)
        return full[: self.nu]

    def reset(self, u_prev=None) -> None:
        """Forget the previous plan; set the previously applied input."""
        self.u_prev = np.zeros(self.nu) if u_prev is None else _as_vec("u_prev", u_prev, self.nu)
        self._plan = None

    def make_step(self, x, x_ref=None, u_ref=None) -> ControllerStepResult:
        """Solve the QP from state ``x``; apply the first move (or a stated fallback)."""
        n, nx, nu = self.horizon, self.nx, self.nu
        x = _as_vec("x", x, nx)
        x_ref = np.zeros(nx) if x_ref is None else _as_vec("x_ref", x_ref, nx)
        u_ref = np.zeros(nu) if u_ref is None else _as_vec("u_ref", u_ref, nu)
        xr = np.tile(x_ref, n)
        ur = np.tile(u_ref, n)
        free = self._phi @ x - xr
        g = 2.0 * (self._gam.T @ self._qbar @ free - self._rbar @ ur)
        const = float(free @ self._qbar @ free + ur @ self._rbar @ ur + (x - x_ref) @ self.q @ (x - x_ref))
        e = np.zeros(n * nu)
        e[:nu] = self.u_prev
        dmax = np.tile(self.du_max, n)
        lba = [-dmax + e]
        uba = [dmax + e]
        if self._has_x:
            px = self._phi @ x
            lba.append(np.tile(self.x_min, n) - px)
            uba.append(np.tile(self.x_max, n) - px)
        lba, uba = np.concatenate(lba), np.concatenate(uba)
        big = 1e20  # qpOASES wants finite bounds
        lba, uba = np.clip(lba, -big, big), np.clip(uba, -big, big)
        lbx = np.clip(np.tile(self.u_min, n), -big, big)
        ubx = np.clip(np.tile(self.u_max, n), -big, big)
        t0 = time.perf_counter()
        try:
            sol = self._qp(h=self._h, g=g, a=self._amat, lba=lba, uba=uba, lbx=lbx, ubx=ubx)
            stats = self._qp.stats()
            ok = bool(stats.get("success", False))
            status = str(stats.get("return_status", "unknown"))
            uopt = np.array(sol["x"]).reshape(-1)
        except RuntimeError as exc:  # casadi raises when the plugin errors out
            stats, ok, status, uopt = {}, False, f"error: {exc}", None
        solve_time = time.perf_counter() - t0
        iters = int(stats.get("iter_count", stats.get("iter", 0)) or 0)
        if ok and uopt is not None and np.all(np.isfinite(uopt)):
            # check the solution really satisfies the constraints (solver tolerances)
            tol = 1e-6 * (1.0 + np.max(np.abs(uopt)))
            ax = self._amat @ uopt
            ok = bool(np.all(ax >= lba - tol) and np.all(ax <= uba + tol)
                      and np.all(uopt >= lbx - tol) and np.all(uopt <= ubx + tol))
            if not ok:
                status = f"{status} (constraint violation above tolerance)"
        if ok:
            plan = uopt.reshape(n, nu)
            cost = float(0.5 * uopt @ self._h @ uopt + g @ uopt + const)
            states = np.vstack([x, (self._phi @ x + self._gam @ uopt).reshape(n, nx)])
            self._plan = plan
            self.u_prev = plan[0].copy()
            return ControllerStepResult(True, status, cost, iters, solve_time, plan[0], plan,
                                        None, states)
        if self._plan is not None and self._plan.shape[0] > 1:
            plan = np.vstack([self._plan[1:], self._plan[-1:]])
            fallback = "shifted_plan"
        else:
            plan = np.tile(self.u_prev, (n, 1))
            fallback = "hold_input"
        self._plan = plan if fallback == "shifted_plan" else None
        self.u_prev = plan[0].copy()
        return ControllerStepResult(False, status, float("nan"), iters, solve_time, plan[0],
                                    plan, fallback)
