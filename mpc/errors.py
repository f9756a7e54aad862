"""Exception family of the ``mpc`` package."""


class MpcError(Exception):
    """Base class of every error raised by ``mpc``."""


class MpcInputError(MpcError, ValueError):
    """A setting is outside what is allowed; the message names field, value and range."""


class MpcSolverError(MpcError, RuntimeError):
    """The optimal-control problem could not be solved; carries the solver status."""


class OutsideModelsWarning(UserWarning):
    """A setting lets the controller take the plant where the twin's models do not describe it
    (:mod:`twin.validity`); noted, not refused, as the twin notes such a state."""
