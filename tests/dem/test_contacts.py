"""Hertz–Mindlin contacts: analytic collisions, numba vs plain-Python reference, time step."""

import math

import numpy as np
import pytest

from dem.errors import DemInputError
from dem.materials import (Material, damping_coefficient, damping_coefficient_linear_formula,
                           effective_youngs_Pa, hertz_contact_duration_s, rayleigh_time_step_s)
from dem.reference import reference_forces
from dem.system import PlaneWall, System
from dem import kernels as K


def _collide(restitution, speed=1.0, r=1e-3):
    mat = Material(restitution=restitution, friction_coef=0.3)
    s = System([[0, 0, 0], [2 * r * (1 + 1e-6), 0, 0]], [r, r], mat, time_step_factor=0.02)
    s.vel[0, 0] = speed / 2
    s.vel[1, 0] = -speed / 2
    start = end = None
    for _ in range(200000):
        s.run(1)
        gap = s.pos[1, 0] - s.pos[0, 0] - 2 * r
        if gap < 0 and start is None:
            start = s.time_s
        if start is not None and gap >= 0:
            end = s.time_s
            break
    assert end is not None
    e = (s.vel[1, 0] - s.vel[0, 0]) / speed
    return s, e, end - start


def test_head_on_duration_matches_hertz():
    s, e, dur = _collide(1.0, speed=2.0)
    m = s.mass[0] / 2
    r_eff = s.rad[0] / 2
    e_star = effective_youngs_Pa(s.material, s.material)
    expected = hertz_contact_duration_s(m, r_eff, e_star, 2.0)
    assert abs(dur - expected) / expected < 0.02
    assert abs(e - 1.0) < 0.02


@pytest.mark.parametrize("e_target", [0.3, 0.5, 0.8])
def test_restitution_matches_target_and_is_speed_independent(e_target):
    _, e1, _ = _collide(e_target, speed=0.5)
    _, e2, _ = _collide(e_target, speed=4.0)
    assert abs(e1 - e_target) / e_target < 0.02
    assert abs(e2 - e_target) / e_target < 0.02


def _bounce_off_a_free_body(mass_ratio, r=2e-3):
    """Restitution of a sphere hit by a free plane body (a drop weight) of ``mass_ratio`` times its mass, the
    sphere and the body of one material (so the pair's restitution is its own), and the momentum's error."""
    mat = Material(restitution=0.5, friction_coef=0.3)
    m = System([[0.0, 0.0, 0.0]], [r], mat).mass[0]
    s = System([[0.0, 0.0, 0.0]], [r], mat, wall_material=mat, time_step_factor=0.02,
               walls=[PlaneWall((0, 0, r * (1 + 1e-6)), (0, 0, -1), (0, 0, -1.0), mass_kg=mass_ratio * m)])
    for _ in range(4000):
        s.run(25)
        if s.w_p[0, 2] - s.pos[0, 2] > r * (1 + 1e-6) and s.vel[0, 2] < 0:
            break
    M = mass_ratio * m
    return (s.w_v[0, 2] - s.vel[0, 2]) / 1.0, (M * s.w_v[0, 2] + m * s.vel[0, 2] + M) / M


@pytest.mark.parametrize("mass_ratio", [1.0, 3.0, 1e4])
def test_a_sphere_rebounds_off_a_free_body_at_the_materials_restitution(mass_ratio):
    """The wall contact's damping took the sphere's own mass, not the pair's m M / (m + M) (Tsuji et al. 1992),
    so a free body (a drop weight) of the sphere's mass gave e = 0.48 for 0.5 (too strong by sqrt(1 + m/M));
    a fixed wall is M infinite, as LIGGGHTS and LAMMPS take walls."""
    e, momentum_err = _bounce_off_a_free_body(mass_ratio)
    assert abs(momentum_err) < 1e-9
    assert e == pytest.approx(0.5, rel=0.01)


def test_linear_damping_formula_differs_from_exact_hertz_inversion():
    # the linear-spring closed form is not exact for Hertz: our inversion must differ from it
    assert abs(damping_coefficient(0.5) - damping_coefficient_linear_formula(0.5)) > 0.01
    assert damping_coefficient(1.0) == 0.0


def _random_system(seed, n=8):
    rng = np.random.default_rng(seed)
    r = 1e-3 * rng.uniform(0.8, 1.2, n)
    pos = np.zeros((n, 3))
    pos[:, 0] = np.cumsum(np.r_[0.0, 1.9e-3 * np.ones(n - 1)])
    pos[:, 1:] = rng.normal(0, 2e-4, (n, 2))
    mat = Material(restitution=0.6, friction_coef=0.4)
    walls = [PlaneWall((0, 0, -1.05e-3), (0, 0, 1), (0, 0, 0.01))]
    s = System(pos, r, mat, walls=walls)
    s.vel[:] = rng.normal(0, 0.3, (n, 3))
    s.omega[:] = rng.normal(0, 300.0, (n, 3))
    # put some history on existing contacts
    s.pairs.xi[:] = rng.normal(0, 1e-7, s.pairs.xi.shape)
    s.w_xi[:] = rng.normal(0, 1e-7, s.w_xi.shape)
    return s


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_numba_forces_match_plain_python_reference(seed):
    s = _random_system(seed)
    pr = s.pairs
    hist = {(int(pr.i[k]), int(pr.j[k])): pr.xi[k].copy() for k in range(pr.i.shape[0]) if pr.touch[k]}
    wh = {(i, 0): s.w_xi[i, 0].copy() for i in range(s.n) if s.w_in[i, 0]}
    assert len(hist) >= 3 and len(wh) >= 2
    cp = s.cp
    dt = s.dt_s
    f_ref, t_ref, h_ref, wh_ref = reference_forces(
        s.pos, s.vel, s.omega, s.rad, s.mass, e_star=cp[K.CP_ESTAR_PP], g_star=cp[K.CP_GSTAR_PP],
        mu=cp[K.CP_MU_PP], eta=cp[K.CP_ETA_PP], dt=dt, history=hist,
        walls=[(s.w_p[0], s.w_n[0], s.w_v[0])], wall_history=wh, e_star_w=cp[K.CP_ESTAR_PW],
        g_star_w=cp[K.CP_GSTAR_PW], mu_w=cp[K.CP_MU_PW], eta_w=cp[K.CP_ETA_PW])
    s._forces(dt)
    scale = np.max(np.abs(f_ref))
    assert scale > 0
    np.testing.assert_allclose(s.force, f_ref, rtol=1e-9, atol=1e-9 * scale)
    np.testing.assert_allclose(s.torque, t_ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(t_ref)))
    for (i, j), xi in h_ref.items():
        k = int(np.nonzero((pr.i == i) & (pr.j == j))[0][0])
        np.testing.assert_allclose(pr.xi[k], xi, rtol=1e-9, atol=1e-15)
    for (i, _), xi in wh_ref.items():
        np.testing.assert_allclose(s.w_xi[i, 0], xi, rtol=1e-9, atol=1e-15)


def test_rayleigh_time_step_formula():
    mat = Material(youngs_modulus_Pa=30e9, poisson_ratio=0.25, density_kg_m3=2700)
    g = 30e9 / 2.5
    expected = math.pi * 1e-3 * math.sqrt(2700 / g) / (0.1631 * 0.25 + 0.8766)
    assert rayleigh_time_step_s(1e-3, mat) == pytest.approx(expected, rel=1e-12)


def test_critical_time_step_is_respected():
    mat = Material()
    s = System([[0, 0, 0], [3e-3, 0, 0]], [1e-3, 1e-3], mat)
    assert s.dt_s <= 0.2 * s.critical_dt_s * (1 + 1e-12)
    with pytest.raises(DemInputError, match="dt_s"):
        System([[0, 0, 0], [3e-3, 0, 0]], [1e-3, 1e-3], mat, dt_s=1.01 * s.critical_dt_s)
    with pytest.raises(DemInputError, match="time_step_factor"):
        System([[0, 0, 0], [3e-3, 0, 0]], [1e-3, 1e-3], mat, time_step_factor=1.5)


def test_material_validation_names_field_value_and_range():
    with pytest.raises(DemInputError, match=r"'restitution'.*\(0.0, 1.0\].*1.5"):
        Material(restitution=1.5)
    with pytest.raises(DemInputError, match="youngs_modulus_Pa"):
        Material(youngs_modulus_Pa=-1.0)
