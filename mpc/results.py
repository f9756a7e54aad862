"""Result object of one controller step, shared by the linear MPC, the PI baseline and the NMPC.

Modelled on python-control's ``OptimalControlResult`` (fields ``success``, ``cost``,
``inputs``): every step says whether the optimiser succeeded, what it cost, how long it took,
what was applied and, when the optimiser failed, which fallback produced the applied input.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mpc.errors import MpcInputError

FALLBACKS = (None, "shifted_plan", "hold_input")


@dataclass(frozen=True)
class ControllerStepResult:
    """What one ``make_step`` of a controller did.

    Attributes
    ----------
    success : bool
        True when the applied input is the solution of this step's problem.
    status : str
        Solver status text (e.g. ``"Solve_Succeeded"``, ``"unconstrained"``, ``"pi"``).
    cost : float
        Optimal cost of this step's problem (``nan`` when not solved).
    iterations : int
        Solver iterations (0 for closed-form or non-optimising controllers, -1 when the
        solver does not report them).
    solve_time_s : float
        Wall-clock time of the solve, seconds.
    u_applied : numpy.ndarray
        Input applied to the plant, shape ``(nu,)``, physical units.
    plan : numpy.ndarray or None
        Planned inputs over the horizon, shape ``(N, nu)``; ``None`` for controllers without
        a plan. ``plan[0]`` equals ``u_applied`` unless a fallback was used.
    fallback_used : str or None
        ``None`` when the solution was applied, else ``"shifted_plan"`` (the previous plan
        shifted one step) or ``"hold_input"`` (the previous input held).
    states_plan : numpy.ndarray or None
        Predicted states, shape ``(N + 1, nx)``, when the controller has them.
    """

    success: bool
    status: str
    cost: float
    iterations: int
    solve_time_s: float
    u_applied: np.ndarray
    plan: np.ndarray | None = None
    fallback_used: str | None = None
    states_plan: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.fallback_used not in FALLBACKS:
            raise MpcInputError(
                "The 'fallback_used' field of ControllerStepResult must be one of "
                f"{FALLBACKS}. Got {self.fallback_used!r}."
            )
        if self.success and self.fallback_used is not None:
            raise MpcInputError(
                "The 'fallback_used' field of ControllerStepResult must be None when "
                f"success is True. Got {self.fallback_used!r}."
            )
        object.__setattr__(self, "u_applied", np.asarray(self.u_applied, dtype=float).reshape(-1))
        if self.plan is not None:
            object.__setattr__(self, "plan", np.atleast_2d(np.asarray(self.plan, dtype=float)))

    def as_row(self, input_names: tuple[str, ...] | None = None) -> dict:
        """A flat dict for one row of a run's DataFrame (one column per applied input)."""
        names = input_names or tuple(f"u{i}" for i in range(self.u_applied.size))
        if len(names) != self.u_applied.size:
            raise MpcInputError(
                f"The 'input_names' parameter must have {self.u_applied.size} names. "
                f"Got {len(names)}."
            )
        row = {
            "success": self.success,
            "status": self.status,
            "cost": self.cost,
            "iterations": self.iterations,
            "solve_time_s": self.solve_time_s,
            "fallback_used": self.fallback_used,
        }
        row.update({n: float(v) for n, v in zip(names, self.u_applied)})
        return row
