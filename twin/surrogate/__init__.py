"""A fast PLS surrogate of the twin's steady state (MISSION.md eq. 8) for real-time use and as
a soft sensor; ``python -m twin.surrogate --generate --train`` regenerates it."""

from .design import (DEFAULT_N_MINERALOGIES, DEFAULT_POINTS, DEFAULT_SEED, FEED_RANGE_TPH, SPEED_RANGE,
                     design_conditions, design_mineralogies, generate_training_table, load_training_table,
                     twin_kpis)
from .compiled import CompiledSurrogate
from .files import (COMPILE_COMMAND, COMPILED_PATH, FORMAT_VERSION, GENERATE_COMMAND, MODEL_PATH, TABLE_PATH,
                    TRAIN_COMMAND, calibration_sha256, load, save, save_compiled, shipped_compiled, shipped_surrogate)
from .inputs import CONDITION_COLUMNS, as_mineralogy, blend_mineralogy, feature_frame, input_columns, mineral_names
from .model import (DEFAULT_PARAMS, Q_FLOOR, Q_LIMIT_FACTOR, RANGE_MARGIN, SCORE_MARGIN, TARGETS, TRACE_WT_PCT,
                    Surrogate, cross_validate, held_out_split, split_xy)
from .predict import surrogate_steady
from .train import main, train_and_save

__all__ = ["COMPILED_PATH", "COMPILE_COMMAND", "CONDITION_COLUMNS", "CompiledSurrogate", "DEFAULT_N_MINERALOGIES", "DEFAULT_PARAMS", "DEFAULT_POINTS", "DEFAULT_SEED",
           "FEED_RANGE_TPH", "FORMAT_VERSION", "GENERATE_COMMAND", "MODEL_PATH", "Q_FLOOR", "Q_LIMIT_FACTOR",
           "RANGE_MARGIN", "SCORE_MARGIN", "SPEED_RANGE", "Surrogate", "TABLE_PATH", "TARGETS", "TRACE_WT_PCT",
           "TRAIN_COMMAND", "as_mineralogy", "blend_mineralogy", "calibration_sha256", "cross_validate",
           "design_conditions", "design_mineralogies", "feature_frame", "generate_training_table", "held_out_split",
           "input_columns", "load", "load_training_table", "main", "mineral_names", "save", "save_compiled", "shipped_compiled",
           "shipped_surrogate",
           "split_xy", "surrogate_steady", "train_and_save"]
