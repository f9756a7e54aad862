"""Scenes, replays, what-if sweeps, reports and the grindtwin command.

The Python API mirrors the CLI: ``scenarios.load_scene``, ``scenarios.check_scene``,
``scenarios.run_scene``, ``scenarios.replay_scene``, ``scenarios.run_sweep``,
``scenarios.write_report`` (imported on first use, so that ``import scenarios`` stays light).
"""

_API = {
    "load_scene": "scenarios.scene", "check_scene": "scenarios.run", "Scene": "scenarios.scene",
    "run_scene": "scenarios.run", "replay_scene": "scenarios.run", "RunResult": "scenarios.run",
    "run_sweep": "scenarios.run", "write_report": "scenarios.output",
}

__all__ = sorted(_API)


def __getattr__(name):
    if name in _API:
        import importlib

        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'scenarios' has no attribute {name!r}")
