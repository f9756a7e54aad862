"""Discrete-time maps of a continuous CasADi model ``f(x, u, d) -> xdot`` (time in hours).

The NMPC (direct multiple shooting) and the estimator need ``x_next = F(x, u, d)`` over one
sample period with ``u`` and ``d`` held (zero-order hold). Two constructions:

- :func:`rk4_map` - ``n_steps`` classical fourth-order Runge-Kutta steps (Hairer, Norsett &
  Wanner, *Solving ODEs I*, section II.1), symbolic, so it embeds in an NLP and is cheap to
  differentiate; global error O(h^4) (tested by the observed order);
- :func:`rk4_sensitivity_map` - the same RK4 steps with the Jacobians ``dF/dx`` and ``dF/du``,
  propagated through the model's sparse DAE form (its aggregates ``z = g(x)`` kept, not
  substituted: ``df/dx = f_x + f_z g_x`` with sparse factors), as mixed MX/SX code that
  compiles to small C with loops (:mod:`mpc.codegen`);
- :func:`cvodes_map` - SUNDIALS CVODES through ``casadi.integrator`` (variable order BDF,
  error-controlled), the reference for accuracy, slower to embed.

Explicit RK4 is only stable when ``h * lambda`` lies in its stability region
``|1 + z + z^2/2 + z^3/6 + z^4/24| <= 1`` for every eigenvalue ``lambda`` of the Jacobian;
:func:`min_rk4_substeps` finds the fewest sub-steps that achieve that at a linearisation;
:func:`stable_rk4_substeps` does it for a model at an operating point, with the rates scaled
by :data:`RK4_RATE_SAFETY`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from mpc.errors import MpcInputError

#: Rates at the linearisation are scaled by this before the RK4 stability count: room for the
#: faster breakage of a softer ore (estimate) or a lighter load than at the operating point.
RK4_RATE_SAFETY = 1.4


def _check_f(f) -> None:
    if not isinstance(f, ca.Function) or f.n_in() != 3 or f.n_out() != 1:
        raise MpcInputError(
            "The 'f' parameter must be a casadi.Function f(x, u, d) -> xdot with 3 inputs "
            f"and 1 output. Got {f!r}."
        )


def _check_dt(dt_h: float) -> float:
    dt_h = float(dt_h)
    if not (np.isfinite(dt_h) and dt_h > 0):
        raise MpcInputError(f"The 'dt_h' parameter must be a float > 0. Got {dt_h!r}.")
    return dt_h


def rk4_map(f: ca.Function, dt_h: float, n_steps: int = 1, name: str = "rk4_map") -> ca.Function:
    """``F(x, u, d) -> x_next`` by ``n_steps`` RK4 steps of length ``dt_h / n_steps``."""
    _check_f(f)
    dt_h = _check_dt(dt_h)
    if not (isinstance(n_steps, (int, np.integer)) and n_steps >= 1):
        raise MpcInputError(f"The 'n_steps' parameter of rk4_map must be an int >= 1. "
                            f"Got {n_steps!r}.")
    x = ca.MX.sym("x", f.size1_in(0))
    u = ca.MX.sym("u", f.size1_in(1))
    d = ca.MX.sym("d", f.size1_in(2))
    h = dt_h / n_steps
    xk = x
    for _ in range(int(n_steps)):
        k1 = f(xk, u, d)
        k2 = f(xk + 0.5 * h * k1, u, d)
        k3 = f(xk + 0.5 * h * k2, u, d)
        k4 = f(xk + h * k3, u, d)
        xk = xk + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function(name, [x, u, d], [xk], ["x", "u", "d"], ["x_next"])


def rk4_sensitivity_map(model, dt_h: float, n_steps: int = 1, name: str = "rk4_sens",
                        with_d: bool = False) -> ca.Function:
    """``F(x, u, d) -> (x_next, A, B)`` with ``A = dx_next/dx``, ``B = dx_next/du`` (and
    ``D = dx_next/dd`` as a fourth output when ``with_d``) by ``n_steps``
    RK4 steps of ``model.dae`` (forward sensitivities of the RK4 stages: ``dk = f_x S + f_z (g_x S)
    + f_u [0 I]`` at each stage, ``S`` the stage point's sensitivity; Hairer, Norsett & Wanner,
    section II.1, differentiated). Same values as AD of :func:`rk4_map`; the sparse factors make
    each stage product ``(nnz f_x + nnz f_z + nnz g_x) (n_x + n_u)`` multiply-adds."""
    dt_h = _check_dt(dt_h)
    if not (isinstance(n_steps, (int, np.integer)) and n_steps >= 1):
        raise MpcInputError(f"The 'n_steps' parameter of rk4_sensitivity_map must be an int >= 1. "
                            f"Got {n_steps!r}.")
    dae, zs, g = model.dae, model.z, model.z_expr
    nx, nu, nd = model.x.numel(), model.u.numel(), model.d.numel()
    ode = dae["ode"]
    wrt = ca.vertcat(model.u, model.d) if with_d else model.u
    nw = wrt.numel()
    parts = [ca.substitute(e, zs, g) if zs.numel() else e
             for e in (ode, ca.jacobian(ode, model.x), ca.jacobian(ode, zs), ca.jacobian(ode, wrt))]
    point = ca.Function(f"{name}_point", [model.x, model.u, model.d],
                        [*parts, ca.jacobian(g, model.x)], ["x", "u", "d"], ["k", "fx", "fz", "fu", "gx"])
    x, u, d = ca.MX.sym("x", nx), ca.MX.sym("u", nu), ca.MX.sym("d", nd)
    e_u = ca.horzcat(ca.DM(nw, nx), ca.DM.eye(nw))

    def stage(xi, si):
        k, fx, fz, fu, gx = point(xi, u, d)
        dk = ca.mtimes(fx, si) + ca.mtimes(fu, e_u)
        if zs.numel():
            dk = dk + ca.mtimes(fz, ca.mtimes(gx, si))
        return k, dk

    h = dt_h / int(n_steps)
    xk, s = x, ca.MX(ca.horzcat(ca.DM.eye(nx), ca.DM(nx, nw)))
    for _ in range(int(n_steps)):
        k1, s1 = stage(xk, s)
        k2, s2 = stage(xk + 0.5 * h * k1, s + 0.5 * h * s1)
        k3, s3 = stage(xk + 0.5 * h * k2, s + 0.5 * h * s2)
        k4, s4 = stage(xk + h * k3, s + h * s3)
        xk = xk + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        s = s + h / 6.0 * (s1 + 2 * s2 + 2 * s3 + s4)
    outs = [xk, s[:, :nx], s[:, nx:nx + nu]] + ([s[:, nx + nu:]] if with_d else [])
    return ca.Function(name, [x, u, d], outs, ["x", "u", "d"], ["x_next", "A", "B", "D"][:len(outs)])


def cvodes_map(f: ca.Function, dt_h: float, abstol: float = 1e-8, reltol: float = 1e-8,
               name: str = "cvodes_map") -> ca.Function:
    """``F(x, u, d) -> x_next`` by CVODES over ``dt_h`` with the given tolerances."""
    _check_f(f)
    dt_h = _check_dt(dt_h)
    for nm, tol in (("abstol", abstol), ("reltol", reltol)):
        if not (np.isfinite(tol) and tol > 0):
            raise MpcInputError(f"The '{nm}' parameter of cvodes_map must be > 0. Got {tol!r}.")
    nx, nu, nd = f.size1_in(0), f.size1_in(1), f.size1_in(2)
    x = ca.MX.sym("x", nx)
    p = ca.MX.sym("p", nu + nd)
    ode = f(x, p[:nu], p[nu:])
    integ = ca.integrator(f"{name}_integrator", "cvodes", {"x": x, "p": p, "ode": ode},
                          0.0, dt_h, {"abstol": float(abstol), "reltol": float(reltol)})
    xs = ca.MX.sym("x", nx)
    u = ca.MX.sym("u", nu)
    d = ca.MX.sym("d", nd)
    xn = integ(x0=xs, p=ca.vertcat(u, d))["xf"]
    return ca.Function(name, [xs, u, d], [xn], ["x", "u", "d"], ["x_next"])


def rk4_amplification(z) -> np.ndarray:
    """``|R(z)|`` of classical RK4, ``R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24``."""
    z = np.asarray(z, dtype=complex)
    return np.abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24)


def min_rk4_substeps(a, dt_h: float, n_max: int = 10_000) -> int:
    """Fewest RK4 sub-steps over ``dt_h`` for which every eigenvalue of ``a`` is stable.

    ``a`` is a Jacobian ``df/dx`` (e.g. ``sys.A`` of :func:`mpc.linear.linearize`). Raises
    :class:`MpcInputError` if an eigenvalue has a positive real part (no step is stable).
    """
    dt_h = _check_dt(dt_h)
    lam = np.linalg.eigvals(np.asarray(a, dtype=float))
    if np.any(lam.real > 0):
        raise MpcInputError(f"The 'a' parameter must have no eigenvalue with Re > 0. "
                            f"Got {lam[lam.real > 0]}.")
    for n in range(1, n_max + 1):
        if np.all(rk4_amplification(lam * dt_h / n) <= 1.0):
            return n
    raise MpcInputError(f"No stable RK4 sub-step count up to n_max = {n_max}.")


def state_jacobian(f, x, u, d) -> np.ndarray:
    """``df/dx`` of the model ``f(x, u, d)`` at ``(x, u, d)``."""
    _check_f(f)
    xs = ca.SX.sym("x", f.size1_in(0))
    return np.asarray(ca.Function("state_jacobian", [xs], [ca.jacobian(f(xs, u, d), xs)])(
        np.asarray(x, float)), float)


def stable_rk4_substeps(f, x, u, d, dt_h: float, safety: float = RK4_RATE_SAFETY) -> int:
    """:func:`min_rk4_substeps` for the model ``f(x, u, d)`` linearised at ``(x, u, d)`` with
    its rates times ``safety``."""
    return min_rk4_substeps(float(safety) * state_jacobian(f, x, u, d), dt_h)
