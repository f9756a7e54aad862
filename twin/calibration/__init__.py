"""Calibrations: the mineralogy -> breakage maps, the DEM chain that derives breakage parameters
from virtual tests, the fits to MISSION.md's table, and the shipped calibration files.

Command line: ``grindtwin calibrate`` (or ``python -m twin.calibration [--dem]``).
"""

from .._lazy import lazy_face

#: Public name -> the module that defines it, imported on first use (PEP 562).
_API = {
    "AUSTIN_SHAPE": ".breakage_map", "COEFFICIENT_NAMES": ".breakage_map",
    "mineralogy_breakage": ".breakage_map",
    "calibrate_from_dem": ".dem_link", "dem_breakage": ".dem_link", "dem_twin_calibration": ".dem_link",
    "refit_table": ".dem_link",
    "CALIBRATION_DIR": ".files", "DEM_CALIBRATION_PATH": ".files", "TABLE_CALIBRATION_PATH": ".files",
    "shipped_calibration": ".files", "shipped_dem_calibration": ".files", "write_json_atomically": ".files",
    "fit_log_ratios": ".fitting",
    "KPIS": ".reference", "reference_table": ".reference",
    "main": ".table",
}

__all__ = ["AUSTIN_SHAPE", "CALIBRATION_DIR", "COEFFICIENT_NAMES", "DEM_CALIBRATION_PATH", "KPIS",
           "TABLE_CALIBRATION_PATH", "calibrate_from_dem", "dem_breakage", "dem_twin_calibration",
           "fit_log_ratios", "main", "mineralogy_breakage", "reference_table", "refit_table", "shipped_calibration",
           "shipped_dem_calibration", "write_json_atomically"]
__getattr__, __dir__ = lazy_face(__name__, _API)
