"""Neighbour search, force assembly and velocity-Verlet integration (numba, SI units).

- Neighbour search: sort-based linked cells (cell edge = largest diameter + skin) building a
  Verlet list of pairs within ``R_i + R_j + skin``; rebuilt when any sphere has moved more than
  half the skin since the last build (Allen & Tildesley, *Computer Simulation of Liquids*,
  §5.3). Optional periodicity along z (drum slice).
- Integration: velocity Verlet (kick–drift–kick), the standard explicit DEM scheme
  (Allen & Tildesley §3.2); forces use the mid-step velocities for damping and incremental
  springs.
- Optional Cundall local (non-viscous) damping ``F <- F - alpha |F| sign(v)`` per component
  (Potyondy & Cundall 2004 §2.3; Yade ``NewtonIntegrator.damping``) for quasi-static tests;
  ``v`` is the mid-step velocity, or with ``CP_DAMP_AT_STEP`` (System ``damping_velocity=
  "at_force"``) Yade's ``cundallDamp2nd`` estimate ``v + dt/2 F/m`` at the time of the force.

Developers: the kernels are cached by numba (``cache=True``), and numba checks only this file's
time stamp, not those of the functions it compiles in (``dem.bonds``, ``dem.contacts``). After
editing those, delete ``dem/__pycache__/*.nbi`` and ``*.nbc``, or the old kernels run.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from dem.bonds import BROKEN_SHEAR_SLIDING, P_OVERLAP0, P_SIGNED_MC, bond_forces
from dem.contacts import drum_walls, pair_contact, plane_walls

# indices of the scalar parameter vector ``cp``
(CP_ESTAR_PP, CP_GSTAR_PP, CP_MU_PP, CP_ETA_PP, CP_ESTAR_PW, CP_GSTAR_PW, CP_MU_PW, CP_ETA_PW,
 CP_LOCAL_DAMPING, CP_GX, CP_GY, CP_GZ, CP_LZ, CP_SKIN, CP_BETA, CP_DRUM_R, CP_DRUM_OMEGA,
 CP_LIFTER_H, CP_LIFTER_HW, CP_HIST_LO, CP_HIST_DLOG, CP_CONTACT_LAW, CP_DAMP_AT_STEP) = range(23)
N_CP = 23

STATUS_OK = 0
STATUS_CONTACT_TABLE_FULL = 1
STATUS_NONFINITE = 2


@nb.njit(cache=True)
def build_neighbour_list(pos, rad, skin, lz, b_partner, b_index):
    """Pairs (i < j) within ``R_i + R_j + skin`` by sorted linked cells.

    Returns (pair_i, pair_j, pair_bond, n_pairs); ``pair_bond`` is the bond index of a bonded
    pair or -1.
    """
    n = pos.shape[0]
    cell = 2.0 * np.max(rad) + skin
    lo = np.empty(3)
    hi = np.empty(3)
    for d in range(3):
        lo[d] = np.min(pos[:, d]) - 1e-9
        hi[d] = np.max(pos[:, d]) + 1e-9
    periodic = lz > 0.0
    if periodic:
        lo[2] = 0.0
        hi[2] = lz
    # cap the number of cells at ~8 per sphere (fragments flying apart)
    while True:
        nx = max(1, int((hi[0] - lo[0]) / cell))
        ny = max(1, int((hi[1] - lo[1]) / cell))
        nz = max(1, int((hi[2] - lo[2]) / cell))
        if nx * ny * nz <= 8 * n + 27:
            break
        cell *= 1.5
    if periodic and nz < 3:
        nz = 1
    cx = (hi[0] - lo[0]) / nx
    cy = (hi[1] - lo[1]) / ny
    cz = (hi[2] - lo[2]) / nz
    cid = np.empty(n, dtype=np.int64)
    ci = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        a = min(nx - 1, max(0, int((pos[i, 0] - lo[0]) / cx)))
        b = min(ny - 1, max(0, int((pos[i, 1] - lo[1]) / cy)))
        zz = pos[i, 2]
        if periodic:
            zz -= lz * math.floor(zz / lz)
        c = min(nz - 1, max(0, int((zz - lo[2]) / cz)))
        ci[i, 0] = a
        ci[i, 1] = b
        ci[i, 2] = c
        cid[i] = (a * ny + b) * nz + c
    order = np.argsort(cid)
    ncell = nx * ny * nz
    start = np.zeros(ncell + 1, dtype=np.int64)
    for i in range(n):
        start[cid[i] + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    cap = 16 * n + 16
    pi = np.empty(cap, dtype=np.int64)
    pj = np.empty(cap, dtype=np.int64)
    npair = 0
    dzr = 1 if nz > 1 else 0
    for i in range(n):
        for ox in range(-1, 2):
            a = ci[i, 0] + ox
            if a < 0 or a >= nx:
                continue
            for oy in range(-1, 2):
                b = ci[i, 1] + oy
                if b < 0 or b >= ny:
                    continue
                for oz in range(-dzr, dzr + 1):
                    c = ci[i, 2] + oz
                    if periodic:
                        c = c % nz
                    elif c < 0 or c >= nz:
                        continue
                    cc = (a * ny + b) * nz + c
                    for q in range(start[cc], start[cc + 1]):
                        j = order[q]
                        if j <= i:
                            continue
                        dx = pos[j, 0] - pos[i, 0]
                        dy = pos[j, 1] - pos[i, 1]
                        dz = pos[j, 2] - pos[i, 2]
                        if periodic:
                            dz -= lz * math.floor(dz / lz + 0.5)
                        rc = rad[i] + rad[j] + skin
                        if dx * dx + dy * dy + dz * dz < rc * rc:
                            if npair == cap:
                                cap *= 2
                                ni = np.empty(cap, dtype=np.int64)
                                nj = np.empty(cap, dtype=np.int64)
                                ni[:npair] = pi[:npair]
                                nj[:npair] = pj[:npair]
                                pi = ni
                                pj = nj
                            pi[npair] = i
                            pj[npair] = j
                            npair += 1
    pb = np.full(npair, -1, dtype=np.int64)
    for k in range(npair):
        i = pi[k]
        for s in range(b_partner.shape[1]):
            if b_partner[i, s] == pj[k]:
                pb[k] = b_index[i, s]
                break
    return pi[:npair], pj[:npair], pb, npair


@nb.njit(inline="always", cache=True)
def _cundall_damped(f, v, alpha):
    """Cundall's local non-viscous damping ``f - alpha |f| sign(v)`` (Cundall 1987; Potyondy &
    Cundall 2004, eq. 2); ``f`` unchanged when ``v = 0``."""
    s = f * v
    if s > 0.0:
        return f - alpha * f
    if s < 0.0:
        return f + alpha * f
    return f


@nb.njit(cache=True)
def compute_forces(pos, vel, omega, rad, mass, force, torque, cp, dt, pi, pj, pb, c_partner,
                   c_xi, b_ij, b_props, b_fn, b_fs, b_mb, b_mt, b_len, b_state, w_p, w_n, w_v,
                   w_f, w_xi, w_in, drum_angle, lifter_angles, d_xi, d_in, hist_pp, hist_pw):
    """All forces and torques at the current positions (mid-step velocities).

    Returns (status, drum torque N m, number of bonds broken in this call).
    """
    n = pos.shape[0]
    for i in range(n):
        force[i, 0] = mass[i] * cp[CP_GX]
        force[i, 1] = mass[i] * cp[CP_GY]
        force[i, 2] = mass[i] * cp[CP_GZ]
        torque[i, 0] = 0.0
        torque[i, 1] = 0.0
        torque[i, 2] = 0.0
    status = 0
    lz = cp[CP_LZ]
    for k in range(pi.shape[0]):
        b = pb[k]
        ov0 = 0.0
        if b >= 0:
            if b_state[b] == 0 or b_state[b] == BROKEN_SHEAR_SLIDING:
                continue  # carried by bond_forces
            ov0 = b_props[b, P_OVERLAP0]
            if b_props[b, P_SIGNED_MC] != 0.0:
                # "yade_jcfpm": the contact of a broken bond is erased while the spheres are
                # apart by more than its initD, and re-created stress-free at the overlap
                # they then have (Yade JCFpm: initD = penetration depth at creation)
                ex = pos[pj[k], 0] - pos[pi[k], 0]
                ey = pos[pj[k], 1] - pos[pi[k], 1]
                ez = pos[pj[k], 2] - pos[pi[k], 2]
                if lz > 0.0:
                    ez -= lz * math.floor(ez / lz + 0.5)
                pen = rad[pi[k]] + rad[pj[k]] - math.sqrt(ex * ex + ey * ey + ez * ez)
                if pen < ov0:
                    ov0 = pen if pen > 0.0 else 0.0
                    b_props[b, P_OVERLAP0] = ov0
        st = pair_contact(pi[k], pj[k], pos, vel, omega, rad, mass, force, torque, lz,
                          cp[CP_ESTAR_PP], cp[CP_GSTAR_PP], cp[CP_MU_PP], cp[CP_ETA_PP], dt,
                          c_partner, c_xi, hist_pp, cp[CP_HIST_LO], cp[CP_HIST_DLOG], ov0,
                          cp[CP_CONTACT_LAW])
        if st != 0:
            status = STATUS_CONTACT_TABLE_FULL
    nbroken = bond_forces(pos, vel, omega, rad, force, torque, lz, dt, b_ij, b_props, b_fn, b_fs,
                          b_mb, b_mt, b_len, b_state, cp[CP_BETA])
    if w_p.shape[0] > 0:
        plane_walls(pos, vel, omega, rad, mass, force, torque, w_p, w_n, w_v, w_f, w_xi, w_in,
                    cp[CP_ESTAR_PW], cp[CP_GSTAR_PW], cp[CP_MU_PW], cp[CP_ETA_PW], dt, hist_pw,
                    cp[CP_HIST_LO], cp[CP_HIST_DLOG], cp[CP_CONTACT_LAW])
    tq = 0.0
    if cp[CP_DRUM_R] > 0.0:
        tq = drum_walls(pos, vel, omega, rad, mass, force, torque, cp[CP_DRUM_R],
                        cp[CP_DRUM_OMEGA], drum_angle, lifter_angles, cp[CP_LIFTER_H],
                        cp[CP_LIFTER_HW], d_xi, d_in, cp[CP_ESTAR_PW], cp[CP_GSTAR_PW],
                        cp[CP_MU_PW], cp[CP_ETA_PW], dt, hist_pw, cp[CP_HIST_LO],
                        cp[CP_HIST_DLOG], cp[CP_CONTACT_LAW])
    alpha = cp[CP_LOCAL_DAMPING]
    if alpha > 0.0:
        # the velocity whose sign the damping opposes: the mid-step one, or with
        # CP_DAMP_AT_STEP Yade's NewtonIntegrator::cundallDamp2nd, the velocity at the time of
        # the force, v(t) ~ v(t - dt/2) + dt/2 F/m
        hdt = 0.5 * dt if cp[CP_DAMP_AT_STEP] != 0.0 else 0.0
        for i in range(n):
            im = 1.0 / mass[i]
            ii = 1.0 / (0.4 * mass[i] * rad[i] * rad[i])
            for d in range(3):
                fd = force[i, d]
                force[i, d] = _cundall_damped(fd, vel[i, d] + hdt * fd * im, alpha)
                td = torque[i, d]
                torque[i, d] = _cundall_damped(td, omega[i, d] + hdt * td * ii, alpha)
    return status, tq, nbroken


@nb.njit(cache=True)
def run_steps(n_steps, dt, pos, vel, omega, rad, mass, inertia, force, torque, cp, pos_ref,
              pi, pj, pb, c_partner, c_xi, b_ij, b_props, b_fn, b_fs, b_mb, b_mt, b_len, b_state,
              b_partner, b_index, w_p, w_n, w_v, w_mass, w_f, w_xi, w_in, drum_angle,
              lifter_angles, d_xi, d_in, hist_pp, hist_pw, rec_wall_f, rec_wall_pos,
              rec_torque, rec_broken):
    """Advance ``n_steps`` velocity-Verlet steps; ``force``/``torque`` must hold the forces at entry.

    Planar walls move with ``w_v``; a wall with ``w_mass > 0`` is free along its normal and is
    accelerated by the spheres' reaction and gravity (drop weight). Records per step: wall
    forces (N, along each wall normal, positive = pushed outwards), wall positions along the
    normals, drum torque, bonds broken.
    Returns (status, steps done, drum angle, pair_i, pair_j, pair_bond).
    """
    n = pos.shape[0]
    lz = cp[CP_LZ]
    skin = cp[CP_SKIN]
    half = 0.5 * dt
    status = 0
    ang = drum_angle
    done = 0
    for step in range(n_steps):
        # kick + drift
        for i in range(n):
            im = 1.0 / mass[i]
            ii = 1.0 / inertia[i]
            for d in range(3):
                vel[i, d] += half * force[i, d] * im
                omega[i, d] += half * torque[i, d] * ii
                pos[i, d] += dt * vel[i, d]
            if lz > 0.0:
                pos[i, 2] -= lz * math.floor(pos[i, 2] / lz)
        for k in range(w_p.shape[0]):
            for d in range(3):
                w_p[k, d] += dt * w_v[k, d]
        ang += cp[CP_DRUM_OMEGA] * dt
        # neighbour list
        mx = 0.0
        for i in range(n):
            dx = pos[i, 0] - pos_ref[i, 0]
            dy = pos[i, 1] - pos_ref[i, 1]
            dz = pos[i, 2] - pos_ref[i, 2]
            if lz > 0.0:
                dz -= lz * math.floor(dz / lz + 0.5)
            r2 = dx * dx + dy * dy + dz * dz
            if r2 > mx:
                mx = r2
        if math.sqrt(mx) > 0.5 * skin:
            pi, pj, pb, npair = build_neighbour_list(pos, rad, skin, lz, b_partner, b_index)
            pos_ref[:, :] = pos
        st, tq, nbr = compute_forces(pos, vel, omega, rad, mass, force, torque, cp, dt, pi, pj,
                                     pb, c_partner, c_xi, b_ij, b_props, b_fn, b_fs, b_mb, b_mt,
                                     b_len, b_state, w_p, w_n, w_v, w_f, w_xi, w_in, ang,
                                     lifter_angles, d_xi, d_in, hist_pp, hist_pw)
        if st != 0:
            status = st
        # kick
        for i in range(n):
            im = 1.0 / mass[i]
            ii = 1.0 / inertia[i]
            for d in range(3):
                vel[i, d] += half * force[i, d] * im
                omega[i, d] += half * torque[i, d] * ii
        for k in range(w_p.shape[0]):
            if w_mass[k] > 0.0:
                fnrm = (w_f[k, 0] * w_n[k, 0] + w_f[k, 1] * w_n[k, 1] + w_f[k, 2] * w_n[k, 2])
                gn = cp[CP_GX] * w_n[k, 0] + cp[CP_GY] * w_n[k, 1] + cp[CP_GZ] * w_n[k, 2]
                acc = fnrm / w_mass[k] + gn
                for d in range(3):
                    w_v[k, d] += dt * acc * w_n[k, d]
        for k in range(w_p.shape[0]):
            rec_wall_f[step, k] = -(w_f[k, 0] * w_n[k, 0] + w_f[k, 1] * w_n[k, 1]
                                    + w_f[k, 2] * w_n[k, 2])
            rec_wall_pos[step, k] = (w_p[k, 0] * w_n[k, 0] + w_p[k, 1] * w_n[k, 1]
                                     + w_p[k, 2] * w_n[k, 2])
        rec_torque[step] = tq
        rec_broken[step] = nbr
        done = step + 1
        if not math.isfinite(vel[0, 0] + force[n - 1, 2] + pos[n // 2, 0]):
            status = STATUS_NONFINITE
            break
    return status, done, ang, pi, pj, pb
