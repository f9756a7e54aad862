"""Drum-mill charge DEM: short smoke run with physical checks, critical speed, validation."""

import math

import numpy as np
import pytest
import scipy.constants

from dem.drum import critical_speed_rad_s, drum_test
from dem.errors import DemInputError


def test_critical_speed_formula():
    assert critical_speed_rad_s(0.5, 0.025) == pytest.approx(math.sqrt(2 * scipy.constants.g / 0.475))
    with pytest.raises(DemInputError, match="ball_diameter_m"):
        critical_speed_rad_s(0.5, 0.6)


@pytest.fixture(scope="module")
def short_run():
    return drum_test(0.7, 0.3, ball_diameter_m=0.04, section_length_m=0.1, settle_revolutions=0.5,
                     measure_revolutions=0.5, random_state=1)


def test_drum_power_and_spectrum_are_physical(short_run):
    r = short_run
    # the charge resists the rotation: positive power, negative torque on the drum
    assert r.power_W > 0 and r.torque_Nm < 0
    # power is bounded by lifting the whole charge's weight at the shell speed
    m_charge = r.n_balls_full_mill * 7800 * math.pi * 0.04**3 / 6
    assert r.power_W < m_charge * scipy.constants.g * 0.25 * r.omega_rad_s
    sp = r.spectrum
    assert list(sp.columns) == ["energy_lo_J", "energy_hi_J", "energy_mid_J", "ball_ball_per_s",
                                "ball_wall_per_s", "total_per_s"]
    assert r.collisions_per_s > 0
    assert np.all(sp["total_per_s"] >= 0)
    assert r.length_scale == pytest.approx(3.0)
    assert r.omega_rad_s == pytest.approx(0.7 * critical_speed_rad_s(0.5, 0.04))


def test_drum_input_validation():
    with pytest.raises(DemInputError, match="speed_frac_critical"):
        drum_test(-0.1, 0.35)
    with pytest.raises(DemInputError, match="section_length_m"):
        drum_test(0.7, 0.35, section_length_m=0.01)


def test_shell_and_lifter_contacts_push_inwards_and_load_the_drum():
    from dem.materials import Material
    from dem.system import DrumGeometry, System

    mat = Material(youngs_modulus_Pa=1e9, friction_coef=0.3, restitution=0.7)
    r = 0.01
    # ball 0 presses on the shell at the bottom; ball 1 touches the side of lifter 0 (angle 0)
    drum = DrumGeometry(0.25, 1.0, n_lifters=1, lifter_height_m=0.02, lifter_width_m=0.01)
    pos = [[0.0, -(0.25 - r + 1e-4), 0.05], [0.235, 0.005 + r - 1e-4, 0.05]]
    s = System(pos, [r, r], mat, drum=drum, periodic_z_m=0.1)
    f_shell = 4 / 3 * s.cp[0 + 4] * math.sqrt(r) * (1e-4) ** 1.5
    assert s.force[0, 1] == pytest.approx(f_shell, rel=1e-9)  # along +y, towards the axis
    assert s.force[1, 1] > 0 and abs(s.force[1, 0]) < 1e-2 * s.force[1, 1]  # only tangential damping
    # the lifter force on the drum (-y at x = 0.235) turns it clockwise: negative torque
    assert s._forces(0.0)[0] < 0  # (drum torque, bonds broken)
