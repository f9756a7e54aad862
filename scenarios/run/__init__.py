"""Runs of a scene: its models, the feed on the sample grid, an open-loop, batch or closed-loop
run, the KPIs and summary (``run_scene``, ``replay_scene``), and what-if sweeps (``run_sweep``)."""

from scenarios.run.closed_loop import check_scene_export, export_scene_controller
from scenarios.run.kpis import KPI_KEYS, compute_kpis
from scenarios.run.models import Models, build_models, is_batch
from scenarios.run.preflight import check_scene
from scenarios.run.runner import RunResult, replay_scene, run_scene
from scenarios.run.sweep import MAX_CASES, parse_vary, run_sweep

__all__ = ["KPI_KEYS", "MAX_CASES", "Models", "RunResult", "build_models", "check_scene", "check_scene_export",
           "compute_kpis", "export_scene_controller", "is_batch", "parse_vary",
           "replay_scene", "run_scene", "run_sweep"]
