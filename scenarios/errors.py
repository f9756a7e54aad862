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
