"""Hertz–Mindlin contact forces as numba kernels on plain arrays (SI units).

Model (sources in :mod:`dem.materials`):

- normal: ``f_n = 4/3 E* sqrt(R*) d^1.5 - eta sqrt(m* S_n) v_n``, ``S_n = 2 E* sqrt(R* d)``,
  clamped at ``f_n >= 0`` (no attraction); Hertz (Johnson 1985) + Tsuji et al. (1992) damping;
- tangential: incremental Mindlin no-slip spring ``f_t = -S_t xi - eta sqrt(m* S_t) v_t``,
  ``S_t = 8 G* sqrt(R* d)``, where ``xi`` is the accumulated tangential displacement, rotated
  into the current tangent plane every step; Coulomb limit ``|f_t| <= mu f_n``, on sliding
  ``xi`` is reset to ``-f_t/S_t`` (Mindlin & Deresiewicz 1953; the LIGGGHTS/EDEM form);
- a new contact (first step of overlap) records its normal impact energy ``m* v_n^2 / 2`` in a
  logarithmic histogram (collision-energy spectra of the drum mill).

Conventions: ``n`` points from particle i to particle j (or from a wall into the domain),
``v_rel`` is the velocity of j (or of the particle) relative to i (or the wall) at the
contact point. Contact history lives in per-particle slot tables ``c_partner[N, MAXC]`` and
``c_xi[N, MAXC, 3]`` keyed by the smaller index of the pair.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

#: contact-table overflow flag returned by kernels
STATUS_CONTACT_TABLE_FULL = 1

#: contact laws (``law`` argument of the kernels): Hertz–Mindlin (default) and the linear
#: spring of Yade (``Ip2_FrictMat_FrictMat_FrictPhys`` + ``Law2_ScGeom_FrictPhys_CundallStrack``,
#: also the non-cohesive branch of ``Law2_ScGeom_JCFpmPhys_JointedCohesiveFrictionalPM``):
#: ``k_n = 2 E1 R1 E2 R2/(E1 R1 + E2 R2)``, ``k_s = 2 E1 nu1 R1 E2 nu2 R2/(E1 nu1 R1 + E2 nu2 R2)``
#: (Yade's ``poisson`` is the ratio k_s/k_n, not Poisson's ratio), Coulomb ``|f_s| <= mu f_n``.
#: In the kernels ``k_n = 2 e_star r_eff``, ``k_s = 2 g_star r_eff``; :class:`dem.system.System`
#: sets e_star, g_star so that these are Yade's values (sphere-sphere of one material:
#: ``e_star = E``, ``g_star = nu E``; sphere-wall, Yade gives both radii the sphere's:
#: ``e_star = E_s E_w/(E_s + E_w)``, ``g_star = (nu E)_s (nu E)_w / ((nu E)_s + (nu E)_w)``).
CONTACT_LAW_HERTZ_MINDLIN = 0
CONTACT_LAW_LINEAR_YADE = 1


@nb.njit(cache=True, inline="always")
def slot_find(c_partner, i, j):
    for s in range(c_partner.shape[1]):
        if c_partner[i, s] == j:
            return s
    return -1


@nb.njit(cache=True, inline="always")
def slot_insert(c_partner, c_xi, i, j):
    for s in range(c_partner.shape[1]):
        if c_partner[i, s] < 0:
            c_partner[i, s] = j
            c_xi[i, s, 0] = 0.0
            c_xi[i, s, 1] = 0.0
            c_xi[i, s, 2] = 0.0
            return s
    return -1


@nb.njit(cache=True, inline="always")
def add_pair_load(force, torque, i, j, fx, fy, fz, nx, ny, nz, ai, aj):
    """Force f on sphere j and -f on sphere i at their contact point (unit normal n from i to j,
    lever arms ai, aj from the centres), with the torques: arm_j = -aj n, arm_i = +ai n."""
    force[j, 0] += fx
    force[j, 1] += fy
    force[j, 2] += fz
    force[i, 0] -= fx
    force[i, 1] -= fy
    force[i, 2] -= fz
    tx = ny * fz - nz * fy
    ty = nz * fx - nx * fz
    tz = nx * fy - ny * fx
    torque[j, 0] -= aj * tx
    torque[j, 1] -= aj * ty
    torque[j, 2] -= aj * tz
    torque[i, 0] -= ai * tx
    torque[i, 1] -= ai * ty
    torque[i, 2] -= ai * tz


@nb.njit(cache=True, inline="always")
def rotate_into_plane(vec, b, nx, ny, nz):
    """Rotate the stored vector vec[b] into the plane normal to n, keeping its magnitude (the
    incremental update of a bond's shear force or bending moment as the bond turns;
    Potyondy & Cundall 2004, sec. 2.2)."""
    old = math.sqrt(vec[b, 0] ** 2 + vec[b, 1] ** 2 + vec[b, 2] ** 2)
    along = vec[b, 0] * nx + vec[b, 1] * ny + vec[b, 2] * nz
    vec[b, 0] -= along * nx
    vec[b, 1] -= along * ny
    vec[b, 2] -= along * nz
    new = math.sqrt(vec[b, 0] ** 2 + vec[b, 1] ** 2 + vec[b, 2] ** 2)
    if new > 0.0:
        sc = old / new
        vec[b, 0] *= sc
        vec[b, 1] *= sc
        vec[b, 2] *= sc


@nb.njit(cache=True, inline="always")
def hist_add(hist, lo_log10, dlog10, energy_J):
    if energy_J <= 0.0:
        k = 0
    else:
        k = int(math.floor((math.log10(energy_J) - lo_log10) / dlog10))
    if k < 0:
        k = 0
    if k >= hist.shape[0]:
        k = hist.shape[0] - 1
    hist[k] += 1.0


@nb.njit(cache=True)
def hertz_mindlin(delta, nx, ny, nz, vrx, vry, vrz, r_eff, m_eff, e_star, g_star, mu, eta,
                  xi, dt, law=0.0):
    """Force on j (on the particle for walls) of one Hertz–Mindlin contact.

    ``law = 1`` makes it the linear contact of Yade instead (``CONTACT_LAW_LINEAR_YADE``):
    ``k_n = 2 e_star r_eff``, ``k_s = 2 g_star r_eff`` (see :data:`CONTACT_LAW_LINEAR_YADE`).
    ``xi`` (length-3 view) is updated in place. Returns (fx, fy, fz, fn, vn).
    """
    vn = vrx * nx + vry * ny + vrz * nz
    if law == 1.0:
        sq = 1.0
        s_n = 2.0 * e_star * r_eff
        fn = s_n * delta - eta * math.sqrt(m_eff * s_n) * vn
    else:
        sq = math.sqrt(r_eff * delta)
        s_n = 2.0 * e_star * sq
        fn = (4.0 / 3.0) * e_star * sq * delta - eta * math.sqrt(m_eff * s_n) * vn
    if fn < 0.0:
        fn = 0.0
    # tangential relative velocity
    vtx = vrx - vn * nx
    vty = vry - vn * ny
    vtz = vrz - vn * nz
    # rotate the spring into the current tangent plane, keeping its length
    old = math.sqrt(xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2])
    xn = xi[0] * nx + xi[1] * ny + xi[2] * nz
    xi[0] -= xn * nx
    xi[1] -= xn * ny
    xi[2] -= xn * nz
    new = math.sqrt(xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2])
    if new > 0.0:
        sc = old / new
        xi[0] *= sc
        xi[1] *= sc
        xi[2] *= sc
    xi[0] += vtx * dt
    xi[1] += vty * dt
    xi[2] += vtz * dt
    if law == 1.0:
        s_t = 2.0 * g_star * r_eff
    else:
        s_t = 8.0 * g_star * sq
    ct = eta * math.sqrt(m_eff * s_t)
    ftx = -s_t * xi[0] - ct * vtx
    fty = -s_t * xi[1] - ct * vty
    ftz = -s_t * xi[2] - ct * vtz
    ft = math.sqrt(ftx * ftx + fty * fty + ftz * ftz)
    lim = mu * fn
    if ft > lim:
        if ft > 0.0:
            sc = lim / ft
        else:
            sc = 0.0
        ftx *= sc
        fty *= sc
        ftz *= sc
        if s_t > 0.0:
            xi[0] = -ftx / s_t
            xi[1] = -fty / s_t
            xi[2] = -ftz / s_t
    return fn * nx + ftx, fn * ny + fty, fn * nz + ftz, fn, vn


@nb.njit(cache=True)
def pair_contact(i, j, pos, vel, omega, rad, mass, force, torque, lz, e_star, g_star, mu, eta,
                 dt, c_partner, c_xi, hist, lo_log10, dlog10, overlap0, law=0.0):
    """Hertz–Mindlin contact between spheres i < j; updates forces, torques and history.

    ``overlap0`` is subtracted from the geometric overlap (the overlap at bonding of a pair
    whose bond has broken, else 0).

    Returns 0, or STATUS_CONTACT_TABLE_FULL if a new contact found no free slot.
    """
    dx = pos[j, 0] - pos[i, 0]
    dy = pos[j, 1] - pos[i, 1]
    dz = pos[j, 2] - pos[i, 2]
    if lz > 0.0:
        dz -= lz * math.floor(dz / lz + 0.5)
    rs = rad[i] + rad[j] - overlap0
    d2 = dx * dx + dy * dy + dz * dz
    s = slot_find(c_partner, i, j)
    if d2 >= rs * rs:
        if s >= 0:
            c_partner[i, s] = -1
        return 0
    d = math.sqrt(d2)
    delta = rs - d
    nx = dx / d
    ny = dy / d
    nz = dz / d
    new = False
    if s < 0:
        s = slot_insert(c_partner, c_xi, i, j)
        new = True
        if s < 0:
            return STATUS_CONTACT_TABLE_FULL
    # contact point arms
    ai = rad[i] - 0.5 * (delta + overlap0)
    aj = rad[j] - 0.5 * (delta + overlap0)
    # velocities of the contact point on each body: v + w x r
    # arm of i: +ai n ; arm of j: -aj n
    wix = omega[i, 0]
    wiy = omega[i, 1]
    wiz = omega[i, 2]
    wjx = omega[j, 0]
    wjy = omega[j, 1]
    wjz = omega[j, 2]
    vix = vel[i, 0] + ai * (wiy * nz - wiz * ny)
    viy = vel[i, 1] + ai * (wiz * nx - wix * nz)
    viz = vel[i, 2] + ai * (wix * ny - wiy * nx)
    vjx = vel[j, 0] - aj * (wjy * nz - wjz * ny)
    vjy = vel[j, 1] - aj * (wjz * nx - wjx * nz)
    vjz = vel[j, 2] - aj * (wjx * ny - wjy * nx)
    r_eff = rad[i] * rad[j] / (rad[i] + rad[j])
    m_eff = mass[i] * mass[j] / (mass[i] + mass[j])
    fx, fy, fz, fn, vn = hertz_mindlin(delta, nx, ny, nz, vjx - vix, vjy - viy, vjz - viz,
                                       r_eff, m_eff, e_star, g_star, mu, eta, c_xi[i, s], dt,
                                       law)
    if new:
        hist_add(hist, lo_log10, dlog10, 0.5 * m_eff * vn * vn)
    add_pair_load(force, torque, i, j, fx, fy, fz, nx, ny, nz, ai, aj)
    return 0


@nb.njit(cache=True)
def wall_contact(i, delta, nx, ny, nz, cx, cy, cz, wvx, wvy, wvz, pos, vel, omega, rad, mass,
                 force, torque, e_star, g_star, mu, eta, dt, xi, active, k, hist, lo_log10,
                 dlog10, law=0.0):
    """Hertz–Mindlin contact of sphere i with a wall element at contact point c.

    ``n`` points from the wall into the particle; ``(wvx, wvy, wvz)`` is the wall velocity at c;
    ``xi``/``active[i, k]`` are the tangential history and contact flag of this wall element.
    Returns the force on the particle (the wall receives its opposite).
    """
    if active[i, k] == 0:
        xi[0] = 0.0
        xi[1] = 0.0
        xi[2] = 0.0
    rx = cx - pos[i, 0]
    ry = cy - pos[i, 1]
    rz = cz - pos[i, 2]
    vx = vel[i, 0] + omega[i, 1] * rz - omega[i, 2] * ry - wvx
    vy = vel[i, 1] + omega[i, 2] * rx - omega[i, 0] * rz - wvy
    vz = vel[i, 2] + omega[i, 0] * ry - omega[i, 1] * rx - wvz
    # the particle plays the role of j (n from wall to particle, v_rel = particle - wall)
    fx, fy, fz, fn, vn = hertz_mindlin(delta, nx, ny, nz, vx, vy, vz, rad[i], mass[i], e_star,
                                       g_star, mu, eta, xi, dt, law)
    if active[i, k] == 0:
        hist_add(hist, lo_log10, dlog10, 0.5 * mass[i] * vn * vn)
        active[i, k] = 1
    force[i, 0] += fx
    force[i, 1] += fy
    force[i, 2] += fz
    torque[i, 0] += ry * fz - rz * fy
    torque[i, 1] += rz * fx - rx * fz
    torque[i, 2] += rx * fy - ry * fx
    return fx, fy, fz


@nb.njit(cache=True)
def plane_walls(pos, vel, omega, rad, mass, force, torque, w_p, w_n, w_v, w_f, w_xi, w_in,
                e_star, g_star, mu, eta, dt, hist, lo_log10, dlog10, law=0.0):
    """Contacts of all spheres with infinite planes (point ``w_p``, unit normal ``w_n`` into the domain)."""
    nw = w_p.shape[0]
    for k in range(nw):
        w_f[k, 0] = 0.0
        w_f[k, 1] = 0.0
        w_f[k, 2] = 0.0
    for i in range(pos.shape[0]):
        for k in range(nw):
            h = ((pos[i, 0] - w_p[k, 0]) * w_n[k, 0] + (pos[i, 1] - w_p[k, 1]) * w_n[k, 1]
                 + (pos[i, 2] - w_p[k, 2]) * w_n[k, 2])
            delta = rad[i] - h
            if delta <= 0.0:
                w_in[i, k] = 0
                continue
            cx = pos[i, 0] - h * w_n[k, 0]
            cy = pos[i, 1] - h * w_n[k, 1]
            cz = pos[i, 2] - h * w_n[k, 2]
            fx, fy, fz = wall_contact(i, delta, w_n[k, 0], w_n[k, 1], w_n[k, 2], cx, cy, cz,
                                      w_v[k, 0], w_v[k, 1], w_v[k, 2], pos, vel, omega, rad,
                                      mass, force, torque, e_star, g_star, mu, eta, dt,
                                      w_xi[i, k], w_in, k, hist, lo_log10, dlog10, law)
            w_f[k, 0] -= fx
            w_f[k, 1] -= fy
            w_f[k, 2] -= fz


@nb.njit(cache=True)
def drum_walls(pos, vel, omega, rad, mass, force, torque, drum_radius, drum_omega, drum_angle,
               lifter_angles, lifter_height, lifter_half_width, d_xi, d_in, e_star, g_star, mu,
               eta, dt, hist, lo_log10, dlog10, law=0.0):
    """Contacts with a drum shell (axis z through the origin, rotating at ``drum_omega`` rad/s).

    Element 0 is the cylindrical shell (spheres inside); elements 1..K are lifters: radial bars
    from the shell inwards of height ``lifter_height``, rounded with half width
    ``lifter_half_width`` (a capsule section, infinite along z). Returns the torque (N m, about
    +z) that the spheres exert on the drum.
    """
    tq = 0.0
    nl = lifter_angles.shape[0]
    for i in range(pos.shape[0]):
        x = pos[i, 0]
        y = pos[i, 1]
        rho = math.sqrt(x * x + y * y)
        delta = rad[i] + rho - drum_radius
        if delta > 0.0 and rho > 0.0:
            nx = -x / rho
            ny = -y / rho
            cx = -nx * drum_radius
            cy = -ny * drum_radius
            fx, fy, fz = wall_contact(i, delta, nx, ny, 0.0, cx, cy, pos[i, 2],
                                      -drum_omega * cy, drum_omega * cx, 0.0, pos, vel, omega,
                                      rad, mass, force, torque, e_star, g_star, mu, eta, dt,
                                      d_xi[i, 0], d_in, 0, hist, lo_log10, dlog10, law)
            tq -= cx * fy - cy * fx
        else:
            d_in[i, 0] = 0
        if rho < drum_radius - lifter_height - lifter_half_width - rad[i]:
            for k in range(nl):
                d_in[i, k + 1] = 0
            continue
        for k in range(nl):
            a = lifter_angles[k] + drum_angle
            ux = math.cos(a)
            uy = math.sin(a)
            s = drum_radius - (x * ux + y * uy)
            if s < 0.0:
                s = 0.0
            if s > lifter_height:
                s = lifter_height
            qx = (drum_radius - s) * ux
            qy = (drum_radius - s) * uy
            dx = x - qx
            dy = y - qy
            dist = math.sqrt(dx * dx + dy * dy)
            delta = rad[i] + lifter_half_width - dist
            if delta <= 0.0 or dist <= 0.0:
                d_in[i, k + 1] = 0
                continue
            nx = dx / dist
            ny = dy / dist
            cx = qx + nx * lifter_half_width
            cy = qy + ny * lifter_half_width
            fx, fy, fz = wall_contact(i, delta, nx, ny, 0.0, cx, cy, pos[i, 2],
                                      -drum_omega * cy, drum_omega * cx, 0.0, pos, vel, omega,
                                      rad, mass, force, torque, e_star, g_star, mu, eta, dt,
                                      d_xi[i, k + 1], d_in, k + 1, hist, lo_log10, dlog10,
                                      law)
            tq -= cx * fy - cy * fx
    return tq


def new_contact_tables(n: int, max_contacts: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Empty contact-history tables (partner ids, tangential springs)."""
    return (np.full((n, max_contacts), -1, dtype=np.int64),
            np.zeros((n, max_contacts, 3), dtype=np.float64))
