"""The DEM breakage map's strength index and energy group (twin.calibration.dem_map section 1),
in plain Python: the notes of a calibration (Calibration.extrapolation_notes) read them where
the surrogate answers without numpy."""

from __future__ import annotations

import math

from ..ore.mineralogy import Mineralogy
from ..ore.ores import load_ore

#: The law's reference ore (its strength index is the measured 4.2 kN of MISSION.md section 2).
REFERENCE_ORE = "B"
#: MISSION.md section 2: measured peak fracture force of a -25+19 mm Type B particle.
TARGET_B_N = 4200.0


def target_peak_force_N(ore: Mineralogy, reference: Mineralogy | None = None) -> float:
    """The DEM's calibration target for an ore's -25+19 mm particle: F_X = F_B sqrt((E_X/E_B)
    (H_X/H_B)), the strength index scaled by stiffness and hardness (twin.calibration.dem_link's
    module docstring, section 1)."""
    b = reference or load_ore(REFERENCE_ORE)
    return TARGET_B_N * math.sqrt((ore.youngs_gpa / b.youngs_gpa) * (ore.hardness_index_gpa / b.hardness_index_gpa))


def energy_group(ore: Mineralogy, reference: dict) -> float:
    """Pi = (F/F_B)^2 (E_B/E) (rho_B/rho) of an ore against the law's reference (module s1)."""
    f = target_peak_force_N(ore) / reference["target_peak_force_N"]
    return f * f * (reference["youngs_gpa"] / ore.youngs_gpa) * (reference["density_t_m3"] / ore.density_t_m3)
