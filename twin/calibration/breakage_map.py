"""The mineralogy map of the ``table`` calibration (the default ``dem`` calibration maps by the
DEM laws of twin.calibration.dem_map instead): the energy-specific selection at 1 mm follows
the ore's mineralogical hardness and texture,

    S^E_1 = S^E_ref (H_ref / H_min)^a_H * TI^-a_T       [t/kWh]

(harder minerals absorb more energy per fracture: Bond's law and the Vickers-hardness
correlation of grindability, e.g. Ozkahraman 2005, Int. J. Rock Mech. 42, 1022; finer,
intergrown textures resist breakage: Brace 1961). The size exponent of S steepens with the
textural index, alpha = alpha_0 TI^a_alpha: friable, fine-grained ores have flaws at the
scale of a lump, so coarse lumps break easily while liberated fine grains stay strong (the
size effect on fracture energy of Tavares & King 1998, Int. J. Miner. Process. 54, 1-28).
The rest of the shape of S and the breakage function B take the typical values Austin,
Klimpel & Luckie (1984, ch. 4) report for ores ground with ~25 mm balls. S^E_ref, a_H, a_T
and a_alpha are not typed in: ``grindtwin calibrate --map mineralogy`` fits them
(twin.calibration.table; shipped as ``twin/calibration/files/table.json``).
"""

from __future__ import annotations

from ..breakage import BreakageParams
from ..ore.mineralogy import Mineralogy

#: Reference hardness index [GPa] that makes S^E_ref the rate of a Type-B-like ore.
HARDNESS_REFERENCE_GPA = 8.0
#: Austin shape parameters, typical of ores ground by ~25 mm balls (Austin et al. 1984, ch. 4).
AUSTIN_SHAPE = {"alpha": 1.0, "mu_um": 3000.0, "Lambda": 2.5, "gamma": 1.0, "beta": 4.0, "phi": 0.5}

COEFFICIENT_NAMES = ("se_ref_t_kwh", "hardness_exponent", "texture_exponent", "alpha_texture_exponent",
                     "cushioning_rate_coeff", "slurry_power_coeff", "clay_crowding_coeff")


def mineralogy_breakage(ore: Mineralogy, coefficients: dict) -> BreakageParams:
    """Breakage parameters of one ore from its mineralogy (documented mapping above)."""
    se = (coefficients["se_ref_t_kwh"]
          * (HARDNESS_REFERENCE_GPA / ore.hardness_index_gpa) ** coefficients["hardness_exponent"]
          * ore.textural_index ** (-coefficients["texture_exponent"]))
    shape = dict(AUSTIN_SHAPE)
    shape["alpha"] = AUSTIN_SHAPE["alpha"] * ore.textural_index ** coefficients["alpha_texture_exponent"]
    return BreakageParams(se_1mm_t_kwh=se, source="mineralogy map (twin.calibration.breakage_map)", **shape)
