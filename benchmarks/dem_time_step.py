"""The measured stability bound of the DEM time step, against the critical step System computes.

System's critical step (``System.critical_dt_s``) is the smaller of the contact step and the
bond-spring step ``sqrt(m / sum k)`` per sphere (dem.system); velocity Verlet on one harmonic
spring is stable up to 2/omega, and a sphere coupled to many bonds lowers that, so the true
bound lies somewhere between. This benchmark finds it: a compression test's loading phase run to
the same simulated time at time steps ``factor x critical`` (set past System's allowed range,
which stops at 1, by assigning ``dt_s`` after construction), on several packings, for two
models (``--models``):

- ``jcfpm``: the Yade-JCFpm mirror of benchmarks/dem_parallel_worker.py (central-ish force-only
  bonds, linear contacts, platen 0.1 m/s), 500 and 2,000 spheres;
- ``calibration``: what the DEM calibration runs (twin/calibration/dem_link.py): Type B's
  parallel bonds with bending and twisting moments from the shipped calibration file, Hertz-
  Mindlin contacts, steel platens at its 0.25 m/s, 150 spheres (its resolution) and 500.
 A run is *stable* when it
raises no instability, breaks no bond that the reference (factor 0.25) does not, and its
platen force at the end is within ``STABLE_TOL`` of the reference's. The accuracy cost of the
allowed factors on whole compression tests is in benchmarks/results/dem_accuracy.md.

``python benchmarks/dem_time_step.py [--models jcfpm,calibration] [--sizes 500,2000] [--seeds 0,1,2]`` writes
benchmarks/results/dem_time_step.md and .csv (default: both models, each at its own sizes, seeds 0,1,2).
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np
import pandas as pd

from dem_common import SPHERES_LIST, option_type, write_table
from dem_parallel_worker import loading_system
from dem.agglomerate import make_agglomerate
from dem.errors import DemInstabilityError
from dem.lab import DEFAULT_TIME_STEP_FACTOR as DEFAULT_FACTOR

#: simulated loading time (s): 30 um of platen travel, elastic for the intact particle
T_END_S = 3e-4
#: relative difference of the final platen force from the reference's that still counts as stable
STABLE_TOL = 0.01
REFERENCE_FACTOR = 0.25
FACTORS = (0.5, 1.0, 1.25, 1.5, 1.75, 2.0, 2.5)


def calibration_loading_system(agg, dt_s: float):
    """The compression test as the DEM calibration runs it for Type B (its bonds, material, platen
    speed; dem.lab.compression_test's damping and platens)."""
    import json

    from dem.bonds import BondParams, BondSet
    from dem.materials import STEEL, Material
    from dem.system import PlaneWall, System
    from twin.calibration.dem_link import PLATEN_SPEED_M_S
    from twin.calibration.files import CALIBRATION_DIR

    ore = json.loads((CALIBRATION_DIR / "dem.json").read_text(encoding="utf-8"))["dem"]["ores"]["B"]
    b = ore["bond"]
    bonds = BondParams(kn_Pa_m=b["kn_GPa_m"] * 1e9, ks_Pa_m=b["ks_GPa_m"] * 1e9,
                       tensile_strength_Pa=b["tensile_strength_MPa"] * 1e6, cohesion_Pa=b["cohesion_MPa"] * 1e6)
    rock = Material(youngs_modulus_Pa=ore["youngs_gpa"] * 1e9, density_kg_m3=ore["density_t_m3"] * 1e3)
    pos = agg.pos_m.copy()
    z_lo = float(np.min(pos[:, 2] - agg.radius_m))
    z_hi = float(np.max(pos[:, 2] + agg.radius_m))
    walls = [PlaneWall((0, 0, z_lo), (0, 0, 1)), PlaneWall((0, 0, z_hi), (0, 0, -1), (0, 0, -PLATEN_SPEED_M_S))]
    return System(pos, agg.radius_m, rock, density_kg_m3=rock.density_kg_m3 / agg.solid_fraction,
                  bonds=BondSet(agg.bond_pairs, pos, agg.radius_m, bonds), wall_material=STEEL, walls=walls,
                  local_damping=0.7, dt_s=dt_s)


MODELS = {"jcfpm": (loading_system, (500, 2000)), "calibration": (calibration_loading_system, (150, 500))}


def loading(agg, factor: float, model: str = "jcfpm") -> dict:
    s = MODELS[model][0](agg, 1e-12)        # any valid step; the factor's is set next
    s.set_dt_beyond_critical(factor * s.critical_dt_s)
    steps = int(round(T_END_S / s.dt_s))
    try:
        s.run(steps)
    except DemInstabilityError:
        return {"steps": steps, "unstable": True, "force_end_N": np.nan, "broken": -1,
                "critical_dt_s": s.critical_dt_s}
    return {"steps": steps, "unstable": False,
            "force_end_N": float(s.record_arrays()["wall_force_N"][-1, 1]),
            "broken": int(np.sum(s.bonds.state != 0)), "critical_dt_s": s.critical_dt_s}


def scan(model: str, n: int, seed: int) -> list[dict]:
    agg = make_agglomerate(0.022, n, random_state=seed)
    ref = loading(agg, REFERENCE_FACTOR, model)
    rows = []
    for f in FACTORS:
        r = loading(agg, f, model)
        err = r["force_end_N"] / ref["force_end_N"] - 1.0
        stable = (not r["unstable"]) and r["broken"] <= ref["broken"] and abs(err) <= STABLE_TOL
        rows.append({"model": model, "n_spheres": n, "seed": seed, "factor": f, "dt_s": f * r["critical_dt_s"],
                     "steps": r["steps"], "force_err_pct": 100 * err, "broken": r["broken"],
                     "broken_reference": ref["broken"], "stable": stable})
        print(rows[-1], flush=True)
    return rows


def options(argv) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", default=",".join(MODELS), help="comma-separated (default %(default)s)",
                    type=option_type(str, MODELS.__contains__, "one of " + ", ".join(MODELS), many=True))
    ap.add_argument("--sizes", type=SPHERES_LIST, help="sphere counts for every model (default: each model's own: "
                    + "; ".join(f"{m} {','.join(map(str, v[1]))}" for m, v in MODELS.items()) + ")")
    ap.add_argument("--seeds", default="0,1,2", help="packing seeds (default %(default)s)",
                    type=option_type(int, lambda v: v >= 0, "an integer >= 0", many=True))
    return ap.parse_args(argv)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    o = options(argv)
    t = pd.DataFrame([r for m in o.models for n in (o.sizes or MODELS[m][1])
                      for s in o.seeds for r in scan(m, n, s)])
    groups = t.groupby(["model", "n_spheres"])
    bound = {k: float(g.groupby("factor").stable.all().loc[lambda x: x].index.max()) for k, g in groups}
    first_bad = {k: g.loc[~g.stable, "factor"].min() for k, g in groups}
    note = (f"Command: `python benchmarks/dem_time_step.py {' '.join(argv)}`. Loading phase of the "
            f"compression test to t = {T_END_S:g} s at factor x System.critical_dt_s (models: see the script's "
            f"docstring); reference factor {REFERENCE_FACTOR}; stable = no instability, no bond broken that the "
            f"reference keeps, final platen force within {100 * STABLE_TOL:g} % of the reference's. Largest factor "
            "stable on every packing: " + ", ".join(f"{m} {n} spheres {bound[m, n]:g} (first unstable "
                                                     f"{first_bad[m, n]:g})" for m, n in bound)
            + f". System allows factors up to 1; the compression test's default is {DEFAULT_FACTOR:g}.")
    write_table(t, "dem_time_step", "Measured stability bound of the DEM time step", note)


if __name__ == "__main__":
    main()
