"""A fast PLS surrogate of the twin's steady state (MISSION.md eq. 8) for real-time use and as
a soft sensor; ``python -m twin.surrogate --generate --train`` regenerates it."""

from .._lazy import lazy_face

#: Public name -> the module that defines it, imported on first use (PEP 562).
_API = {
    "DEFAULT_N_MINERALOGIES": ".design", "DEFAULT_POINTS": ".design", "DEFAULT_SEED": ".design",
    "FEED_RANGE_TPH": ".design", "SPEED_RANGE": ".design", "design_conditions": ".design",
    "design_mineralogies": ".design", "generate_training_table": ".design", "load_training_table": ".design",
    "twin_kpis": ".design",
    "CompiledSurrogate": ".compiled",
    "COMPILE_COMMAND": ".files", "COMPILED_PATH": ".files", "FORMAT_VERSION": ".files",
    "GENERATE_COMMAND": ".files", "MODEL_PATH": ".files", "TABLE_PATH": ".files", "TRAIN_COMMAND": ".files",
    "calibration_sha256": ".files", "check_trained_on": ".files", "load": ".files", "save": ".files", "save_compiled": ".files",
    "shipped_compiled": ".files", "shipped_surrogate": ".files",
    "CONDITION_COLUMNS": ".inputs", "as_mineralogy": ".inputs", "blend_mineralogy": ".inputs",
    "feature_frame": ".inputs", "input_columns": ".inputs", "mineral_names": ".inputs",
    "DEFAULT_PARAMS": ".model", "Q_FLOOR": ".model", "Q_LIMIT_FACTOR": ".model", "RANGE_MARGIN": ".model",
    "SCORE_MARGIN": ".compiled", "TARGETS": ".model", "TRACE_WT_PCT": ".model", "Surrogate": ".model",
    "cross_validate": ".model", "held_out_split": ".model", "split_xy": ".model",
    "surrogate_steady": ".predict",
    "main": ".train", "train_and_save": ".train",
}

__all__ = ["COMPILED_PATH", "COMPILE_COMMAND", "CONDITION_COLUMNS", "CompiledSurrogate", "DEFAULT_N_MINERALOGIES", "DEFAULT_PARAMS", "DEFAULT_POINTS", "DEFAULT_SEED",
           "FEED_RANGE_TPH", "FORMAT_VERSION", "GENERATE_COMMAND", "MODEL_PATH", "Q_FLOOR", "Q_LIMIT_FACTOR",
           "RANGE_MARGIN", "SCORE_MARGIN", "SPEED_RANGE", "Surrogate", "TABLE_PATH", "TARGETS", "TRACE_WT_PCT",
           "TRAIN_COMMAND", "as_mineralogy", "blend_mineralogy", "calibration_sha256", "check_trained_on", "cross_validate",
           "design_conditions", "design_mineralogies", "feature_frame", "generate_training_table", "held_out_split",
           "input_columns", "load", "load_training_table", "main", "mineral_names", "save", "save_compiled", "shipped_compiled",
           "shipped_surrogate",
           "split_xy", "surrogate_steady", "train_and_save"]
__getattr__, __dir__ = lazy_face(__name__, _API)
