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
contact point. The history of a sphere pair lives in its row of the Verlet list
(:class:`dem.state.PairArrays`, carried over when the list is rebuilt), that of a sphere and a
wall in per-sphere tables; each kernel writes only its own rows (see :mod:`dem.state`).
"""

from __future__ import annotations

import math

import numba as nb

from dem.state import N_LOAD, unsigned, write_pair_load

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


@nb.njit(cache=True, inline="always")
def hertz_mindlin(delta, nx, ny, nz, vrx, vry, vrz, r_eff, m_eff, e_star, g_star, mu, eta,
                  x0, x1, x2, dt, law=0.0):
    """Force on j (on the particle for walls) of one Hertz–Mindlin contact.

    ``law = 1`` makes it the linear contact of Yade instead (``CONTACT_LAW_LINEAR_YADE``):
    ``k_n = 2 e_star r_eff``, ``k_s = 2 g_star r_eff`` (see :data:`CONTACT_LAW_LINEAR_YADE`).
    ``(x0, x1, x2)`` is the tangential spring; its update is returned, so that no array view is
    made per contact. Returns (fx, fy, fz, fn, vn, x0, x1, x2).
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
    # rotate the spring into the current tangent plane, keeping its length: the arithmetic of
    # dem.state.rotated_into_plane written out, because called here (inlined, returning a tuple)
    # it made the drum's step slower (numba 0.68; docs/benchmarks.md, the bond blocks)
    old2 = x0 * x0 + x1 * x1 + x2 * x2
    xn = x0 * nx + x1 * ny + x2 * nz
    x0 -= xn * nx
    x1 -= xn * ny
    x2 -= xn * nz
    new2 = x0 * x0 + x1 * x1 + x2 * x2
    if new2 > 0.0:
        sc = math.sqrt(old2 / new2)
        x0 *= sc
        x1 *= sc
        x2 *= sc
    x0 += vtx * dt
    x1 += vty * dt
    x2 += vtz * dt
    if law == 1.0:
        s_t = 2.0 * g_star * r_eff
    else:
        s_t = 8.0 * g_star * sq
    ct = eta * math.sqrt(m_eff * s_t)
    ftx = -s_t * x0 - ct * vtx
    fty = -s_t * x1 - ct * vty
    ftz = -s_t * x2 - ct * vtz
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
            x0 = -ftx / s_t
            x1 = -fty / s_t
            x2 = -ftz / s_t
    return fn * nx + ftx, fn * ny + fty, fn * nz + ftz, fn, vn, x0, x1, x2


@nb.njit(cache=True, inline="always")
def pair_contact(k, pi, pj, xi, touch, load, impact, pos, vel, om, rad, mass, lz, e_star, g_star,
                 mu, eta, dt, overlap0, law=0.0):
    """Hertz–Mindlin contact of pair k (spheres i < j of the Verlet list): updates its history
    (``xi``, ``touch``) and writes its loads into row k of ``load`` (zeros when apart) and, if
    the contact began this step, its impact energy into ``impact[k]`` (else -1).

    ``overlap0`` is subtracted from the geometric overlap (the overlap at bonding of a pair
    whose bond has broken, else 0).
    """
    k = unsigned(k)
    i = unsigned(pi[k])
    j = unsigned(pj[k])
    impact[k] = -1.0
    dx = pos[j, 0] - pos[i, 0]
    dy = pos[j, 1] - pos[i, 1]
    dz = pos[j, 2] - pos[i, 2]
    if lz > 0.0:
        dz -= lz * math.floor(dz / lz + 0.5)
    rs = rad[i] + rad[j] - overlap0
    d2 = dx * dx + dy * dy + dz * dz
    if d2 >= rs * rs:
        touch[k] = 0
        for c in range(N_LOAD):
            load[k, c] = 0.0
        return
    d = math.sqrt(d2)
    delta = rs - d
    inv_d = 1.0 / d
    nx = dx * inv_d
    ny = dy * inv_d
    nz = dz * inv_d
    new = touch[k] == 0
    if new:
        touch[k] = 1
        xi[k, 0] = 0.0
        xi[k, 1] = 0.0
        xi[k, 2] = 0.0
    # contact point arms: of i +ai n, of j -aj n; contact-point velocities v + w x r
    ai = rad[i] - 0.5 * (delta + overlap0)
    aj = rad[j] - 0.5 * (delta + overlap0)
    vrx = vel[j, 0] - vel[i, 0] - aj * (om[j, 1] * nz - om[j, 2] * ny) - ai * (om[i, 1] * nz - om[i, 2] * ny)
    vry = vel[j, 1] - vel[i, 1] - aj * (om[j, 2] * nx - om[j, 0] * nz) - ai * (om[i, 2] * nx - om[i, 0] * nz)
    vrz = vel[j, 2] - vel[i, 2] - aj * (om[j, 0] * ny - om[j, 1] * nx) - ai * (om[i, 0] * ny - om[i, 1] * nx)
    r_eff = rad[i] * rad[j] / (rad[i] + rad[j])
    m_eff = mass[i] * mass[j] / (mass[i] + mass[j])
    fx, fy, fz, fn, vn, xi[k, 0], xi[k, 1], xi[k, 2] = hertz_mindlin(
        delta, nx, ny, nz, vrx, vry, vrz, r_eff, m_eff, e_star, g_star, mu, eta, xi[k, 0],
        xi[k, 1], xi[k, 2], dt, law)
    if new:
        impact[k] = 0.5 * m_eff * vn * vn
    write_pair_load(load, k, fx, fy, fz, nx, ny, nz, ai, aj)


@nb.njit(cache=True, inline="always")
def wall_contact(i, k, delta, nx, ny, nz, cx, cy, cz, wvx, wvy, wvz, pos, vel, om, rad, m_eff,
                 force, torque, xi, touch, impact, e_star, g_star, mu, eta, dt, law=0.0):
    """Hertz–Mindlin contact of sphere i with wall element k at contact point c.

    ``m_eff`` is the pair's reduced mass in the damping (Tsuji et al. 1992): the sphere's own for a
    fixed or driven wall (infinite mass, as LIGGGHTS and LAMMPS take every wall), ``m M/(m + M)``
    for a free wall of mass M (a drop weight), as for two spheres (:func:`pair_contact`).

    ``n`` points from the wall into the particle; ``(wvx, wvy, wvz)`` is the wall velocity at c;
    ``xi[i, k]``/``touch[i, k]`` are the tangential history and contact flag, ``impact[i, k]``
    receives the impact energy of a contact that begins now. Adds the force and torque to
    sphere i and returns the force on the particle (the wall receives its opposite).
    """
    new = touch[i, k] == 0
    if new:
        xi[i, k, 0] = 0.0
        xi[i, k, 1] = 0.0
        xi[i, k, 2] = 0.0
        touch[i, k] = 1
    rx = cx - pos[i, 0]
    ry = cy - pos[i, 1]
    rz = cz - pos[i, 2]
    vx = vel[i, 0] + om[i, 1] * rz - om[i, 2] * ry - wvx
    vy = vel[i, 1] + om[i, 2] * rx - om[i, 0] * rz - wvy
    vz = vel[i, 2] + om[i, 0] * ry - om[i, 1] * rx - wvz
    # the particle plays the role of j (n from wall to particle, v_rel = particle - wall)
    fx, fy, fz, fn, vn, xi[i, k, 0], xi[i, k, 1], xi[i, k, 2] = hertz_mindlin(
        delta, nx, ny, nz, vx, vy, vz, rad[i], m_eff, e_star, g_star, mu, eta, xi[i, k, 0],
        xi[i, k, 1], xi[i, k, 2], dt, law)
    if new:
        impact[i, k] = 0.5 * m_eff * vn * vn
    f = force
    t = torque
    f[i, 0] += fx
    f[i, 1] += fy
    f[i, 2] += fz
    t[i, 0] += ry * fz - rz * fy
    t[i, 1] += rz * fx - rx * fz
    t[i, 2] += rx * fy - ry * fx
    return fx, fy, fz


@nb.njit(cache=True, inline="always")
def plane_walls(i, pos, vel, om, rad, mass, force, torque, w_p, w_n, w_v, w_mass, w_xi, w_touch,
                w_force, w_impact, e_star, g_star, mu, eta, dt, law=0.0):
    """Contacts of sphere i with the infinite planes (point ``w_p``, unit normal ``w_n`` into
    the domain, velocity ``w_v``, mass ``w_mass``: > 0 for a free wall, else fixed or driven);
    the sphere's force on each wall goes into ``w_force[i]``."""
    for k in range(w_p.shape[0]):
        w_impact[i, k] = -1.0
        h = ((pos[i, 0] - w_p[k, 0]) * w_n[k, 0] + (pos[i, 1] - w_p[k, 1]) * w_n[k, 1]
             + (pos[i, 2] - w_p[k, 2]) * w_n[k, 2])
        delta = rad[i] - h
        if delta <= 0.0:
            w_touch[i, k] = 0
            continue
        cx = pos[i, 0] - h * w_n[k, 0]
        cy = pos[i, 1] - h * w_n[k, 1]
        cz = pos[i, 2] - h * w_n[k, 2]
        m_eff = mass[i]
        if w_mass[k] > 0.0:
            m_eff = mass[i] * w_mass[k] / (mass[i] + w_mass[k])
        fx, fy, fz = wall_contact(i, k, delta, w_n[k, 0], w_n[k, 1], w_n[k, 2], cx, cy, cz,
                                  w_v[k, 0], w_v[k, 1], w_v[k, 2], pos, vel, om, rad, m_eff,
                                  force, torque, w_xi, w_touch, w_impact, e_star, g_star, mu,
                                  eta, dt, law)
        w_force[i, k, 0] = -fx
        w_force[i, k, 1] = -fy
        w_force[i, k, 2] = -fz


@nb.njit(cache=True, inline="always")
def drum_walls(i, pos, vel, om, rad, mass, force, torque, lifter_angles, d_xi, d_touch, d_impact,
               drum_radius, drum_omega, drum_angle, lifter_height, lifter_half_width, e_star,
               g_star, mu, eta, dt, law=0.0):
    """Contacts of sphere i with a drum shell (axis z through the origin, rotating at
    ``drum_omega`` rad/s) and its lifters.

    Element 0 is the cylindrical shell (spheres inside); elements 1..K are lifters: radial bars
    from the shell inwards of height ``lifter_height``, rounded with half width
    ``lifter_half_width`` (a capsule section, infinite along z). The torque (N m, about +z) that
    the sphere exerts on the drum is returned.
    """
    tq = 0.0
    nl = lifter_angles.shape[0]
    x = pos[i, 0]
    y = pos[i, 1]
    rho = math.sqrt(x * x + y * y)
    delta = rad[i] + rho - drum_radius
    for k in range(nl + 1):
        d_impact[i, k] = -1.0
    if delta > 0.0 and rho > 0.0:
        nx = -x / rho
        ny = -y / rho
        cx = -nx * drum_radius
        cy = -ny * drum_radius
        fx, fy, fz = wall_contact(i, 0, delta, nx, ny, 0.0, cx, cy, pos[i, 2], -drum_omega * cy,
                                  drum_omega * cx, 0.0, pos, vel, om, rad, mass[i], force, torque, d_xi, d_touch,
                                  d_impact, e_star, g_star, mu, eta, dt, law)
        tq -= cx * fy - cy * fx
    else:
        d_touch[i, 0] = 0
    if rho < drum_radius - lifter_height - lifter_half_width - rad[i]:
        for k in range(nl):
            d_touch[i, k + 1] = 0
        return tq
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
            d_touch[i, k + 1] = 0
            continue
        nx = dx / dist
        ny = dy / dist
        cx = qx + nx * lifter_half_width
        cy = qy + ny * lifter_half_width
        fx, fy, fz = wall_contact(i, k + 1, delta, nx, ny, 0.0, cx, cy, pos[i, 2],
                                  -drum_omega * cy, drum_omega * cx, 0.0, pos, vel, om, rad, mass[i], force, torque,
                                  d_xi, d_touch, d_impact, e_star, g_star, mu, eta, dt, law)
        tq -= cx * fy - cy * fx
    return tq
