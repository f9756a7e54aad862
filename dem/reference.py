"""Plain-Python reference of the force routines, for tests (slow, all pairs, no numba).

Implements the same model as :mod:`dem.contacts` and :mod:`dem.bonds` (see their docstrings
for the physics and sources) written independently with numpy vectors: Hertz–Mindlin pair and
plane-wall contacts with incremental tangential springs, and parallel bonds with incremental
force/moment updates and the tension/shear failure test. Histories are dicts keyed by pair.
"""

from __future__ import annotations

import math

import numpy as np


def _hm(delta, n, v_rel, r_eff, m_eff, e_star, g_star, mu, eta, xi, dt):
    vn = float(v_rel @ n)
    sq = math.sqrt(r_eff * delta)
    s_n = 2 * e_star * sq
    fn = max(0.0, 4 / 3 * e_star * sq * delta - eta * math.sqrt(m_eff * s_n) * vn)
    vt = v_rel - vn * n
    old = np.linalg.norm(xi)
    xi = xi - (xi @ n) * n
    new = np.linalg.norm(xi)
    if new > 0:
        xi = xi * (old / new)
    xi = xi + vt * dt
    s_t = 8 * g_star * sq
    ft = -s_t * xi - eta * math.sqrt(m_eff * s_t) * vt
    if np.linalg.norm(ft) > mu * fn:
        nft = np.linalg.norm(ft)
        ft = ft * (mu * fn / nft) if nft > 0 else ft * 0
        xi = -ft / s_t
    return fn * n + ft, xi


def reference_forces(pos, vel, omega, rad, mass, *, e_star, g_star, mu, eta, dt, history,
                     walls=(), wall_history=None, e_star_w=0.0, g_star_w=0.0, mu_w=0.0, eta_w=0.0,
                     bonded=frozenset()):
    """Forces and torques of all sphere–sphere and sphere–plane contacts.

    ``history`` maps (i, j) -> tangential spring (3,) and is updated (returns a new dict);
    ``walls`` is a list of (point, normal, velocity); ``bonded`` the set of (i, j) pairs whose
    contact is suppressed by an intact bond.
    """
    n = len(rad)
    force = np.zeros((n, 3))
    torque = np.zeros((n, 3))
    new_hist = {}
    for i in range(n):
        for j in range(i + 1, n):
            if (i, j) in bonded:
                continue
            d = pos[j] - pos[i]
            dist = np.linalg.norm(d)
            delta = rad[i] + rad[j] - dist
            if delta <= 0:
                continue
            nv = d / dist
            ai = rad[i] - delta / 2
            aj = rad[j] - delta / 2
            vi = vel[i] + np.cross(omega[i], ai * nv)
            vj = vel[j] + np.cross(omega[j], -aj * nv)
            r_eff = rad[i] * rad[j] / (rad[i] + rad[j])
            m_eff = mass[i] * mass[j] / (mass[i] + mass[j])
            f, xi = _hm(delta, nv, vj - vi, r_eff, m_eff, e_star, g_star, mu, eta,
                        np.array(history.get((i, j), np.zeros(3)), dtype=float), dt)
            new_hist[(i, j)] = xi
            force[j] += f
            force[i] -= f
            torque[j] += np.cross(-aj * nv, f)
            torque[i] += np.cross(ai * nv, -f)
    new_wh = {}
    for k, (p, nrm, vw) in enumerate(walls):
        nrm = np.asarray(nrm, float) / np.linalg.norm(nrm)
        for i in range(n):
            h = float((pos[i] - np.asarray(p)) @ nrm)
            delta = rad[i] - h
            if delta <= 0:
                continue
            c = pos[i] - h * nrm
            r = c - pos[i]
            v_rel = vel[i] + np.cross(omega[i], r) - np.asarray(vw, float)
            xi0 = (wall_history or {}).get((i, k), np.zeros(3))
            f, xi = _hm(delta, nrm, v_rel, rad[i], mass[i], e_star_w, g_star_w, mu_w, eta_w,
                        np.array(xi0, dtype=float), dt)
            new_wh[(i, k)] = xi
            force[i] += f
            torque[i] += np.cross(r, f)
    return force, torque, new_hist, new_wh


def reference_bond(pos_i, pos_j, vel_i, vel_j, om_i, om_j, r_i, r_j, state, *, area, rbar, kn, ks,
                   tensile, cohesion, tan_phi, beta, dt):
    """One incremental update of a parallel bond.

    ``state`` = dict(fn, fs (3,), mb (3,), mt, length, broken); returns (new state,
    force on j, torque on i, torque on j, mode) with mode 0 intact, 1 tension, 2 shear.
    """
    d = pos_j - pos_i
    dist = np.linalg.norm(d)
    nv = d / dist
    inertia = math.pi * rbar**4 / 4
    polar = 2 * inertia
    gap = dist - r_i - r_j
    ai = r_i + gap / 2
    aj = r_j + gap / 2
    vr = (vel_j + np.cross(om_j, -aj * nv)) - (vel_i + np.cross(om_i, ai * nv))
    vn = vr @ nv
    fn = state["fn"] + kn * area * (dist - state["length"])
    fs = np.array(state["fs"], float)
    old = np.linalg.norm(fs)
    fs = fs - (fs @ nv) * nv
    if np.linalg.norm(fs) > 0:
        fs *= old / np.linalg.norm(fs)
    fs = fs - ks * area * (vr - vn * nv) * dt
    mb = np.array(state["mb"], float)
    mt = state["mt"]
    if beta > 0:
        dth = (om_j - om_i) * dt
        dtt = dth @ nv
        mt = mt - ks * polar * dtt
        old = np.linalg.norm(mb)
        mb = mb - (mb @ nv) * nv
        if np.linalg.norm(mb) > 0:
            mb *= old / np.linalg.norm(mb)
        mb = mb - kn * inertia * (dth - dtt * nv)
    sigma = fn / area + beta * np.linalg.norm(mb) * rbar / inertia
    tau = np.linalg.norm(fs) / area + beta * abs(mt) * rbar / polar
    mode = 0
    if sigma > tensile:
        mode = 1
    elif tau > cohesion + max(-fn / area, 0.0) * tan_phi:
        mode = 2
    new = {"fn": fn, "fs": fs, "mb": mb, "mt": mt, "length": dist, "broken": mode != 0}
    if mode:
        z = np.zeros(3)
        return ({"fn": 0.0, "fs": z, "mb": z, "mt": 0.0, "length": dist, "broken": True}, z, z, z, mode)
    f_j = -fn * nv + fs
    m = mb + mt * nv
    t_j = np.cross(-aj * nv, f_j) + m
    t_i = np.cross(ai * nv, -f_j) - m
    return new, f_j, t_i, t_j, mode
