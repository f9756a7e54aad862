"""Calibrations: the mineralogy -> breakage maps, the DEM chain that derives breakage parameters
from virtual tests, the fits to MISSION.md's table, and the shipped calibration files.

Command line: ``grindtwin calibrate`` (or ``python -m twin.calibration [--dem]``).
"""

from .breakage_map import AUSTIN_SHAPE, COEFFICIENT_NAMES, mineralogy_breakage
from .dem_link import calibrate_from_dem, dem_breakage, dem_twin_calibration, refit_table
from .files import (CALIBRATION_DIR, DEM_CALIBRATION_PATH, TABLE_CALIBRATION_PATH, shipped_calibration,
                    shipped_dem_calibration, write_json_atomically)
from .fitting import fit_log_ratios
from .reference import KPIS, reference_table
from .table import main

__all__ = ["AUSTIN_SHAPE", "CALIBRATION_DIR", "COEFFICIENT_NAMES", "DEM_CALIBRATION_PATH", "KPIS",
           "TABLE_CALIBRATION_PATH", "calibrate_from_dem", "dem_breakage", "dem_twin_calibration",
           "fit_log_ratios", "main", "mineralogy_breakage", "reference_table", "refit_table", "shipped_calibration",
           "shipped_dem_calibration", "write_json_atomically"]
