"""A scheduled ramp as the open loop and as a closed loop give it to the plant: an open loop's plant takes
the scene's blend linearly between samples (its inputs are linear in time between samples), a closed loop's
holds each sample's blend over the sample (``scenarios.run.closed_loop.hold_schedule``: the blend the
controller sampled). In a sweep over ``controller.kind`` the ``none`` case therefore sees a ramp half a
sample earlier than the PI and NMPC cases. This runs the reference transition as an open loop (no control,
no sensor noise) both ways, the held ramp written as one step per sample to the ramp's value at that sample,
and compares the KPIs.

    PYTHONPATH=. python benchmarks/twin_ramp_hold.py

Writes benchmarks/results/twin_ramp_hold.csv and .md.
"""

from __future__ import annotations

import copy
import os
import sys
from pathlib import Path

sys.path.insert(0, os.path.dirname(__file__))

import pandas as pd

from dem_common import write_table

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenarios" / "reference_transition.toml"
KPIS = ("p80_iae_um_h", "p80_within_10um_frac", "p80_mean_um", "specific_energy_kwh_t")


def held(ramp: dict, dt: float) -> list[dict]:
    """A linear ramp from pure ``B`` as one step per sample to its value at that sample (what a closed loop holds)."""
    n = round(ramp["ramp_h"] / dt)
    end = ramp["blend"]
    steps = []
    for k in range(1, n + 1):
        w = k / n
        blend = {ore: w * frac for ore, frac in end.items()}
        blend["B"] = blend.get("B", 0.0) + (1.0 - w)
        steps.append({"at_h": ramp["at_h"] + k * dt, "kind": "step", "blend": blend})
    return steps


def main() -> None:
    from scenarios.run import run_scene
    from scenarios.scene.loader import read_toml, scene_from_dict

    data = read_toml(SCENE)
    data["controller"] = {"kind": "none", "target_p80_um": data["controller"]["target_p80_um"]}
    data["sensors"] = {k: v for k, v in data.get("sensors", {}).items() if "noise" not in k}
    (ramp,) = data["feed"]["schedule"]
    assert ramp["kind"] == "ramp" and data["feed"]["blend"] == {"B": 1.0}
    variants = {"linear between samples (open loop)": data, "held over each sample (closed loop)": copy.deepcopy(data)}
    variants["held over each sample (closed loop)"]["feed"]["schedule"] = held(ramp, data["scene"]["sample_period_h"])
    rows = []
    for name, d in variants.items():
        kpis = run_scene(scene_from_dict(d, SCENE), progress=False).kpis
        rows.append({"ramp": name, **{k: kpis[k] for k in KPIS}})
    table = pd.DataFrame(rows)
    for k in KPIS:
        table[f"{k}_change_pct"] = 100.0 * (table[k] / table[k].iloc[0] - 1.0)
    write_table(table, "twin_ramp_hold", "A scheduled ramp linear between samples against held over each sample",
                "The reference transition (8 h, 3-min samples, a 0.5 h ramp from B to 60 % B / 40 % D at 3 h) as an "
                "open loop without sensor noise; changes against the first row.")
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
