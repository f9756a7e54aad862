"""Scenes, replays, what-if sweeps, reports and the grindtwin command.

The Python API mirrors the CLI: ``scenarios.load_scene``, ``scenarios.check_scene``,
``scenarios.run_scene``, ``scenarios.replay_scene``, ``scenarios.run_sweep`` (imported on
first use, so that ``import scenarios`` stays light).
"""

_API = {
    "load_scene": "scenarios.loader", "check_scene": "scenarios.loader",
    "run_scene": "scenarios.runner", "replay_scene": "scenarios.runner",
    "RunResult": "scenarios.runner", "run_sweep": "scenarios.sweep",
    "write_report": "scenarios.report",
}

__all__ = sorted(_API)


def __getattr__(name):
    if name in _API:
        import importlib

        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'scenarios' has no attribute {name!r}")
