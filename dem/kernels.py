"""Neighbour search, force assembly and velocity-Verlet integration (numba, SI units).

- Neighbour search: sort-based linked cells (cell edge = largest diameter + skin) building a
  Verlet list of pairs within ``R_i + R_j + skin``; rebuilt when any sphere has moved more than
  half the skin since the last build (Allen & Tildesley, *Computer Simulation of Liquids*,
  §5.3), the contact histories carried over pair by pair. Optional periodicity along z (drum
  slice).
- Parallel (numba ``prange``) over blocks of bonds, over pairs and over spheres (the
  neighbour search is serial), each writing only its own rows; per-sphere sums in a fixed
  order (:mod:`dem.state`), so the results do not depend on the number of threads
  (``NUMBA_NUM_THREADS`` or ``numba.set_num_threads``). Element functions (one contact, one bond, one sphere's walls)
  are inlined and take plain arrays and scalars: a call that passes arrays, or a view made per
  contact, costs reference counting that the threads contend for.
- Integration: velocity Verlet (kick–drift–kick), the standard explicit DEM scheme
  (Allen & Tildesley §3.2); forces use the mid-step velocities for damping and incremental
  springs.
- Optional Cundall local (non-viscous) damping ``F <- F - alpha |F| sign(v)`` per component
  (Potyondy & Cundall 2004 §2.3; Yade ``NewtonIntegrator.damping``) for quasi-static tests;
  ``v`` is the mid-step velocity, or with ``CP_DAMP_AT_STEP`` (System ``damping_velocity=
  "at_force"``) Yade's ``cundallDamp2nd`` estimate ``v + dt/2 F/m`` at the time of the force.

Developers: the kernels are cached by numba (``cache=True``) in :func:`dem.kernel_cache_dir`, a
folder named by a hash of every dem source: numba itself checks only this file's content, not
that of the files whose functions it compiles in (``dem.bonds``, ``dem.contacts``). A new module
with kernels must be imported by ``dem/__init__.py`` (which points numba's cache there while it
imports them).
"""

from __future__ import annotations

import math
import os

import numba as nb
import numpy as np

from dem.bonds import BOND_BLOCK, BROKEN_SHEAR_SLIDING, INTACT, P_OVERLAP0, P_SIGNED_MC, bond_block
from dem.contacts import drum_walls, hist_add, pair_contact, plane_walls
from dem.state import N_LOAD, PairArrays, add_rows, fill_csr, unsigned

# indices of the scalar parameter vector ``cp``
(CP_ESTAR_PP, CP_GSTAR_PP, CP_MU_PP, CP_ETA_PP, CP_ESTAR_PW, CP_GSTAR_PW, CP_MU_PW, CP_ETA_PW,
 CP_LOCAL_DAMPING, CP_GX, CP_GY, CP_GZ, CP_LZ, CP_SKIN, CP_BETA, CP_DRUM_R, CP_DRUM_OMEGA,
 CP_LIFTER_H, CP_LIFTER_HW, CP_HIST_LO, CP_HIST_DLOG, CP_CONTACT_LAW, CP_DAMP_AT_STEP,
 CP_CENTRAL_BONDS) = range(24)
N_CP = 24

#: numba's threading layers in the order tried, unless the user chose one (NUMBA_THREADING_LAYER
#: or NUMBA_THREADING_LAYER_PRIORITY): OpenMP first. numba's own default puts TBB first, and
#: with TBB a step of a few thousand spheres gained nothing from the second core where OpenMP
#: gained (benchmarks/results/dem_parallel_speed.md records the layer that ran)
THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]
if not {"NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY"} & set(os.environ):
    nb.config.THREADING_LAYER_PRIORITY = THREADING_LAYER_PRIORITY

STATUS_OK = 0
STATUS_REBUILD = 1
STATUS_NONFINITE = 2


@nb.njit(cache=True)
def _cell_grid(pos, rad, skin, lz):
    """Linked cells of edge >= largest diameter + skin: (lower corner, cell sizes, counts,
    cell of each sphere (n, 3), spheres sorted by cell, first sorted index of each cell)."""
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
    # cap the number of cells at ~8 per sphere (fragments flying apart), counted in floats: a
    # system blowing up spans distances whose cell counts overflow an integer (one cell then;
    # the run stops on its non-finite state soon after)
    span = np.empty(3)
    for d in range(3):
        span[d] = hi[d] - lo[d]
    if not (np.isfinite(span[0]) and np.isfinite(span[1]) and np.isfinite(span[2])):
        cell = math.inf
    while (max(1.0, math.floor(span[0] / cell)) * max(1.0, math.floor(span[1] / cell))
           * max(1.0, math.floor(span[2] / cell)) > 8.0 * n + 27.0):
        cell *= 1.5
    nx = max(1, int(span[0] / cell))
    ny = max(1, int(span[1] / cell))
    nz = max(1, int(span[2] / cell))
    if periodic and nz < 3:
        nz = 1
    size = np.array([(hi[0] - lo[0]) / nx, (hi[1] - lo[1]) / ny, (hi[2] - lo[2]) / nz])
    counts = np.array([nx, ny, nz])
    cid = np.empty(n, dtype=np.int64)
    ci = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        a = min(nx - 1, max(0, int((pos[i, 0] - lo[0]) / size[0])))
        b = min(ny - 1, max(0, int((pos[i, 1] - lo[1]) / size[1])))
        zz = pos[i, 2]
        if periodic:
            zz -= lz * math.floor(zz / lz)
        c = min(nz - 1, max(0, int((zz - lo[2]) / size[2])))
        ci[i, 0] = a
        ci[i, 1] = b
        ci[i, 2] = c
        cid[i] = (a * ny + b) * nz + c
    order = np.argsort(cid)
    start = np.zeros(nx * ny * nz + 1, dtype=np.int64)
    for i in range(n):
        start[cid[i] + 1] += 1
    for c in range(nx * ny * nz):
        start[c + 1] += start[c]
    return counts, ci, order, start


@nb.njit(cache=True)
def _scan_sphere(i, pos, rad, skin, lz, counts, ci, order, start, out_j, at):
    """Neighbours j > i of sphere i within ``R_i + R_j + skin`` in the 27 (9 if the periodic
    slice is one cell thick) surrounding cells, written to ``out_j[at:]``; returns their number.
    With ``at == -1`` only the number of spheres in those cells (a bound of the neighbours, with
    no distance computed); with ``at == -2`` the number of neighbours, nothing written."""
    nx, ny, nz = counts[0], counts[1], counts[2]
    periodic = lz > 0.0
    dzr = 1 if nz > 1 else 0
    found = 0
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
                if periodic:  # c is in [-1, nz]: wrapped without an integer division
                    c = c + nz if c < 0 else (c - nz if c >= nz else c)
                elif c < 0 or c >= nz:
                    continue
                cc = (a * ny + b) * nz + c
                if at == -1:
                    found += start[cc + 1] - start[cc]
                    continue
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
                        if at >= 0:
                            out_j[at + found] = j
                        found += 1
    return found


#: Largest scan buffer [entries of 8 bytes] of :func:`build_neighbour_list`: above it (a very large
#: or very polydisperse system, whose cells hold many spheres) the neighbours are counted first
#: and scanned again, as before the buffer, so the buffer never holds more than 64 MB
NEIGHBOUR_BUFFER_MAX = 1 << 23


@nb.njit(cache=True)
def build_neighbour_list(pos, rad, skin, lz, b_partner, b_index, max_buffer=NEIGHBOUR_BUFFER_MAX):
    """Pairs (i < j) within ``R_i + R_j + skin`` by sorted linked cells, grouped by i: each
    sphere's cells scanned once into its own slot of a buffer sized by the cells' occupancy
    (~70 entries a sphere in an agglomerate), then packed; if that buffer would exceed
    ``max_buffer`` entries, a count pass and a second scan instead. Serial: a parallel version
    doubled the kernels' compile time; in the drum the list is rebuilt every few tens of steps,
    in the compression test every ~1e3-1e4.

    Returns (pair_i, pair_j, pair_bond, first): ``pair_bond`` is the bond index of a bonded pair
    or -1; the pairs of sphere i are ``first[i]:first[i+1]``.
    """
    n = pos.shape[0]
    counts, ci, order, start = _cell_grid(pos, rad, skin, lz)
    dummy = np.empty(0, dtype=np.int64)
    # typed int64 like the scan's offsets: a literal compiles a second copy of _scan_sphere
    bound_only, count_only = np.int64(-1), np.int64(-2)
    slot = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        slot[i + 1] = slot[i] + _scan_sphere(i, pos, rad, skin, lz, counts, ci, order, start, dummy, bound_only)
    first = np.zeros(n + 1, dtype=np.int64)
    one_scan = slot[n] <= max_buffer
    buf = np.empty(slot[n] if one_scan else 0, dtype=np.int64)
    for i in range(n):
        if one_scan:
            found = _scan_sphere(i, pos, rad, skin, lz, counts, ci, order, start, buf, slot[i])
        else:
            found = _scan_sphere(i, pos, rad, skin, lz, counts, ci, order, start, dummy, count_only)
        first[i + 1] = first[i] + found
    npair = first[n]
    pi = np.empty(npair, dtype=np.int64)
    pj = np.empty(npair, dtype=np.int64)
    pb = np.full(npair, -1, dtype=np.int64)
    for i in range(n):
        if one_scan:
            for k in range(first[i], first[i + 1]):
                pj[k] = buf[slot[i] + k - first[i]]
        else:
            _scan_sphere(i, pos, rad, skin, lz, counts, ci, order, start, pj, first[i])
        for k in range(first[i], first[i + 1]):
            pi[k] = i
            for s in range(b_partner.shape[1]):
                if b_partner[i, s] == pj[k]:
                    pb[k] = b_index[i, s]
                    break
    return pi, pj, pb, first


@nb.njit(cache=True)
def new_pair_arrays(pi, pj, pb, first, b_state):
    """A :class:`dem.state.PairArrays` on a fresh neighbour list, no contact history; its
    active pairs those not carried by a bond in state ``b_state``."""
    npair = pi.shape[0]
    n = first.shape[0] - 1
    pr = PairArrays(pi, pj, pb, first, np.zeros((npair, 3)), np.zeros(npair, dtype=np.int8),
                    np.zeros((npair, N_LOAD)), np.full(npair, -1.0), np.empty(npair, dtype=np.int64),
                    np.zeros(1, dtype=np.int64), np.empty(n + 1, dtype=np.int64),
                    np.empty(2 * npair, dtype=np.int64))
    refresh_active(pr, b_state)
    return pr


@nb.njit(cache=True, inline="always")
def _carried(b, b_state):
    """True while bond b (-1: none) carries its pair: intact, or JCFpm's sliding after a shear
    break (see :data:`dem.bonds.BROKEN_SHEAR_SLIDING`)."""
    if b < 0:
        return False
    st = b_state[b]
    return st == INTACT or st == BROKEN_SHEAR_SLIDING


@nb.njit(cache=True)
def refresh_active(pr, b_state):
    """The pairs no bond carries (in increasing order) and their per-sphere CSR list, in place."""
    pb, active = pr.bond, pr.active
    m = 0
    for k in range(pb.shape[0]):
        if not _carried(pb[k], b_state):
            active[m] = k
            m += 1
    pr.n_active[0] = m
    # the count read back from its array: numba typed the local ``m`` as a literal 0 on some
    # paths and compiled fill_csr a second time
    fill_csr(pr.i, pr.j, active, pr.n_active[0], pr.sphere_start, pr.sphere_entry)


@nb.njit(cache=True)
def rebuild_pairs(sp, bd, old, skin, lz):
    """A new neighbour list at the current positions with the contact histories of the pairs
    that were already listed (matched within each sphere's group)."""
    pi, pj, pb, first = build_neighbour_list(sp.pos, sp.rad, skin, lz, bd.partner, bd.index)
    pr = new_pair_arrays(pi, pj, pb, first, bd.state)
    xi, touch = pr.xi, pr.touch
    o_first, o_j, o_xi, o_touch = old.first, old.j, old.xi, old.touch
    for i in range(first.shape[0] - 1):
        for k in range(first[i], first[i + 1]):
            for q in range(o_first[i], o_first[i + 1]):
                if o_j[q] == pj[k]:
                    touch[k] = o_touch[q]
                    for c in range(3):
                        xi[k, c] = o_xi[q, c]
                    break
    return pr


@nb.njit(cache=True)
def _cundall_damped(f, v, alpha):
    """Cundall's local non-viscous damping ``f - alpha |f| sign(v)`` (Cundall 1987; Potyondy &
    Cundall 2004, eq. 2); ``f`` unchanged when ``v = 0``."""
    s = f * v
    # both damped values made, then chosen: selects, no branch on the sign of f v, which varies
    # from sphere to sphere and component to component and is mispredicted
    lower = f - alpha * f
    higher = f + alpha * f
    out = lower if s > 0.0 else f
    return higher if s < 0.0 else out


@nb.njit(cache=True, inline="always")
def _contact_overlap0(k, pi, pj, pb, b_state, b_props, pos, rad, lz):
    """Overlap subtracted from active pair k's geometric overlap: 0 without a bond, else the
    overlap its broken bond had (JCFpm: lowered as the pair separates)."""
    k = unsigned(k)
    if pb[k] < 0:
        return 0.0
    b = unsigned(pb[k])
    ov0 = b_props[b, P_OVERLAP0]
    if b_props[b, P_SIGNED_MC] != 0.0:
        # "yade_jcfpm": the contact of a broken bond is erased while the spheres are apart by
        # more than its initD, and re-created stress-free at the overlap they then have (Yade
        # JCFpm: initD = penetration depth at creation)
        i = unsigned(pi[k])
        j = unsigned(pj[k])
        ex = pos[j, 0] - pos[i, 0]
        ey = pos[j, 1] - pos[i, 1]
        ez = pos[j, 2] - pos[i, 2]
        if lz > 0.0:
            ez -= lz * math.floor(ez / lz + 0.5)
        pen = rad[i] + rad[j] - math.sqrt(ex * ex + ey * ey + ez * ez)
        if pen < ov0:
            ov0 = pen if pen > 0.0 else 0.0
            b_props[b, P_OVERLAP0] = ov0
    return ov0


@nb.njit(cache=True, inline="always")
def _damp(i, force, torque, vel, om, im, ii, alpha, hdt):
    """Cundall local damping of sphere i of inverse mass ``im`` and inverse moment of inertia
    ``ii``; ``hdt`` 0 (mid-step velocity) or dt/2 (Yade's NewtonIntegrator::cundallDamp2nd: the
    velocity at the time of the force, v(t) ~ v(t - dt/2) + dt/2 F/m)."""
    for d in range(3):
        fd = force[i, d]
        force[i, d] = _cundall_damped(fd, vel[i, d] + hdt * fd * im, alpha)
        td = torque[i, d]
        torque[i, d] = _cundall_damped(td, om[i, d] + hdt * td * ii, alpha)


@nb.njit(cache=True, parallel=True)
def sphere_loads(sp, bd, pr, wl, dr, d_torque, cp, dt, drum_angle, kick, advance, pos_ref, lim2):
    """Total force and torque on each sphere (parallel over spheres): gravity, its bond and
    contact rows in a fixed order, walls and drum, then Cundall damping; with ``kick`` then the
    step's closing half kick of the sphere, and with ``advance`` also the next step's opening
    half kick and drift (:func:`_advance`), in the same parallel loop: each is one fewer
    barrier per step, and a sphere's arithmetic is the same as in separate loops. Returns the
    next step's drift counts (moved beyond half the skin, non-finite), 0 without ``advance``."""
    pos, vel, om, rad, mass, inertia, f, t = sp
    b_load, b_start, b_entry = bd.load, bd.sphere_start, bd.sphere_entry
    p_load, p_start, p_entry = pr.load, pr.sphere_start, pr.sphere_entry
    w_p, w_n, w_v, w_xi, w_touch, w_force, w_impact = wl.p, wl.n, wl.v, wl.xi, wl.touch, wl.f_sphere, wl.impact_J
    lifters, d_xi, d_touch, d_impact = dr.lifter_angles, dr.xi, dr.touch, dr.impact_J
    law = cp[CP_CONTACT_LAW]
    ew, gw, muw, etaw = cp[CP_ESTAR_PW], cp[CP_GSTAR_PW], cp[CP_MU_PW], cp[CP_ETA_PW]
    gx, gy, gz = cp[CP_GX], cp[CP_GY], cp[CP_GZ]
    alpha = cp[CP_LOCAL_DAMPING]
    hdt = 0.5 * dt if cp[CP_DAMP_AT_STEP] != 0.0 else 0.0
    drum_r = cp[CP_DRUM_R]
    central = cp[CP_CENTRAL_BONDS] != 0.0
    lz = cp[CP_LZ]
    nw = w_p.shape[0]
    moved = 0
    bad = 0
    for q in nb.prange(pos.shape[0]):
        i = unsigned(q)
        f[i, 0] = mass[i] * gx
        f[i, 1] = mass[i] * gy
        f[i, 2] = mass[i] * gz
        t[i, 0] = 0.0
        t[i, 1] = 0.0
        t[i, 2] = 0.0
        add_rows(b_load, b_start, b_entry, i, f, t, not central)
        add_rows(p_load, p_start, p_entry, i, f, t)
        if nw > 0:
            plane_walls(i, pos, vel, om, rad, mass, f, t, w_p, w_n, w_v, wl.mass, w_xi, w_touch, w_force,
                        w_impact, ew, gw, muw, etaw, dt, law)
        if drum_r > 0.0:
            d_torque[i] = drum_walls(i, pos, vel, om, rad, mass, f, t, lifters, d_xi, d_touch,
                                     d_impact, drum_r, cp[CP_DRUM_OMEGA], drum_angle,
                                     cp[CP_LIFTER_H], cp[CP_LIFTER_HW], ew, gw, muw, etaw, dt,
                                     law)
        # the divisions once a sphere (damping, closing kick and opening kick used three each)
        im = 1.0 / mass[i]
        ii = 1.0 / inertia[i]
        if alpha > 0.0:
            _damp(i, f, t, vel, om, im, ii, alpha, hdt)
        if kick:
            _half_kick(i, vel, om, im, ii, f, t, 0.5 * dt)
            if advance:
                code = _advance(i, pos, vel, om, im, ii, f, t, 0.5 * dt, dt, lz, pos_ref, lim2)
                moved += code == 1
                bad += code == 2
    return moved, bad


@nb.njit(cache=True)
def _collect(pr, wl, dr, cp, hist_pp, hist_pw):
    """The serial end of a force evaluation, in sphere order: wall reactions, drum torque,
    impact energies of new contacts into the histograms. Returns the drum torque."""
    lo = cp[CP_HIST_LO]
    dl = cp[CP_HIST_DLOG]
    p_impact, active = pr.impact_J, pr.active
    for q in range(pr.n_active[0]):
        k = active[q]
        if p_impact[k] >= 0.0:
            hist_add(hist_pp, lo, dl, p_impact[k])
    w_touch, w_force, w_impact, w_f = wl.touch, wl.f_sphere, wl.impact_J, wl.f
    n = w_touch.shape[0]
    for k in range(w_f.shape[0]):
        fx = fy = fz = 0.0
        for i in range(n):
            if w_touch[i, k]:
                fx += w_force[i, k, 0]
                fy += w_force[i, k, 1]
                fz += w_force[i, k, 2]
                if w_impact[i, k] >= 0.0:
                    hist_add(hist_pw, lo, dl, w_impact[i, k])
        w_f[k, 0] = fx
        w_f[k, 1] = fy
        w_f[k, 2] = fz
    tq = 0.0
    if cp[CP_DRUM_R] > 0.0:
        d_impact, d_torque = dr.impact_J, dr.torque_sphere
        for i in range(n):
            tq += d_torque[i]
            for k in range(d_impact.shape[1]):
                if d_impact[i, k] >= 0.0:
                    hist_add(hist_pw, lo, dl, d_impact[i, k])
    return tq


@nb.njit(cache=True, parallel=True, error_model="numpy")
def compute_forces(sp, bd, pr, wl, dr, cp, dt, drum_angle, hist_pp, hist_pw, kick=False, advance=False,
                   pos_ref=None, lim2=0.0):
    """All forces and torques at the current positions (mid-step velocities): the bonds, in
    parallel over blocks of BOND_BLOCK, then the contacts (every active pair of the Verlet list,
    those no bond carries), in parallel over pairs, each writing its own rows; a bond that breaks
    now leaves its contact to the next step (the active pairs are refreshed after the loops); then
    per sphere (with ``kick``, the step's closing half kick too). Each loop runs only when it has
    work: a bonded agglomerate before damage has no active pair, the drum no bond. (One loop for
    both, which saves a barrier when both have work, made the drum's contacts slower once the
    bond blocks were compiled into the same loop: docs/benchmarks.md.)

    With ``kick`` and ``advance``, the next step's opening half kick and drift too, checked
    against ``pos_ref`` (:func:`_advance`). Returns (drum torque N m, number of bonds broken in
    this call, the next step's drift counts: moved beyond half the skin, non-finite). A caller of this (and of
    any parallel kernel) must itself be compiled with ``parallel=True``: called from a plain
    njit function the parallel loops run 2-3x slower even on one thread (measured).

    ``error_model="numpy"``: a division by zero gives inf or nan (found by the callers' check of
    the state) instead of a test before every division, which would keep the bond blocks' loops
    from being vectorised.
    """
    pi, pj, pb, xi, touch, load, impact = pr.i, pr.j, pr.bond, pr.xi, pr.touch, pr.load, pr.impact_J
    active = pr.active
    pos, vel, om, rad, mass = sp.pos, sp.vel, sp.omega, sp.rad, sp.mass
    ij, b_props, fn, fs, mb, mt = bd.ij, bd.props, bd.fn, bd.fs, bd.mb, bd.mt
    length, b_state, b_load = bd.length, bd.state, bd.load
    lz = cp[CP_LZ]
    beta = cp[CP_BETA]
    central = cp[CP_CENTRAL_BONDS] != 0.0
    law = cp[CP_CONTACT_LAW]
    e_star, g_star, mu, eta = cp[CP_ESTAR_PP], cp[CP_GSTAR_PP], cp[CP_MU_PP], cp[CP_ETA_PP]
    nbond = ij.shape[0]
    n_act = pr.n_active[0]
    nb_blocks = (nbond + BOND_BLOCK - 1) // BOND_BLOCK
    scratch = bd.scratch
    nbroken = 0
    nreleased = 0
    if nb_blocks > 0:
        for q in nb.prange(nb_blocks):
            b0 = q * BOND_BLOCK
            broke, released = bond_block(b0, min(b0 + BOND_BLOCK, nbond), ij, b_props, fn, fs, mb, mt, length,
                                         b_state, b_load, pos, vel, om, rad, lz, dt, beta, central,
                                         scratch[nb.get_thread_id()])
            nbroken += broke
            nreleased += released
    if n_act > 0:
        for q in nb.prange(n_act):
            k = active[q]
            ov0 = _contact_overlap0(k, pi, pj, pb, b_state, b_props, pos, rad, lz)
            pair_contact(k, pi, pj, xi, touch, load, impact, pos, vel, om, rad, mass, lz, e_star,
                         g_star, mu, eta, dt, ov0, law)
    if nreleased > 0:
        refresh_active(pr, b_state)
    ref = sp.pos if pos_ref is None else pos_ref
    moved, bad = sphere_loads(sp, bd, pr, wl, dr, dr.torque_sphere, cp, dt, drum_angle, kick, advance, ref, lim2)
    return _collect(pr, wl, dr, cp, hist_pp, hist_pw), nbroken, moved, bad


@nb.njit(cache=True, inline="always")
def _half_kick(i, vel, om, im, ii, force, torque, half):
    """Half-step velocity update of sphere i (inverse mass ``im``, inverse moment of inertia ``ii``)
    from its current force and torque."""
    for d in range(3):
        vel[i, d] += half * force[i, d] * im
        om[i, d] += half * torque[i, d] * ii


@nb.njit(cache=True, inline="always")
def _advance(i, pos, vel, om, im, ii, force, torque, half, dt, lz, pos_ref, lim2):
    """Opening half kick and full position step of sphere i (wrapped into the periodic slice),
    then its check against the list's reference position: 0, 1 if it moved beyond half the skin,
    2 if its position is not finite."""
    _half_kick(i, vel, om, im, ii, force, torque, half)
    for d in range(3):
        pos[i, d] += dt * vel[i, d]
    if lz > 0.0:
        pos[i, 2] -= lz * math.floor(pos[i, 2] / lz)
    dx = pos[i, 0] - pos_ref[i, 0]
    dy = pos[i, 1] - pos_ref[i, 1]
    dz = pos[i, 2] - pos_ref[i, 2]
    if lz > 0.0:
        dz -= lz * math.floor(dz / lz + 0.5)
    d2 = dx * dx + dy * dy + dz * dz
    if d2 <= lim2:
        return 0
    return 1 if d2 < math.inf else 2  # NaN or infinite: a non-finite position


@nb.njit(cache=True, parallel=True)
def _kick_drift(sp, half, dt, lz, pos_ref, lim2):
    """:func:`_advance` of every sphere. Returns (spheres moved beyond half the skin, spheres
    with a non-finite position): integer counts, the same whatever the thread count; every
    sphere is checked, so one that blew up out of contact with the rest is found."""
    pos, vel, om, _, mass, inertia, force, torque = sp
    moved = 0
    bad = 0
    for i in nb.prange(pos.shape[0]):
        code = _advance(i, pos, vel, om, 1.0 / mass[i], 1.0 / inertia[i], force, torque, half, dt, lz, pos_ref,
                        lim2)
        moved += code == 1
        bad += code == 2
    return moved, bad


@nb.njit(cache=True)
def _drift_walls(wl, dt):
    """Planar walls' position step at their velocity (before the forces)."""
    for k in range(wl.p.shape[0]):
        for d in range(3):
            wl.p[k, d] += dt * wl.v[k, d]


@nb.njit(cache=True)
def _push_free_walls(wl, cp, dt):
    """After the forces: a free wall (``mass > 0``) accelerated along its normal by the spheres'
    reaction and gravity."""
    for k in range(wl.p.shape[0]):
        if wl.mass[k] > 0.0:
            fnrm = wl.f[k, 0] * wl.n[k, 0] + wl.f[k, 1] * wl.n[k, 1] + wl.f[k, 2] * wl.n[k, 2]
            gn = cp[CP_GX] * wl.n[k, 0] + cp[CP_GY] * wl.n[k, 1] + cp[CP_GZ] * wl.n[k, 2]
            acc = fnrm / wl.mass[k] + gn
            for d in range(3):
                wl.v[k, d] += dt * acc * wl.n[k, d]


@nb.njit(cache=True, parallel=True)
def run_steps(n_steps, dt, sp, bd, pr, wl, dr, cp, pos_ref, drum_angle, hist_pp, hist_pw,
              rec_wall_f, rec_wall_pos, rec_torque, rec_broken, drifted):
    """Advance up to ``n_steps`` velocity-Verlet steps; ``sp.force``/``sp.torque`` must hold the
    forces at entry.

    Planar walls move with their velocity; a wall with ``mass > 0`` is free along its normal
    (drop weight). Records per step: wall forces (N, along each wall normal, positive = pushed
    outwards), wall positions along the normals, drum torque, bonds broken.

    Once a sphere has moved more than half the skin after a drift, it returns
    ``STATUS_REBUILD`` before that step's forces: the caller rebuilds the list
    (:func:`rebuild_pairs`) and calls again with ``drifted=True`` to finish the step. The list
    is never replaced in here: reassigning a bundle of arrays in a loop of a ``parallel=True``
    function corrupted numba's reference counts (a segmentation fault some rebuilds later).
    Returns (status, steps done, drum angle).
    """
    pos = sp.pos
    n = pos.shape[0]
    lz = cp[CP_LZ]
    lim2 = (0.5 * cp[CP_SKIN]) ** 2
    half = 0.5 * dt
    ang = drum_angle
    moved = bad = 0
    for step in range(n_steps):
        if step > 0 or not drifted:  # else the caller's rebuild came after this step's drift
            if step == 0:  # later steps drift in the previous step's force pass
                moved, bad = _kick_drift(sp, half, dt, lz, pos_ref, lim2)
            _drift_walls(wl, dt)
            ang += cp[CP_DRUM_OMEGA] * dt
            if bad > 0:
                return STATUS_NONFINITE, step, ang
            if moved > 0:
                return STATUS_REBUILD, step, ang
        # the forces, the closing half kick and, unless this is the call's last step, the next
        # step's opening kick and drift, in one pass over the spheres
        # ``step >= 0`` (always true) rather than the constant True: a constant is typed
        # Literal[bool] and compiles a second copy of compute_forces beside the one System
        # calls with a plain bool (minutes on a cold cache)
        tq, nbr, moved, bad = compute_forces(sp, bd, pr, wl, dr, cp, dt, ang, hist_pp, hist_pw, step >= 0,
                                             step + 1 < n_steps, pos_ref, lim2)
        _push_free_walls(wl, cp, dt)
        for k in range(wl.p.shape[0]):
            rec_wall_f[step, k] = -(wl.f[k, 0] * wl.n[k, 0] + wl.f[k, 1] * wl.n[k, 1]
                                    + wl.f[k, 2] * wl.n[k, 2])
            rec_wall_pos[step, k] = (wl.p[k, 0] * wl.n[k, 0] + wl.p[k, 1] * wl.n[k, 1]
                                     + wl.p[k, 2] * wl.n[k, 2])
        rec_torque[step] = tq
        rec_broken[step] = nbr
        if not math.isfinite(sp.vel[0, 0] + sp.force[n - 1, 2] + pos[n // 2, 0]):
            return STATUS_NONFINITE, step + 1, ang
    return STATUS_OK, n_steps, ang
