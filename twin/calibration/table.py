"""The ``table`` calibration: the mineralogy map (twin.calibration.breakage_map) fitted to
MISSION.md's table, with no DEM. Kept beside the DEM chain as the comparison a plain
regression on the table gives: its 11 numbers are fitted to the table's 12.

Fitted: S^E_ref, the hardness, texture and size-exponent texture exponents of the map (no
virtual tests in this map, so nothing derives them), the cushioning rate coefficient, the
clay-crowding and power coefficients of the slurry rheology, and the lab mill's power factor, grate cut
size and sharpness and discharge factor (their reasons are those of the DEM chain,
twin.calibration.fitted.DEM_FITTED).
"""

from __future__ import annotations

import time

from ..effects.rheology import CLAY_CROWDING_MAX
from .breakage_map import COEFFICIENT_NAMES
from .files import Calibration, base_record, provenance
from .fitted import DEM_FITTED
from .fitting import fit_to_table, predict_table, table_errors

#: Start of the fit (only a starting point) and bounds. Signs are physical: harder minerals and
#: finer textures never speed breakage up, cushioning never adds energy.
START = {"se_ref_t_kwh": 0.55, "hardness_exponent": 0.05, "texture_exponent": 0.01, "alpha_texture_exponent": 0.2,
         "cushioning_rate_coeff": 0.01, "slurry_power_coeff": 0.003, "clay_crowding_coeff": 0.9,
         "lab_power_factor": 1.3, "lab_grate_d50_um": 25.0, "lab_grate_sharpness": 1.2,
         "lab_discharge_factor": 2.4}
BOUNDS = {"se_ref_t_kwh": (0.05, 20.0), "hardness_exponent": (0.0, 5.0), "texture_exponent": (0.0, 5.0),
          "alpha_texture_exponent": (-1.0, 2.0),
          "cushioning_rate_coeff": (0.0, 20.0), "slurry_power_coeff": (0.0, 20.0),
          "clay_crowding_coeff": (0.0, CLAY_CROWDING_MAX),
          "lab_power_factor": (0.3, 3.0), "lab_grate_d50_um": (10.0, 3000.0), "lab_grate_sharpness": (0.5, 10.0),
          "lab_discharge_factor": (0.5, 50.0)}
NAMES = tuple(START)
WHY_MAP = "a coefficient of the mineralogy map; this calibration runs no virtual tests that could derive it"


def calibrate_mineralogy_map(name: str = "table", max_iter: int = 200, command: str = "grindtwin calibrate --map mineralogy") -> dict:
    """The ``table`` calibration's record: the mineralogy map fitted to the table."""

    t0 = time.perf_counter()
    record = base_record(name, "mineralogy", "Mineralogy map (hardness and texture indices) fitted to MISSION.md's "
                         "table; no DEM.")
    record["coefficients"] = {k: START[k] for k in COEFFICIENT_NAMES}
    record["mills"] = {"lab": {k[len("lab_"):]: v for k, v in START.items() if k.startswith("lab_")}}
    fitted, fit = fit_to_table(Calibration(record), NAMES, BOUNDS, max_iter=max_iter)
    record["coefficients"], record["mills"] = fitted.coefficients, fitted.record["mills"]
    predicted = predict_table(fitted)
    errors = table_errors(predicted)
    fit.update({"predicted": predicted, "error_pct": errors,
                "max_abs_error_pct": max(abs(e) for row in errors.values() for e in row.values())})
    record["fitted"] = {n: {"value": fit["values"][n], "bounds": list(BOUNDS[n]),
                            "why_not_derivable": DEM_FITTED.get(n, {}).get("why", WHY_MAP)} for n in NAMES}
    record["fit"] = fit
    record["provenance"] = provenance(command, seconds=time.perf_counter() - t0)
    return record
