"""Every shipped scene (scenarios/*.toml) runs end to end under a memory limit (RLIMIT_AS on a
subprocess that runs them one after the other: one import of the packages for all), writing a
complete result folder. Closed-loop scenes are shortened to SHORT_H with their schedule scaled
into it (the transition still happens); the replay replays its history's first SHORT_H."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCENES = sorted((ROOT / "scenarios").glob("*.toml"))
#: Address-space limit of each scene's process [GB]: the replay's goal (issue 14) is 4 GB.
MEMORY_LIMIT_GB = 4.0
#: Length of a shortened closed-loop scene [h].
SHORT_H = 1.0

DRIVER = r"""
import json, resource, sys, traceback
from pathlib import Path
limit = int(float(sys.argv[1]) * 2**30)
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
from scenarios.run import replay_scene, run_scene
from scenarios.scene import load_scene, scene_from_dict


def run(path, out, short_h):
    scene = load_scene(path)
    if scene.feed.history is not None:
        return replay_scene(scene, scene.history_path(), out_dir=out, progress=False, duration_h=short_h)
    data = scene.model_dump(exclude_none=True)
    if scene.controller.kind != "none" and scene.scene.duration_h > short_h:
        k = short_h / scene.scene.duration_h
        data["scene"]["duration_h"] = short_h
        for ev in data["feed"].get("schedule", []):
            ev["at_h"], ev["ramp_h"] = ev["at_h"] * k, ev.get("ramp_h", 0.0) * k
        data["controller"]["preview_lead_h"] = min(data["controller"]["preview_lead_h"], short_h)
    return run_scene(scene_from_dict(data, scene.source_path), out_dir=out, progress=False)


out_root, short_h, results = Path(sys.argv[2]), float(sys.argv[3]), {}
for path in sys.argv[4:]:
    name = Path(path).stem
    try:
        result = run(path, out_root / name, short_h)
        results[name] = {"kpis": result.kpis, "mode": result.summary["mode"],
                         "health": result.summary.get("controller_health")}
    except Exception:
        results[name] = {"error": traceback.format_exc()[-3000:]}
    results[name]["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps(results, default=str))
"""


@pytest.fixture(scope="module")
def shipped_runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("shipped")
    proc = subprocess.run([sys.executable, "-c", DRIVER, str(MEMORY_LIMIT_GB), str(out), str(SHORT_H),
                           *map(str, SCENES)], cwd=ROOT, capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out, json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("scene", SCENES, ids=[p.stem for p in SCENES])
def test_every_shipped_scene_runs_end_to_end_within_the_memory_limit(shipped_runs, scene):
    out_root, results = shipped_runs
    res = results[scene.stem]
    assert "error" not in res, res.get("error")
    k = res["kpis"]
    assert res["peak_rss_mb"] < MEMORY_LIMIT_GB * 1024
    assert k["mass_balance_error"] < 1e-6
    assert 50.0 < k["p80_final_um"] < 3000.0 and 1.0 < k["specific_energy_kwh_t"] < 100.0
    assert {"summary.json", "timeseries.parquet", "grindtwin-manifest.json", "p80.png"} <= {
        p.name for p in (out_root / scene.stem).iterdir()}
    if res["mode"] == "closed_loop":
        assert res["health"]["failed_steps"] == 0, res["health"]
        assert abs(k["p80_final_um"] - 210.0) < 15.0  # the shipped controllers hold their target
