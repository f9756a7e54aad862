"""Model predictive control, estimation and baselines on the grindtwin mill model: the NMPC
(:class:`Controller`), the EKF (:class:`Ekf`), PI and no-control baselines, linear analysis, the
steady-state optimiser, sensors, plants (:mod:`mpc.plants`) and the closed loop."""

from mpc.baselines import FixedInputs, PiFeedback, pi_baseline
from mpc.closed_loop import CLOSED_LOOP_READS, ESTIMATOR_MEASUREMENTS, ClosedLoopResult, LoopSettings, run_closed_loop
from mpc.discretize import (RK4_RATE_SAFETY, cvodes_map, min_rk4_substeps, rk4_map, rk4_sensitivity_map,
                             stable_rk4_substeps, state_jacobian)
from mpc.errors import MpcError, MpcInputError, MpcSolverError, OutsideModelsWarning
from mpc.codegen import CompileFallbackWarning, CompileReport, compiled
from mpc.estimator import DISTURBANCE_MODELS, MEASUREMENTS, ChangeDetector, Ekf
from mpc.estimator import RK4_SUBSTEPS as EKF_RK4_SUBSTEPS
from mpc.export import ExportDifference, check_export, check_out_dir, export_controller, export_lock, recorded_export
from mpc.kpis import (P80_BAND_UM, cumulative, fresh_feed_t, held_cumulative, held_integral, integral, loop_kpis,
                      outside_band_frac, p80_iae_um_h, specific_energy_kwh_t, within_band_frac)
from mpc.linear import (Fopdt, LinearMPC, OperatingPoint, StepMoments, discretize, fit_fopdt, fopdt_from_model,
                        gain_table, linearize, steady_target, step_moments, step_test)
from mpc.nmpc import QP_SOLVERS, SOLVERS, Controller, NmpcSettings, speed_max_note
from mpc.optimize import (FEED_RANGE_NOMINAL, Setpoints, default_feed_bounds, feed_for_target,
                          feed_holding_every_blend, optimal_setpoints,
                          speed_for_target)
from mpc.pi import DiscretePI, pi_from_model, simc_pi
from mpc.plants import LeRouxCircuit, LeRouxParameters, LeRouxPlant, MatchedTwin, TwinPlant, matched_twin
from mpc.results import ControllerStepResult
from mpc.sensors import Sensors, SensorState

__all__ = [
    "EKF_RK4_SUBSTEPS",
    "CLOSED_LOOP_READS", "OutsideModelsWarning", "speed_max_note",
    "ChangeDetector",
    "ClosedLoopResult", "CompileFallbackWarning", "CompileReport", "DISTURBANCE_MODELS", "Controller", "ControllerStepResult", "DiscretePI", "ESTIMATOR_MEASUREMENTS", "Ekf",
    "FixedInputs", "Fopdt", "LeRouxCircuit", "LeRouxParameters", "LeRouxPlant", "LinearMPC", "LoopSettings",
    "MEASUREMENTS", "MatchedTwin", "MpcError", "MpcInputError", "MpcSolverError", "NmpcSettings", "OperatingPoint",
    "P80_BAND_UM", "PiFeedback", "QP_SOLVERS", "SOLVERS", "RK4_RATE_SAFETY", "SensorState", "Sensors", "Setpoints", "StepMoments", "TwinPlant",
    "FEED_RANGE_NOMINAL", "ExportDifference", "check_export", "recorded_export",
    "check_out_dir", "compiled", "cumulative", "cvodes_map", "default_feed_bounds", "discretize", "export_controller", "export_lock", "feed_for_target", "feed_holding_every_blend", "fit_fopdt", "fopdt_from_model", "gain_table",
    "fresh_feed_t", "held_cumulative", "held_integral", "run_closed_loop", "specific_energy_kwh_t",
    "integral", "linearize", "loop_kpis", "matched_twin", "min_rk4_substeps", "optimal_setpoints",
    "outside_band_frac", "p80_iae_um_h", "pi_baseline", "pi_from_model", "rk4_map", "rk4_sensitivity_map", "simc_pi", "speed_for_target",
    "stable_rk4_substeps", "state_jacobian", "steady_target", "step_moments", "step_test", "within_band_frac",
]
