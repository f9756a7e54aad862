"""Model predictive control, estimation and baselines on the grindtwin mill model."""

from mpc.discretize import cvodes_map, min_rk4_substeps, rk4_map
from mpc.errors import MpcError, MpcInputError, MpcSolverError
from mpc.leroux import LeRouxCircuit, LeRouxParameters, LeRouxPlant, MatchedTwin, matched_twin
from mpc.linear import (
    Fopdt,
    LinearMPC,
    OperatingPoint,
    discretize,
    fit_fopdt,
    fopdt_from_model,
    gain_table,
    linearize,
    steady_target,
)
from mpc.pi import DiscretePI, pi_from_model, simc_pi
from mpc.results import ControllerStepResult
from mpc.closed_loop import (
    ClosedLoopResult,
    FixedInputs,
    PiFeedback,
    Sensors,
    TwinPlant,
    pi_baseline,
    run_closed_loop,
)
from mpc.estimator import Ekf
from mpc.nmpc import Controller, NmpcSettings
from mpc.optimize import Setpoints, feed_for_target, optimal_setpoints, speed_for_target

__all__ = [
    "ControllerStepResult",
    "DiscretePI",
    "Fopdt",
    "LeRouxCircuit",
    "LeRouxParameters",
    "LeRouxPlant",
    "MatchedTwin",
    "matched_twin",
    "LinearMPC",
    "MpcError",
    "MpcInputError",
    "MpcSolverError",
    "OperatingPoint",
    "cvodes_map",
    "discretize",
    "fit_fopdt",
    "fopdt_from_model",
    "gain_table",
    "linearize",
    "min_rk4_substeps",
    "pi_from_model",
    "rk4_map",
    "simc_pi",
    "steady_target",
    # NMPC, estimation, closed loop, steady-state optimiser
    "ClosedLoopResult",
    "Controller",
    "Ekf",
    "FixedInputs",
    "NmpcSettings",
    "PiFeedback",
    "TwinPlant",
    "Sensors",
    "Setpoints",
    "feed_for_target",
    "optimal_setpoints",
    "pi_baseline",
    "run_closed_loop",
    "speed_for_target",
]
