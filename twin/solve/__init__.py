"""Solvers of a built mill model: steady states (Newton on the sparse DAE form) and time
integration (IDAS/CVODES, fixed-step RK4, the exact batch solution)."""

from .simulate import (ATOL_REL, ORE_CIRCULATING_LOAD_KEY, ORE_P80_KEY, RTOL, Trajectory, batch_exact, has_ore_products,
                       integrate_constant, mass_balance_error, ore_circulating_load, ore_p80_um, outputs_frame,
                       rk4_simulate, sample_count, simulate, step, step_integrator)
from .steady import (RESIDUAL_REL_TOL, SteadyState, pxx_gradient, steady_sensitivities, steady_state,
                     steady_state_at_load)

__all__ = ["ATOL_REL", "ORE_CIRCULATING_LOAD_KEY", "ORE_P80_KEY", "RESIDUAL_REL_TOL", "RTOL", "SteadyState",
           "Trajectory", "batch_exact", "has_ore_products", "integrate_constant", "mass_balance_error",
           "ore_circulating_load", "ore_p80_um", "outputs_frame", "pxx_gradient", "rk4_simulate", "sample_count",
           "simulate", "steady_sensitivities", "steady_state", "steady_state_at_load", "step", "step_integrator"]
