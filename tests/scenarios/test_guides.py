"""The guides in docs/ run as written: each page's Python code is executed with its settings
(the lines ``NAME = ...`` it says the suite changes) replaced by a short, coarse version of its
scene, and what it computes is checked against what the page claims."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"


def page_code(name: str, **settings) -> str:
    """The ``python`` blocks of ``docs/<name>`` with each ``NAME = ...`` line of ``settings``
    replaced (every one must be found)."""
    code = "\n".join(re.findall(r"```python\n(.*?)```", (DOCS / name).read_text(encoding="utf-8"), re.S))
    for key, value in settings.items():
        code, n = re.subn(rf"^{key} = .*$", f"{key} = {value!r}", code, flags=re.M)
        assert n == 1, f"{name}: no line '{key} = ...'"
    return code


def run_page(name: str, tmp_path: Path, monkeypatch, **settings) -> dict:
    monkeypatch.chdir(tmp_path)  # the page's output folders (runs/...) land here
    namespace = {"__name__": "__guide__"}
    exec(compile(page_code(name, **settings), str(DOCS / name), "exec"), namespace)
    return namespace


def short_reference_scene(tmp_path: Path) -> Path:
    """The reference transition, 1 h long with the ramp at 0.25-0.5 h, the controller's coarse
    model as the plant too (no [plant]), one mixer and a 4-step horizon: seconds, not minutes."""
    text = (REPO / "scenarios" / "reference_transition.toml").read_text()
    text = text[:text.index("[plant]")] + text[text.index("[ores.B]"):]
    for old, new in (("duration_h = 8.0", "duration_h = 1.0"), ("at_h = 3.0", "at_h = 0.25"),
                     ("ramp_h = 0.5", "ramp_h = 0.25"), ("n_mixers = 3", "n_mixers = 1"),
                     ("horizon_steps = 10", "horizon_steps = 4"), ("preview_lead_h = 0.5", "preview_lead_h = 0.2")):
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "short_reference.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_replay_guide(tmp_path, monkeypatch):
    ns = run_page("guide_replay.md", tmp_path, monkeypatch, SCENE=str(REPO / "scenarios" / "replay_day.toml"),
                  HISTORY=str(REPO / "scenarios" / "data" / "sample_history.csv"), HOURS=0.25)
    fr = ns["result"].frame
    assert len(fr) == 16  # 0.25 h at one-minute samples
    np.testing.assert_array_equal(fr["feed_tph"], fr["recorded_feed_tph"])  # open loop: the recorded inputs
    assert ns["result"].kpis["mass_balance_error"] < 1e-6
    assert ns["gap"].abs().mean() == pytest.approx(ns["result"].summary["replay"]["run_minus_recorded"]
                                                   ["p80_um_mean_abs_diff"])
    assert (tmp_path / "runs" / "replay_open" / "run.xlsx").is_file()


@pytest.mark.slow
def test_tuning_guide(tmp_path, monkeypatch):
    ns = run_page("guide_tuning.md", tmp_path, monkeypatch, SCENE=str(short_reference_scene(tmp_path)), HOURS=1.0)
    table = ns["table"]
    assert list(table.index) == list(ns["TUNINGS"])
    nmpc = table.filter(like="NMPC", axis=0)
    assert (nmpc["step p95 [s]"] > 10 * table.loc["PI (feed only)", "step p95 [s]"]).all()  # PI solves nothing
    assert nmpc.loc["NMPC, cheap moves", "feed moves [t/h]"] > nmpc.loc["NMPC, the scene's weights", "feed moves [t/h]"]
    assert (table["IAE [um h]"] >= 0).all() and table["t/h"].between(20.0, 45.0).all()  # the scene's bounds


def test_sweep_guide(tmp_path, monkeypatch):
    ns = run_page("guide_sweep.md", tmp_path, monkeypatch, SCENE=str(short_reference_scene(tmp_path)), WORKERS=1)
    table = ns["table"]
    assert len(table) == 6 and table["error"].isna().all()
    open_loop = table[table["controller.kind"] == "none"].sort_values("D after the transition")
    assert np.all(np.diff(open_loop["specific_energy_kwh_t"]) < 0)  # more soft D: less energy ...
    assert np.all(np.diff(open_loop["p80_final_um"]) > 0)  # ... and a coarser product
