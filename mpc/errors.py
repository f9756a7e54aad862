"""Exception family of the ``mpc`` package, and the tests of a numeric setting and of a blend they share."""

import math
from numbers import Real

from twin.ore import blend_sum_ok


def is_blend(fractions) -> bool:
    """Finite fractions in [0, 1] summing to 1 within the twin's ``blend_sum_tolerance``: a plan or an estimate on
    [5, -4] ran on nothing. The caller rescales them to sum to 1 (``twin.ore.normalised_blend``), as the twin does."""
    values = [float(f) for f in fractions]
    return all(math.isfinite(f) and -1e-9 <= f <= 1 + 1e-9 for f in values) and blend_sum_ok(values)


def is_real(value) -> bool:
    """A real number, not a bool (True read as 1: a 1 h dead time, a 1 um noise) nor a string (it failed inside
    np.isfinite or float() without the setting's name)."""
    return isinstance(value, Real) and not isinstance(value, bool)


class MpcError(Exception):
    """Base class of every error raised by ``mpc``."""


class MpcInputError(MpcError, ValueError):
    """A setting is outside what is allowed; the message names field, value and range."""


class MpcSolverError(MpcError, RuntimeError):
    """The optimal-control problem could not be solved; carries the solver status."""


class OutsideModelsWarning(UserWarning):
    """A setting lets the controller take the plant where the twin's models do not describe it
    (:mod:`twin.validity`); noted, not refused, as the twin notes such a state."""
