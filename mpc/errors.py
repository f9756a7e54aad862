"""Exception family of the ``mpc`` package, and the test of a numeric setting they share."""

from numbers import Real


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
