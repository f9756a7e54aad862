"""The DEM against its published sources: each expected number is written out here from the
source (Johnson 1985; Mindlin 1949; Yade's Ip2_FrictMat_FrictMat_FrictPhys and
Ig2_Wall_Sphere_ScGeom; Potyondy & Cundall 2004; Cundall 1987), not taken from dem's own
helpers, so a wrong exponent, factor or moment of inertia in dem makes these fail."""

import math

import numpy as np
import pytest
import scipy.constants
from scipy.integrate import quad
from scipy.special import beta as beta_fn

from dem.bonds import BROKEN_SHEAR, BROKEN_TENSION, INTACT, BondParams, BondSet, bond_step, kn_from_modulus_Pa_m
from dem.errors import DemInputError
from dem.materials import HERTZ_DURATION_COEF, STEEL, Material
from dem.system import DrumGeometry, PlaneWall, System

G = scipy.constants.g
R1, R2 = 1.0e-3, 1.5e-3
ROCK = Material(youngs_modulus_Pa=30e9, poisson_ratio=0.25, density_kg_m3=2700.0, friction_coef=0.5,
                restitution=1.0)
#: steel with no damping (restitution 1), so a wall's forces are its springs alone
STEEL_ELASTIC = Material(youngs_modulus_Pa=210e9, poisson_ratio=0.3, density_kg_m3=7800.0, friction_coef=0.3,
                         restitution=1.0)


def e_star_johnson(a: Material, b: Material) -> float:
    """Johnson (1985) §4.2: 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2."""
    return 1.0 / ((1 - a.poisson_ratio**2) / a.youngs_modulus_Pa + (1 - b.poisson_ratio**2) / b.youngs_modulus_Pa)


def g_star_mindlin(a: Material, b: Material) -> float:
    """Mindlin (1949) / Johnson (1985) §7.2: 1/G* = (2 - nu1)/G1 + (2 - nu2)/G2, G = E / (2 (1 + nu))."""
    ga = a.youngs_modulus_Pa / (2 * (1 + a.poisson_ratio))
    gb = b.youngs_modulus_Pa / (2 * (1 + b.poisson_ratio))
    return 1.0 / ((2 - a.poisson_ratio) / ga + (2 - b.poisson_ratio) / gb)


def test_hertz_duration_coefficient_is_the_closed_form():
    """Hertz's impact (Johnson 1985, ch. 11): the contact lasts 2 d_max/v int_0^1 dx / sqrt(1 - x^(5/2)) with
    d_max = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5), i.e. 2 (15/16)^(2/5) 1.4716 (m*^2/(R* E*^2 v))^(1/5); the
    integral is (2/5) B(2/5, 1/2) = 1.4716, so the coefficient is 2.8683 (not 2 x 1.4716 = 2.943)."""
    integral = 0.4 * beta_fn(0.4, 0.5)
    assert integral == pytest.approx(quad(lambda x: 1 / math.sqrt(1 - x**2.5), 0, 1)[0], rel=1e-6)
    assert HERTZ_DURATION_COEF == pytest.approx(2 * (15 / 16) ** 0.4 * integral, rel=1e-4)


def _pair_forces(law, delta, vt=0.0, dt=1e-9, material=ROCK):
    """Force on sphere 1 of two spheres (radii R1, R2, at rest) overlapping by ``delta``, after
    sphere 1 moved tangentially (+y) at ``vt`` for one step ``dt`` (restitution 1: no damping)."""
    s = System([[0, 0, 0], [R1 + R2 - delta, 0, 0]], [R1, R2], material, contact_law=law)
    s.vel[1, 1] = vt
    s._forces(dt)
    return s, s.force[1].copy()


@pytest.mark.parametrize("nu", [0.0, 0.25, 0.45])
def test_hertz_mindlin_pair_stiffnesses_follow_johnson(nu):
    """Normal force 4/3 E* sqrt(R*) d^1.5 (Hertz; Johnson 1985 §4.2) and tangential stiffness 8 G* sqrt(R* d)
    (Mindlin 1949; Johnson §7.2), E* = E/(2(1-nu^2)) and G* = G/(2(2-nu)) for identical materials: the
    ratio S_t/S_n is 2(1-nu)/(2-nu)."""
    mat = Material(youngs_modulus_Pa=30e9, poisson_ratio=nu, density_kg_m3=2700.0, restitution=1.0)
    e = mat.youngs_modulus_Pa
    e_star = e / (2 * (1 - nu**2))
    g_star = e / (2 * (1 + nu)) / (2 * (2 - nu))
    r_star = R1 * R2 / (R1 + R2)
    delta, vt, dt = 1e-6, 1e-3, 1e-9
    _, f = _pair_forces("hertz_mindlin", delta, vt, dt, mat)
    assert f[0] == pytest.approx(4 / 3 * e_star * math.sqrt(r_star) * delta**1.5, rel=1e-9)
    s_t = -f[1] / (vt * dt)
    assert s_t == pytest.approx(8 * g_star * math.sqrt(r_star * delta), rel=1e-9)
    s_n = 2 * e_star * math.sqrt(r_star * delta)            # dF_n/d(delta) of Hertz
    assert s_t / s_n == pytest.approx(2 * (1 - nu) / (2 - nu), rel=1e-9)


def test_yade_linear_pair_stiffnesses():
    """Yade's Ip2_FrictMat_FrictMat_FrictPhys: k_n = 2 E1 R1 E2 R2 / (E1 R1 + E2 R2), k_s the same with
    E nu (nu is Yade's k_s/k_n); F_n = k_n d (Law2_ScGeom_FrictPhys_CundallStrack)."""
    e, nu = ROCK.youngs_modulus_Pa, ROCK.poisson_ratio
    k_n = 2 * e * R1 * e * R2 / (e * R1 + e * R2)
    k_s = 2 * e * nu * R1 * e * nu * R2 / (e * nu * R1 + e * nu * R2)
    delta, vt, dt = 1e-6, 1e-3, 1e-9
    _, f = _pair_forces("linear_yade", delta, vt, dt)
    assert f[0] == pytest.approx(k_n * delta, rel=1e-9)
    assert -f[1] / (vt * dt) == pytest.approx(k_s, rel=1e-9)


@pytest.mark.parametrize("law", ["hertz_mindlin", "linear_yade"])
def test_wall_stiffnesses(law):
    """Sphere on a plane: Hertz with R* = R, Johnson's E* and Mindlin's G* of the two materials; Yade's
    Ig2_Wall_Sphere_ScGeom gives the wall the sphere's radius, so k_n = 2 R Es Ew / (Es + Ew)."""
    r, delta, vt, dt = R1, 1e-6, 1e-3, 1e-9
    wall = STEEL_ELASTIC
    s = System([[0, 0, r - delta]], [r], ROCK, wall_material=wall, walls=[PlaneWall((0, 0, 0), (0, 0, 1))],
               contact_law=law)
    s.vel[0, 1] = vt
    s._forces(dt)
    fz, s_t = s.force[0, 2], -s.force[0, 1] / (vt * dt)
    if law == "hertz_mindlin":
        assert fz == pytest.approx(4 / 3 * e_star_johnson(ROCK, wall) * math.sqrt(r) * delta**1.5, rel=1e-9)
        assert s_t == pytest.approx(8 * g_star_mindlin(ROCK, wall) * math.sqrt(r * delta), rel=1e-9)
    else:
        es, ew = ROCK.youngs_modulus_Pa, wall.youngs_modulus_Pa
        gs, gw = es * ROCK.poisson_ratio, ew * wall.poisson_ratio
        assert fz == pytest.approx(2 * es * r * ew * r / (es * r + ew * r) * delta, rel=1e-9)
        assert s_t == pytest.approx(2 * gs * r * gw * r / (gs * r + gw * r), rel=1e-9)


@pytest.mark.parametrize("law", ["hertz_mindlin", "linear_yade"])
def test_contact_energy_is_the_work_of_the_normal_force(law):
    """The stored energy (8/15 E* sqrt(R*) d^2.5, or k_n d^2/2) is the integral of the force the
    kernel applies over the overlap."""
    delta = 2e-6

    def force(d):
        return _pair_forces(law, d)[1][0] if d > 0 else 0.0

    work = quad(force, 0.0, delta, epsabs=0.0, epsrel=1e-10)[0]
    s, _ = _pair_forces(law, delta)
    assert s.contact_energy_J() == pytest.approx(work, rel=1e-8)


def _run_until_apart(s, gap):
    """Run one step at a time through a contact until ``gap()`` is >= 0 again; returns its duration (s)."""
    start = None
    for _ in range(100000):
        s.run(1)
        if gap() < 0 and start is None:
            start = s.time_s
        if start is not None and gap() >= 0:
            return s.time_s - start
    raise AssertionError("the contact did not end")


@pytest.mark.parametrize("e", [1.0, 0.5])
def test_sphere_on_fixed_wall_keeps_restitution_and_hertz_duration(e):
    """Head-on on a fixed wall of the same restitution: rebound at e v (the damping is solved for
    e); undamped, the contact lasts 2.8683 (m^2/(R E*^2 v))^(1/5) (Hertz; m* = m, R* = R)."""
    r, v = R1, 1.0
    mat = Material(30e9, 0.25, 2700.0, 0.5, e)
    wall = Material(210e9, 0.3, 7800.0, 0.3, e)
    s = System([[0, 0, r * (1 + 1e-6)]], [r], mat, wall_material=wall, walls=[PlaneWall((0, 0, 0), (0, 0, 1))],
               time_step_factor=0.02)
    s.vel[0, 2] = -v
    s._forces(0.0)
    duration = _run_until_apart(s, lambda: s.pos[0, 2] - r)
    assert s.vel[0, 2] / v == pytest.approx(e, rel=5e-3)
    if e == 1.0:
        m = s.mass[0]
        t_c = 2 * (15 / 16) ** 0.4 * 0.4 * beta_fn(0.4, 0.5) * (m**2 / (r * e_star_johnson(mat, wall)**2 * v)) ** 0.2
        assert duration == pytest.approx(t_c, rel=1e-2)


def test_sphere_at_rest_on_a_wall_settles_to_the_hertz_overlap():
    """Weight m g carried by Hertz: d = (3 m g / (4 E* sqrt(R)))^(2/3) (Johnson 1985 §4.2)."""
    r = R1
    mat = Material(30e9, 0.25, 2700.0, 0.5, 0.2)
    s = System([[0, 0, r]], [r], mat, wall_material=STEEL, walls=[PlaneWall((0, 0, 0), (0, 0, 1))],
               gravity_m_s2=(0, 0, -G), time_step_factor=0.5)
    m = 2700.0 * 4 / 3 * math.pi * r**3
    expected = (3 * m * G / (4 * e_star_johnson(mat, STEEL) * math.sqrt(r))) ** (2 / 3)
    s.run(20000)
    assert r - s.pos[0, 2] == pytest.approx(expected, rel=1e-4)
    assert s.record_arrays()["wall_force_N"][-1, 0] == pytest.approx(m * G, rel=1e-4)  # pushed outwards


@pytest.mark.parametrize("velocity", ["mid_step", "at_force"])
def test_cundall_local_damping_scales_the_force_by_one_minus_alpha_sign(velocity):
    """Cundall (1987), Potyondy & Cundall (2004) eq. 2: F_d = -alpha |F| sign(v). Under gravity a sphere
    moving up decelerates at g (1 + alpha), one falling accelerates at g (1 - alpha)."""
    alpha, v0, steps = 0.3, 1.0, 200
    s = System([[0, 0, 0], [0.1, 0, 0]], [R1, R1], ROCK, gravity_m_s2=(0, 0, -G), local_damping=alpha,
               damping_velocity=velocity)
    s.vel[:, 2] = [v0, -v0]
    s._forces(0.0)
    s.run(steps)
    t = steps * s.dt_s
    assert s.vel[0, 2] == pytest.approx(v0 - G * (1 + alpha) * t, rel=1e-12)
    assert s.vel[1, 2] == pytest.approx(-v0 - G * (1 - alpha) * t, rel=1e-12)


def test_ball_resting_on_a_lifter_loads_the_drum_with_its_weight_moment():
    """Moment balance about the drum axis: a ball at rest on a horizontal lifter at x exerts the torque
    -m g x on the drum (its weight's moment), so the motor's power -T omega is m g times its lift speed."""
    r, hw = 0.01, 0.005
    drum = DrumGeometry(0.25, 0.0, n_lifters=1, lifter_height_m=0.02, lifter_width_m=2 * hw)
    x = 0.235                                     # above the lifter bar, which lies along +x
    mat = Material(1e9, 0.3, 7800.0, 0.3, 0.3)
    s = System([[x, hw + r, 0.05]], [r], mat, drum=drum, periodic_z_m=0.1, gravity_m_s2=(0, -G, 0),
               time_step_factor=0.5)
    s.run(4000)
    m = s.mass[0]
    assert s.pos[0, 0] == pytest.approx(x, abs=1e-9)
    assert s.record_arrays()["torque_Nm"][-1] == pytest.approx(-m * G * x, rel=1e-4)


# ------------------------------------------------------------------------ parallel bonds
KN, KS, LAMBDA = 1e13, 4e12, 0.8


def _bonded_pair(params):
    pos = np.array([[0.0, 0.0, 0.0], [2 * R1, 0.0, 0.0]])
    rad = np.array([R1, R1])
    return pos, rad, BondSet(np.array([[0, 1]]), pos, rad, params)


def _turn_until_broken(params, axis, dtheta):
    """Spin the two spheres of a bond (along x) in opposite senses about ``axis`` by ``dtheta`` a step
    (no relative velocity at the bond centre: a pure moment). Returns the bond set and the moment
    magnitudes before each step."""
    pos, rad, bs = _bonded_pair(params)
    dt = 1e-7
    omega = np.zeros((2, 3))
    omega[0, axis], omega[1, axis] = -0.5 * dtheta / dt, 0.5 * dtheta / dt
    moments = []
    for _ in range(20000):
        moments.append(float(np.linalg.norm(bs.mb[0])) if axis else abs(float(bs.mt[0])))
        if bond_step(0, bs.ij, bs.props, bs.fn, bs.fs, bs.mb, bs.mt, bs.length, bs.state, bs.arrays.load,
                     pos, np.zeros((2, 3)), omega, rad, 0.0, dt, bs.beta):
            return bs, moments
    raise AssertionError("the bond did not break")


@pytest.mark.parametrize("mode", ["bending", "twist"])
def test_parallel_bond_breaks_at_its_strength_times_the_area_moment_over_R(mode):
    """Potyondy & Cundall (2004) eqs. 5-11, R_b = lambda R: bending dM_b = -k_n I dtheta, I = pi R_b^4 / 4,
    tension at the periphery |M_b| R_b / I reaches sigma_t at M_b = sigma_t I / R_b; twist dM_t = -k_s J dtheta,
    J = pi R_b^4 / 2 = 2 I, shear |M_t| R_b / J reaches the cohesion at M_t = c J / R_b."""
    r_b = LAMBDA * R1
    if mode == "bending":
        strength, k, moment, axis, broken = 5e6, KN, math.pi * r_b**4 / 4, 1, BROKEN_TENSION
        p = BondParams(KN, KS, tensile_strength_Pa=strength, cohesion_Pa=1e12, radius_multiplier=LAMBDA,
                       moment_factor=1.0)
    else:
        strength, k, moment, axis, broken = 8e6, KS, math.pi * r_b**4 / 2, 0, BROKEN_SHEAR
        p = BondParams(KN, KS, tensile_strength_Pa=1e12, cohesion_Pa=strength, radius_multiplier=LAMBDA,
                       moment_factor=1.0)
    dtheta = 1e-6 / (k * moment)                # moment increment of 1e-6 N m a step
    bs, moments = _turn_until_broken(p, axis, dtheta)
    assert moments[1] == pytest.approx(k * moment * dtheta, rel=1e-9)
    assert bs.state[0] == broken
    m_break = strength * moment / r_b
    assert m_break - 1.01e-6 <= moments[-1] <= m_break


def test_bond_from_a_modulus_stretches_like_a_bar_of_that_modulus():
    """Potyondy & Cundall (2004) eq. 9: k_n = E_b / (R_i + R_j), so a bond between touching spheres
    (length L = 2R) has F / A = E_b dL / L whatever its radius multiplier."""
    e_b, strain = 40e9, 1e-5
    p = BondParams(kn_from_modulus_Pa_m(e_b, R1), KS, tensile_strength_Pa=1e12, cohesion_Pa=1e12,
                   radius_multiplier=LAMBDA, moment_factor=0.0)
    pos, rad, bs = _bonded_pair(p)
    dt = 1e-7
    vel = np.array([[0, 0, 0], [2 * R1 * strain / dt, 0, 0]])
    pos[1] += vel[1] * dt
    bond_step(0, bs.ij, bs.props, bs.fn, bs.fs, bs.mb, bs.mt, bs.length, bs.state, bs.arrays.load,
              pos, vel, np.zeros((2, 3)), rad, 0.0, dt, bs.beta)
    assert bs.state[0] == INTACT
    assert bs.fn[0] / (math.pi * (LAMBDA * R1) ** 2) == pytest.approx(e_b * strain, rel=1e-9)


@pytest.mark.parametrize("owner", ["material", "wall_material"])
def test_yade_linear_law_refuses_a_damped_restitution(owner):
    """Yade's Law2_ScGeom_FrictPhys_CundallStrack has no viscous damping; the kernels' damping is solved for a
    Hertz spring, so on the linear law e = 0.3 rebounded at 0.326 with no word. Refused, naming the field."""
    damped = Material(ROCK.youngs_modulus_Pa, ROCK.poisson_ratio, ROCK.density_kg_m3, ROCK.friction_coef, 0.3)
    kw = {"material": ROCK, "wall_material": STEEL_ELASTIC, owner: damped}
    with pytest.raises(DemInputError, match=rf"'{owner}' of System has restitution 0.3; contact_law 'linear_yade'"):
        System([[0, 0, 2 * R1]], [R1], kw["material"], wall_material=kw["wall_material"],
               walls=[PlaneWall((0, 0, 0), (0, 0, 1))], contact_law="linear_yade")
    System([[0, 0, 2 * R1]], [R1], kw["material"], wall_material=kw["wall_material"],
           walls=[PlaneWall((0, 0, 0), (0, 0, 1))], contact_law="hertz_mindlin")
