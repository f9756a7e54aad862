"""Exception family of the ``scenarios`` package."""


class ScenarioError(Exception):
    """Base class of every error raised by ``scenarios``."""


class SceneError(ScenarioError, ValueError):
    """A scene file is invalid; the message names the file, the key path, the value and what is allowed."""


class RunError(ScenarioError, RuntimeError):
    """A run failed; the message says why. Partial output is never presented as complete."""


class Interrupted(BaseException):
    """A signal (SIGTERM) asked the process to stop: raised like KeyboardInterrupt so that a run
    unwinds and removes its partial output. ``signum`` is the signal's number."""

    def __init__(self, signum: int):
        super().__init__(f"signal {signum}")
        self.signum = signum


#: Signals the command's handler received (scenarios.cli.commands): a signal that lands inside a
#: CasADi call can come out of it swallowed, the run going on; a result is then not committed.
RECEIVED_SIGNALS: list[int] = []


def raise_if_interrupted() -> None:
    """Raise :class:`Interrupted` if a signal was received, even one a solver call swallowed."""
    if RECEIVED_SIGNALS:
        raise Interrupted(RECEIVED_SIGNALS[0])
