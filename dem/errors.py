"""Exception family of the ``dem`` package (SI units throughout)."""


class DemError(Exception):
    """Base class of every error raised by ``dem``."""


class DemInputError(DemError, ValueError):
    """A parameter is outside what is allowed; the message names field, value and range."""


class DemInstabilityError(DemError, RuntimeError):
    """The integration blew up (non-finite state); the message names the step and the cause."""


class UnfracturedWarning(UserWarning):
    """A compression test ended without the particle breaking: its peak force is the force at the end of
    the platen's travel, not a strength (CompressionResult.fractured is False)."""
