"""grindtwin's mill twin: size grid, breakage, the mill, effects, the CasADi mill model and the
``Twin`` facade; subpackages ``twin.ore`` (characterisation), ``twin.solve`` (steady states and
runs), ``twin.calibration`` (breakage maps, DEM chain, table fits, calibration files) and
``twin.surrogate`` (the PLS soft sensor, imported on its own: it needs scikit-learn)."""

from ._lazy import lazy_face

#: Public name -> the module that defines it, imported on first use (PEP 562).
_API = {
    "BreakageParams": ".breakage", "OreBreakage": ".breakage", "austin_selection": ".breakage",
    "ore_breakage": ".breakage", "CRITICAL_SIZE_MIN_UM": ".breakage", "SPEED_FACTOR_ZERO_FRAC_CRITICAL": ".mill", "FEED_TPH_MAX": ".mill",
    "BALL_SIZE_MIN_MM": ".mill", "BALL_SIZE_MAX_MM": ".mill", "exponent_order_problem": ".breakage",
    "EFFECTS": ".effects", "Effect": ".effects", "known_effects": ".effects",
    "FastCalibrationWarning": ".errors", "ModelError": ".errors", "OverloadError": ".errors", "SolverError": ".errors",
    "TwinError": ".errors",
    "TwinInputError": ".errors",
    "MILLS": ".mill", "Mill": ".mill", "read_preset": ".mill", "is_preset_file": ".mill", "bond_power_kw": ".mill", "get_mill": ".mill",
    "hogg_fuerstenau_power_kw": ".mill", "load_status": ".mill", "centrifuging_note": ".mill",
    "CENTRIFUGING_FRAC_CRITICAL": ".mill", "POWER_MODELS": ".mill", "power_kw": ".mill",
    "Hydrocyclone": ".effects.classification", "hydrocyclone_from": ".effects.classification",
    "CycloneSurvey": ".effects.classification", "calibrate_plitt": ".effects.classification",
    "circuit_cyclone": ".effects.classification", "plitt_factors": ".effects.classification",
    "plitt_factors_text": ".effects.classification",
    "load_design_cyclone": ".sizing",
    "TabulatedPSD": ".sizes", "SizedMill": ".sizing", "size_mill": ".sizing", "write_preset": ".sizing", "check_preset_path": ".sizing",
    "INPUT_NAMES": ".model", "Model": ".model", "ModelSpec": ".model",
    "Blend": ".ore", "Mineralogy": ".ore", "Texture": ".ore", "load_ore": ".ore", "reference_ores": ".ore",
    "GatesGaudinSchuhmann": ".sizes", "RosinRammler": ".sizes", "SizeGrid": ".sizes", "discretise": ".sizes",
    "pxx_um": ".sizes",
    "SteadyState": ".solve", "Trajectory": ".solve", "sample_count": ".solve", "mass_balance_error": ".solve",
    "DEFAULT_EFFECTS": ".twin", "MIXER_SHARES_SUM_TOL": ".twin", "mixer_shares_sum_ok": ".twin",
    "Twin": ".twin",
    "file_sha256": ".atomic", "is_grindtwin_checkout": ".atomic", "new_folder_beside": ".atomic", "write_text_atomically": ".atomic",
    "LockError": ".atomic", "acquire_lock": ".atomic", "release_lock": ".atomic", "remove_by_name": ".atomic",
    "replace_folder": ".atomic", "temporaries_of": ".atomic", "write_atomically": ".atomic",
    "write_beside": ".atomic", "csv_text": ".atomic", "read_once": ".atomic",
    "JSON_INF": ".atomic", "json_safe": ".atomic", "json_text": ".atomic",
    "check_size_mill_input": ".sizing",
    "trajectory_notes": ".validity",
    "nominal_pressure_note": ".validity",
    "nominal_pressure_kpa": ".validity",
    "blend_density_t_m3": ".validity", "shell_capacity_t": ".validity",
    "SPECIFIC_ENERGY_RANGE_KWH_T": ".validity",
}

__all__ = [
    "BALL_SIZE_MAX_MM", "BALL_SIZE_MIN_MM",
    "Blend", "BreakageParams", "CENTRIFUGING_FRAC_CRITICAL", "DEFAULT_EFFECTS", "EFFECTS", "FEED_TPH_MAX", "Effect", "FastCalibrationWarning", "GatesGaudinSchuhmann",
    "INPUT_NAMES", "MILLS", "MIXER_SHARES_SUM_TOL", "mixer_shares_sum_ok",
    "Hydrocyclone", "Mill", "Mineralogy", "Model", "ModelError", "ModelSpec", "OreBreakage", "POWER_MODELS", "RosinRammler",
    "SPEED_FACTOR_ZERO_FRAC_CRITICAL", "SizeGrid", "SizedMill", "OverloadError", "SolverError", "SteadyState", "TabulatedPSD",
    "Texture", "Trajectory", "Twin", "TwinError",
    "TwinInputError", "CRITICAL_SIZE_MIN_UM", "austin_selection", "bond_power_kw", "centrifuging_note", "hydrocyclone_from", "power_kw", "read_preset", "is_preset_file", "size_mill", "write_preset", "check_preset_path",
    "CycloneSurvey", "calibrate_plitt", "circuit_cyclone", "plitt_factors", "plitt_factors_text", "load_design_cyclone",
    "discretise", "get_mill", "hogg_fuerstenau_power_kw", "known_effects", "load_ore", "load_status", "ore_breakage",
    "file_sha256", "is_grindtwin_checkout", "new_folder_beside", "pxx_um", "reference_ores", "nominal_pressure_note", "trajectory_notes", "write_text_atomically",
    "LockError", "acquire_lock", "release_lock", "remove_by_name", "replace_folder", "temporaries_of",
    "write_atomically", "write_beside", "check_size_mill_input", "sample_count", "nominal_pressure_kpa",
    "mass_balance_error", "csv_text", "read_once", "JSON_INF", "json_safe", "json_text",
    "blend_density_t_m3", "shell_capacity_t", "SPECIFIC_ENERGY_RANGE_KWH_T", "exponent_order_problem",
]
__getattr__, __dir__ = lazy_face(__name__, _API)
