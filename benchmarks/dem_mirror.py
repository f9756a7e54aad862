"""The Yade-JCFpm mirror physics of the comparisons with Yade (benchmarks/dem_parallel.py): the
bonds (``BondParams.yade_jcfpm``: E 30 GPa, Poisson 0.4, tensile 10 MPa, cohesion 20 MPa, friction
30 deg), the rock and platen materials, and the compression test's settings. One place for the
worker that times grindtwin and for the time step both sides run at (dem_common.write_pack)."""

from __future__ import annotations

import math

from dem.bonds import BondParams
from dem.materials import Material

BONDS = BondParams.yade_jcfpm(30e9, 0.4, 10e6, 20e6, 30.0)
ROCK = Material(youngs_modulus_Pa=30e9, poisson_ratio=0.4, density_kg_m3=2700.0,
                friction_coef=math.tan(math.radians(30)), restitution=1.0)
PLATEN = Material(youngs_modulus_Pa=210e9, poisson_ratio=0.3, density_kg_m3=7800.0,
                  friction_coef=math.tan(math.radians(30)), restitution=1.0)
MIRROR = dict(material=ROCK, platen_material=PLATEN, contact_law="linear_yade",
              damping_velocity="at_force", local_damping=0.7, platen_speed_m_s=0.1)
