"""Mill-charge DEM: steel balls in a rotating drum with lifters (3D periodic slice, SI units).

Geometry: a **3D short periodic section** of the mill: the drum axis is z, the section is
``section_length_m`` long and periodic along z (no end walls); results are scaled to the full
mill length by ``mill_length_m / section_length_m``. The shell is a cylinder of diameter
``mill_diameter_m`` rotating counter-clockwise at ``speed_frac_critical`` of the critical
speed ``omega_c = sqrt(2 g / (D - d_ball))`` (the speed at which a ball on the shell
centrifuges; e.g. Napier-Munn et al. 1996, ch. 11), with ``n_lifters`` radial bars
(:func:`dem.contacts.drum_walls`). Gravity is -y.

Ball filling J is the fraction of the mill volume taken by the ball *bed* including its voids
(bed porosity 0.4, the usual convention of the Bond/Austin power and charge formulas), so
``n_balls = J (pi D^2/4) L_section (1 - 0.4) / (pi d^3/6)``.

Outputs after ``settle_revolutions``, over ``measure_revolutions``:

- **power draw** ``P = -T omega`` (W), T the torque the balls exert on the drum (shell and
  lifters), scaled to the full length;
- **collision-energy spectra**: the number of collisions per second (whole mill) in
  logarithmic classes of impact energy ``E = m* v_n^2 / 2`` (normal relative speed at first
  contact), separately ball–ball and ball–wall.

Ball stiffness: the default ball Young's modulus is reduced to 1 GPa (steel: 210 GPa), the
common practice in mill DEM to afford the time step (Mishra & Rajamani 1992 used soft
springs; power draw is insensitive to contact stiffness over orders of magnitude, collision
energies change little). ``bench`` measures this.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import pandas as pd
import scipy.constants

from dem.errors import DemInputError
from dem.materials import RAYLEIGH_SAFETY_FACTOR, Material, check_float
from dem.system import HIST_DLOG10, HIST_LO_LOG10, HIST_NBINS, DrumGeometry, System

#: standard gravity (scipy.constants.g, 9.80665 m/s^2: the one value of g in the project)
G_M_S2 = scipy.constants.g
BED_POROSITY = 0.4
#: most time steps :func:`drum_test` starts (``max_steps``): a budget, not physics, hours of one
#: core for the lab drum's charge. The runs the project makes (the calibration's 2 revolutions, the
#: drum benchmark's 4, at 0.5-0.9 of critical) take some hundred times fewer; a speed fraction typed
#: 100x too small (0.007 for 0.7) takes 100x the steps per revolution. Raise it to mean it.
DRUM_MAX_STEPS = 10**7
#: highest speed fraction of critical a drum takes (twice critical: well into centrifuging)
SPEED_MAX = 2.0

#: default ball material: steel with a reduced Young's modulus (see the module docstring)
SOFT_STEEL_BALL = Material(youngs_modulus_Pa=1e9, poisson_ratio=0.3, density_kg_m3=7800.0,
                           friction_coef=0.3, restitution=0.7)


#: The widest drum [m]: the largest ball mills are ~8.5 m across; a diameter in mm (500) lands above.
MILL_DIAMETER_MAX_M = 20.0


def critical_speed_rad_s(mill_diameter_m: float, ball_diameter_m: float) -> float:
    """Critical speed ``sqrt(2 g / (D - d))`` in rad/s."""
    check_float("critical_speed_rad_s", "mill_diameter_m", mill_diameter_m, 0.0, MILL_DIAMETER_MAX_M, lo_open=True)
    check_float("critical_speed_rad_s", "ball_diameter_m", ball_diameter_m, 0.0, math.inf, lo_open=True)
    if not (0 < ball_diameter_m < mill_diameter_m):
        raise DemInputError(
            f"The 'ball_diameter_m' parameter must be a float in (0, mill_diameter_m={mill_diameter_m}). "
            f"Got {ball_diameter_m!r}.")
    return math.sqrt(2.0 * G_M_S2 / (mill_diameter_m - ball_diameter_m))


@dataclass(frozen=True)
class DrumResult:
    """Result of :func:`drum_test`.

    power_W : mean power draw of the full-length mill; power_per_rev_W : per measured
    revolution (its spread shows the statistical error); torque_Nm : mean torque of the full
    mill; spectrum : DataFrame ``energy_lo_J, energy_hi_J, energy_mid_J, ball_ball_per_s,
    ball_wall_per_s, total_per_s`` (whole mill); collisions_per_s : total; speed_frac_critical,
    omega_rad_s, critical_speed_rad_s, ball_filling, n_balls (simulated), n_balls_full_mill,
    section_length_m, length_scale (full/section), geometry (text), dt_s, n_steps,
    simulated_time_s, wall_time_s.
    """

    power_W: float
    power_per_rev_W: np.ndarray
    torque_Nm: float
    collisions_per_s: float
    speed_frac_critical: float
    omega_rad_s: float
    critical_speed_rad_s: float
    ball_filling: float
    n_balls: int
    n_balls_full_mill: float
    section_length_m: float
    length_scale: float
    geometry: str
    dt_s: float
    n_steps: int
    simulated_time_s: float
    wall_time_s: float
    spectrum: pd.DataFrame = field(repr=False)

    def summary(self) -> dict:
        per_rev = self.power_per_rev_W
        return {"speed_frac_critical": self.speed_frac_critical, "ball_filling": self.ball_filling,
                "power_W": self.power_W,
                "power_rev_std_W": float(np.std(per_rev, ddof=1)) if per_rev.size > 1 else float("nan"),
                "torque_Nm": self.torque_Nm, "collisions_per_s": self.collisions_per_s,
                "n_balls": self.n_balls, "length_scale": self.length_scale, "dt_s": self.dt_s,
                "n_steps": self.n_steps, "wall_time_s": self.wall_time_s}


def _place_balls(n, r, drum_r, clear_r, lz, rng):
    s = 2.0 * r * 1.02
    nzl = max(1, int(lz / s))
    xs = np.arange(-drum_r, drum_r + s, s)
    gx, gy = np.meshgrid(xs, xs)
    gx = gx.ravel()
    gy = gy.ravel()
    ok = np.hypot(gx, gy) <= clear_r - r
    gx, gy = gx[ok], gy[ok]
    pts = []
    for k in range(nzl):
        zc = (k + 0.5) * lz / nzl
        pts.append(np.column_stack([gx + (0.5 * s if k % 2 else 0.0), gy, np.full(gx.shape, zc)]))
    p = np.vstack(pts)
    p = p[np.hypot(p[:, 0], p[:, 1]) <= clear_r - r]
    if p.shape[0] < n:
        raise DemInputError(
            f"The 'ball_filling' parameter of drum_test is too high to place {n} balls on a lattice "
            f"(room for {p.shape[0]}). Lower ball_filling or the ball size.")
    order = np.lexsort((rng.uniform(size=p.shape[0]), p[:, 1]))
    return p[order[:n]]


class DrumSetup(NamedTuple):
    """What :func:`drum_system` builds."""

    system: System
    omega_rad_s: float
    critical_speed_rad_s: float
    steps_per_rev: int
    n_balls_full_mill: float
    section_length_m: float
    length_scale: float
    """Full mill length / simulated slice length (scales torque, power and collision rates)."""


def drum_system(speed_frac_critical: float = 0.7, ball_filling: float = 0.35, *,
                mill_diameter_m: float = 0.5, mill_length_m: float = 0.3,
                ball_diameter_m: float = 0.025, section_length_m: float = 0.1,
                n_lifters: int = 8, lifter_height_m: float = 0.01, lifter_width_m: float = 0.012,
                ball_material: Material = SOFT_STEEL_BALL, shell_material: Material | None = None,
                time_step_factor: float = RAYLEIGH_SAFETY_FACTOR, random_state: int = 0,
                owner: str = "drum_system"):
    """The ball charge of :func:`drum_test` at rest, checked and placed (seeded), as a
    :class:`DrumSetup`. Exposed so studies of the run (e.g. the accuracy benchmark's
    snapshots) start from exactly the same set-up."""
    checks = [("speed_frac_critical", speed_frac_critical, 0.0, SPEED_MAX),
              ("ball_filling", ball_filling, 0.0, 0.6), ("mill_diameter_m", mill_diameter_m, 0.0, MILL_DIAMETER_MAX_M),
              ("mill_length_m", mill_length_m, 0.0, 50.0), ("ball_diameter_m", ball_diameter_m, 0.0, 0.2)]
    for name, val, lo, hi in checks:
        check_float(owner, name, val, lo, hi, lo_open=True)
    critical_speed_rad_s(mill_diameter_m, ball_diameter_m)  # a mill no wider than its ball: named as such
    for name, val in (("lifter_height_m", lifter_height_m), ("lifter_width_m", lifter_width_m)):
        check_float(owner, name, val, -1e-12 if name == "lifter_height_m" else 0.0, 0.25 * mill_diameter_m,
                    lo_open=True)
    if not (2.5 * ball_diameter_m <= section_length_m <= mill_length_m):
        raise DemInputError(
            f"The 'section_length_m' parameter of {owner} must be a float in "
            f"[{2.5 * ball_diameter_m:.4g}, {mill_length_m}] (at least 2.5 ball diameters, at most the mill). "
            f"Got {section_length_m!r}.")
    if not (isinstance(random_state, (int, np.integer)) and not isinstance(random_state, bool)
            and random_state >= 0):
        raise DemInputError(f"The 'random_state' parameter of {owner} must be an int >= 0. Got {random_state!r}.")
    if not (isinstance(n_lifters, (int, np.integer)) and not isinstance(n_lifters, bool) and 0 <= n_lifters <= 64):
        raise DemInputError(f"The 'n_lifters' parameter of {owner} must be an int in [0, 64]. Got {n_lifters!r}.")
    rng = np.random.default_rng(random_state)
    r = 0.5 * ball_diameter_m
    drum_r = 0.5 * mill_diameter_m
    w_c = critical_speed_rad_s(mill_diameter_m, ball_diameter_m)
    omega = speed_frac_critical * w_c
    v_ball = math.pi * ball_diameter_m**3 / 6.0
    n_full = ball_filling * math.pi * drum_r**2 * mill_length_m * (1 - BED_POROSITY) / v_ball
    n = max(1, int(round(n_full * section_length_m / mill_length_m)))
    pos = _place_balls(n, r, drum_r, drum_r - (lifter_height_m + lifter_width_m if n_lifters else 0.0),
                       section_length_m, rng)
    drum = DrumGeometry(drum_r, omega, int(n_lifters), float(lifter_height_m), float(lifter_width_m))
    sys_ = System(pos, np.full(n, r), ball_material, wall_material=shell_material or ball_material,
                  drum=drum, gravity_m_s2=(0.0, -G_M_S2, 0.0), periodic_z_m=section_length_m,
                  time_step_factor=time_step_factor)
    sys_.vel[:] = rng.normal(0.0, 1e-3, sys_.vel.shape)
    return DrumSetup(sys_, omega, w_c, int(math.ceil(2.0 * math.pi / omega / sys_.dt_s)), n_full,
                     float(section_length_m), mill_length_m / section_length_m)


def drum_test(speed_frac_critical: float = 0.7, ball_filling: float = 0.35, *,
              settle_revolutions: float = 1.0, measure_revolutions: float = 2.0,
              max_steps: int = DRUM_MAX_STEPS, **setup) -> DrumResult:
    """Simulate the ball charge of a drum mill; see the module docstring. ``setup``: the
    keywords of :func:`drum_system` (mill and ball sizes, slice length, lifters, materials,
    time-step factor, seed) with its defaults. A run of more than ``max_steps`` time steps is
    refused before its first step (see :data:`DRUM_MAX_STEPS`)."""
    if not (isinstance(max_steps, (int, np.integer)) and not isinstance(max_steps, bool) and max_steps >= 1):
        raise DemInputError(
            f"The 'max_steps' parameter of drum_test must be an int >= 1. Got {max_steps!r}.")
    for name, val, lo, hi in (("settle_revolutions", settle_revolutions, -1e-12, 100.0),
                              ("measure_revolutions", measure_revolutions, 0.0, 1000.0)):
        check_float("drum_test", name, val, lo, hi, lo_open=True)
    t0 = time.perf_counter()
    st = drum_system(speed_frac_critical, ball_filling, owner="drum_test", **setup)
    sys_, omega, steps_rev, scale = st.system, st.omega_rad_s, st.steps_per_rev, st.length_scale
    n_settle = int(round(settle_revolutions * steps_rev))
    n_meas = max(1, int(round(measure_revolutions * steps_rev)))
    if n_settle + n_meas > max_steps:
        slowest = speed_frac_critical * (n_settle + n_meas) / max_steps
        raise DemInputError(
            f"drum_test would run {n_settle + n_meas:.3g} time steps of {sys_.dt_s:.3g} s ({settle_revolutions!r} + "
            f"{measure_revolutions!r} revolutions at speed_frac_critical {speed_frac_critical!r}), more than "
            f"max_steps = {max_steps:.3g}. Allowed: "
            + (f"speed_frac_critical at least {slowest:.3g} at these revolutions, " if slowest <= SPEED_MAX else "")
            + "fewer revolutions, or a larger max_steps to mean it.")
    chunk = max(1, steps_rev // 8)
    done = 0
    while done < n_settle:
        k = min(chunk, n_settle - done)
        sys_.run(k)
        done += k
    sys_.hist_pp[:] = 0.0
    sys_.hist_pw[:] = 0.0
    start = len(sys_.records.torque_Nm)
    done = 0
    while done < n_meas:
        k = min(chunk, n_meas - done)
        sys_.run(k)
        done += k
    tq = np.concatenate(sys_.records.torque_Nm[start:])
    t_meas = n_meas * sys_.dt_s
    power = -tq * omega * scale
    nrev = max(1, int(n_meas // steps_rev))
    per_rev = np.array([np.mean(power[k * steps_rev:(k + 1) * steps_rev]) for k in range(nrev)])
    edges = 10.0 ** (HIST_LO_LOG10 + HIST_DLOG10 * np.arange(HIST_NBINS + 1))
    bb = sys_.hist_pp * scale / t_meas
    bw = sys_.hist_pw * scale / t_meas
    spec = pd.DataFrame({"energy_lo_J": edges[:-1], "energy_hi_J": edges[1:],
                         "energy_mid_J": np.sqrt(edges[:-1] * edges[1:]), "ball_ball_per_s": bb,
                         "ball_wall_per_s": bw, "total_per_s": bb + bw})
    return DrumResult(power_W=float(np.mean(power)), power_per_rev_W=per_rev,
                      torque_Nm=float(np.mean(tq) * scale), collisions_per_s=float(np.sum(bb + bw)),
                      speed_frac_critical=float(speed_frac_critical), omega_rad_s=omega,
                      critical_speed_rad_s=st.critical_speed_rad_s,
                      ball_filling=float(ball_filling), n_balls=sys_.pos.shape[0],
                      n_balls_full_mill=st.n_balls_full_mill,
                      section_length_m=st.section_length_m,
                      length_scale=scale, geometry="3D periodic slice along the mill axis",
                      dt_s=sys_.dt_s, n_steps=sys_.steps, simulated_time_s=sys_.time_s,
                      wall_time_s=time.perf_counter() - t0, spectrum=spec)
