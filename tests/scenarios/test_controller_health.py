"""Controller failures, fallbacks and estimator resets reach summary.json, the report and the
screen (the issue: 21 of 21 forced NMPC failures were reported nowhere)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from tests.scenarios.test_cli import grindtwin
from tests.scenarios.test_runner import _controlled, short_pyrite_scene


@pytest.fixture
def failing_nmpc(monkeypatch):
    """Every NMPC solve fails: max_iter = 0 (NmpcSettings' documented way to force a failure)."""
    import scenarios.run.closed_loop as closed_loop

    real = closed_loop.nmpc_settings
    monkeypatch.setattr(closed_loop, "nmpc_settings", lambda scene: dataclasses.replace(real(scene), max_iter=0))


def test_forced_controller_failures_are_counted_everywhere(tmp_path, capsys, failing_nmpc):
    path = _controlled(short_pyrite_scene(tmp_path, duration_h=0.25), "nmpc")
    out = tmp_path / "out"
    assert grindtwin(["run", path, "--out", out, "--quiet", "--no-plots"]) == 0
    captured = capsys.readouterr()
    summary = json.loads((out / "summary.json").read_text())
    health, k = summary["controller_health"], summary["kpis"]
    n = 16  # 0.25 h of one-minute samples, both ends
    assert health["steps"] == n and health["failed_steps"] == n
    assert health["fallback_steps"] == n and sum(health["fallbacks"].values()) == n
    assert set(health["fallbacks"]) <= {"shifted_plan", "hold_input"}
    assert health["first_failure_time_h"] == 0.0
    assert k["controller_failed_steps"] == n and k["controller_fallback_steps"] == n
    assert k["estimator_resets"] == 0
    assert any("the controller's solve failed on 16 of 16 steps" in w for w in summary["warnings"])
    assert "grindtwin: warning: the controller's solve failed on 16 of 16 steps" in captured.err
    assert "controller_failed_steps    16" in captured.out
    assert grindtwin(["report", out]) == 0
    html = (out / "report.html").read_text()
    assert "<code>controller_failed_steps</code>" in html and "controller steps whose solve failed" in html


def test_a_healthy_loop_reports_zero_and_open_loop_reports_not_applicable(tmp_path):
    from scenarios.run import run_scene

    closed = run_scene(_controlled(short_pyrite_scene(tmp_path, duration_h=0.25), "pi"), progress=False)
    assert closed.summary["controller_health"]["failed_steps"] == 0 and closed.summary["warnings"] == []
    assert closed.kpis["controller_fallback_steps"] == 0
    (tmp_path / "open").mkdir()
    open_loop = run_scene(short_pyrite_scene(tmp_path / "open", duration_h=0.25), progress=False)
    assert open_loop.summary["controller_health"] is None
    assert math.isnan(open_loop.kpis["controller_failed_steps"])


class _DivergingEkf:
    """An estimator whose second update is not finite (as an EKF's can be after a bad step)."""

    nd = 3

    def __init__(self):
        self.calls, self.resets, self.P = 0, 0, np.eye(2)
        self.x_est, self.hardness_est = np.array([1.0, 2.0]), 1.0

    def make_step(self, y, u, d):
        self.calls += 1
        return (np.array([np.nan, 2.0]) if self.calls == 2 else self.x_est), np.r_[d[:2], 1.0]

    def reset(self):
        self.resets += 1


def test_an_estimator_whose_estimate_is_not_finite_is_reset_and_counted():
    from scenarios.run.closed_loop import CountingEstimator

    ekf = _DivergingEkf()
    est = CountingEstimator(ekf)
    for _ in range(4):
        x, d = est.make_step([200.0, 300.0, 1.0], [30.0, 0.7], [0.5, 0.5, 1.0])
        assert np.all(np.isfinite(x)) and np.all(np.isfinite(d))
    assert est.resets == [2] and ekf.resets == 1
    assert est.hardness_est == 1.0  # everything else is the EKF's own


def test_a_saturated_hardness_estimate_and_unreachable_targets_are_said():
    """controller_health counts the samples whose hardness estimate sits at a bound of the EKF's
    clip, and the steps whose plan missed the target; health_notes says both (none without)."""
    from types import SimpleNamespace

    import pandas as pd

    from scenarios.run.closed_loop import controller_health, health_notes

    est = SimpleNamespace(resets=[], ekf=SimpleNamespace(has_hardness=True, hardness_bounds=(0.3, 3.0)))
    frame = pd.DataFrame({"time_h": [0.0, 0.1, 0.2, 0.3], "hardness_est": [1.0, 3.0, 2.9999, 0.3],
                          "status": ["ok", "target_unreachable (ok): predicted P80 250.0 um", "ok", "ok"]})
    health = controller_health(frame, est)
    assert health["hardness_at_bound_steps"] == 2 and health["target_unreachable_steps"] == 1
    notes = health_notes(health)
    assert any("on 2 of 4 steps the estimator's hardness sat at a bound" in n for n in notes)
    assert any("on 1 of 4 steps the controller found no plan that reaches the P80 target" in n for n in notes)
    calm = controller_health(frame.assign(hardness_est=1.0, status="ok"), est)
    assert health_notes(calm) == []


def test_a_load_above_the_checked_band_top_is_said():
    """The NMPC's RK4 step count is checked stable up to the load band's top; samples whose plant
    load went beyond it are counted and said (with the highest load and when), none below it or
    without a checked top (PI)."""
    from types import SimpleNamespace

    import pandas as pd

    from scenarios.run.closed_loop import controller_health, health_notes

    est = SimpleNamespace(resets=[], ekf=None)
    frame = pd.DataFrame({"time_h": [0.0, 0.1, 0.2, 0.3], "load_frac": [1.0, 1.25, 1.31, 1.19]})
    health = controller_health(frame, est, 1.2)
    assert health["above_checked_load_steps"] == 2 and health["load_max"] == 1.31 and health["load_max_time_h"] == 0.2
    assert any("on 2 of 4 steps the mill's load was above 1.2 of nominal" in n and "reached 1.31 at 0.2 h" in n
               for n in health_notes(health))
    assert health_notes(controller_health(frame, est, 1.4)) == []
    assert health_notes(controller_health(frame, est)) == []
