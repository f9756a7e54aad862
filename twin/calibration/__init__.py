"""Calibrations: named, first-class objects (twin.calibration.files), the DEM chain that derives
breakage parameters from virtual tests (dem_link: the tests; dem_map: the laws to any ore),
the table step with exact derivatives (parametric, fitting), the bootstrap (uncertainty), the
mineralogy-map calibration (table) and the shipped files (files/dem.json, the default, and
files/table.json).

Command line: ``grindtwin calibrate`` (or ``python -m twin.calibration``).
"""

from .._lazy import lazy_face

#: Public name -> the module that defines it, imported on first use (PEP 562).
_API = {
    "AUSTIN_SHAPE": ".breakage_map", "COEFFICIENT_NAMES": ".breakage_map", "mineralogy_breakage": ".breakage_map",
    "DEM_FITTED": ".fitted", "DEM_NAMES": ".fitted", "dem_record": ".calibrate", "main": ".calibrate",
    "dem_breakage": ".dem_map", "law_e50_j_kg": ".dem_map",
    "BREAKAGE_MAPS": ".files", "CALIBRATION_DIR": ".files", "Calibration": ".files", "DEFAULT_CALIBRATION": ".files",
    "DEM_CALIBRATION_PATH": ".files", "FAST_LABEL": ".files", "MEASUREMENT_EFFECTS": ".files",
    "TABLE_CALIBRATION_PATH": ".files",
    "check_writable": ".files", "load_calibration": ".files", "shipped_calibration": ".files",
    "shipped_dem_calibration": ".files", "shipped_names": ".files", "write_json_atomically": ".files",
    "fit_log_ratios": ".fitting", "fit_to_table": ".fitting", "predict_table": ".fitting", "table_errors": ".fitting",
    "KPIS": ".reference", "reference_table": ".reference", "check_model": ".model_code",
    "INTERVAL_LEVEL": ".uncertainty", "intervals": ".uncertainty", "min_replicates": ".uncertainty",
    "steady_intervals": ".uncertainty",
}

__all__ = sorted(_API)
__getattr__, __dir__ = lazy_face(__name__, _API)
