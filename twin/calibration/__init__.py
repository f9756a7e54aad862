"""Calibrations: named, first-class objects (twin.calibration.files), the DEM chain that derives
breakage parameters from virtual tests (dem_link: the tests; dem_map: the laws to any ore),
the table step with exact derivatives (parametric, fitting), the bootstrap (uncertainty), the
mineralogy-map calibration (table) and the shipped files (files/dem.json, the default, and
files/table.json).

Command line: ``grindtwin calibrate`` (or ``python -m twin.calibration``).
"""

from .breakage_map import AUSTIN_SHAPE, COEFFICIENT_NAMES, mineralogy_breakage
from .calibrate import DEM_FITTED, DEM_NAMES, dem_record
from .calibrate import run as main
from .dem_map import dem_breakage, law_e50_j_kg
from .files import (BREAKAGE_MAPS, CALIBRATION_DIR, DEFAULT_CALIBRATION, DEM_CALIBRATION_PATH, MEASUREMENT_EFFECTS,
                    TABLE_CALIBRATION_PATH, Calibration, check_writable, load_calibration, shipped_calibration,
                    shipped_dem_calibration, shipped_names, write_json_atomically)
from .fitting import fit_log_ratios, fit_to_table, predict_table, table_errors
from .reference import KPIS, reference_table
from .uncertainty import INTERVAL_LEVEL, intervals, steady_intervals

__all__ = ["AUSTIN_SHAPE", "BREAKAGE_MAPS", "CALIBRATION_DIR", "COEFFICIENT_NAMES", "Calibration",
           "DEFAULT_CALIBRATION", "DEM_CALIBRATION_PATH", "DEM_FITTED", "DEM_NAMES", "INTERVAL_LEVEL", "KPIS",
           "MEASUREMENT_EFFECTS", "TABLE_CALIBRATION_PATH", "check_writable", "dem_breakage", "dem_record",
           "fit_log_ratios", "fit_to_table", "intervals", "law_e50_j_kg", "load_calibration", "main",
           "mineralogy_breakage", "predict_table", "reference_table", "shipped_calibration", "steady_intervals",
           "shipped_dem_calibration", "shipped_names", "table_errors", "write_json_atomically"]
