"""Drum DEM accuracy against time -> the twin's selection function (lab mill, 0.7 critical, J = 0.35).

What the twin takes from the drum DEM (twin.calibration.dem_link, section 4) is the collision-energy
spectrum and the power; it turns them into the energy-specific selection function S^E(d)
(``dem_map.selection_energy_specific``) and fits Austin's form to it
(``dem_map.fit_austin_selection``). This benchmark measures how S^E and the power move with
the DEM's resolution knobs, each against the longest / largest / finest run as the converged
value, with the wall time each setting costs:

(a) revolutions: one long run of the default slice (0.1 m, 504 balls), spectra and torque
    snapshotted every 0.1 revolution from t = 0, so every (settle, measure) window is read from
    the same run (a window's wall time is the time to simulate settle + measure revolutions).
    Reference: settle 1, measure 10 revolutions. Includes the twin's own drum settings
    (dem_link.SETTINGS: full = settle 1 / measure 1 rev at 0.1 m, fast = 0.3 / 0.3 rev at
    0.0625 m).
(b) number of balls: slice length 0.0625 m (2.5 ball diameters, the minimum drum_test allows,
    315 balls), 0.1 m (504) and the whole 0.3 m mill (1512 balls, no length scaling) at
    settle 1 / measure 3 rev; reference: 0.3 m.
(c) time step: time_step_factor 0.4 and 0.2 (default) against 0.1, settle 1 / measure 3 rev, 0.1 m.
(d) seed: the initial ball placement / velocities (random_state 1, 2 against 0) at settle 1 /
    measure 3 rev, 0.1 m: the run-to-run scatter, the floor below which the errors above are noise.
(e) ball stiffness: Young's modulus 1 GPa (dem.drum's default) against 10 GPa (3.2x the steps),
    settle 1 / measure 2 rev, 0.1 m (steel's 210 GPa would cost 14x: not run).

S^E is computed for ore B with its shipped DEM fracture-energy distribution
(twin/calibration/files/dem.json: log-normal E50, sigma) and density; S^E_1mm is S^E evaluated
at 1 mm, SE1_fit / alpha the fitted Austin form (before the table-fitted capture scale, which
multiplies all of them alike and cancels in the errors).

The run replicates dem.drum.drum_test's set-up step by step (same ball placement, seed,
System arguments) and only adds snapshots; the (settle 1, measure 3) window of the 0.1 m run
reproduces the 0.7 row of dem_drum.md (checked in the notes of the table).

Writes benchmarks/results/dem_drum_accuracy.csv/.md; raw runs are cached in ``--cache`` (npz)
so the table can be rebuilt (``--table-only``). Run:
``NUMBA_NUM_THREADS=1 python benchmarks/dem_drum_accuracy.py [--runs long L0.0625 L0.3 dt0.4 dt0.1]``
(~20 min on one free core for all runs).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import OUT, write_table
from dem.drum import SOFT_STEEL_BALL, drum_system
from dem.materials import RAYLEIGH_SAFETY_FACTOR, Material
from dem.system import HIST_DLOG10, HIST_LO_LOG10, HIST_NBINS
from twin.calibration import dem_link, dem_map, load_calibration
from twin.ore.ores import load_ore
from twin.sizes import SizeGrid

SPEED, FILLING = 0.7, 0.35
SNAP_REV = 0.1
#: ball Young's modulus of the stiffness check (steel is 210 GPa; dem.drum's default is 1 GPa)
STIFF_BALL = Material(youngs_modulus_Pa=1e10, poisson_ratio=0.3, density_kg_m3=7800.0,
                      friction_coef=0.3, restitution=0.7)
#: name -> (section_length_m, total revolutions simulated, time_step_factor, random_state, ball material)
RUNS = {
    "long": (0.1, 11.0, RAYLEIGH_SAFETY_FACTOR, 0, SOFT_STEEL_BALL),
    "L0.0625": (0.0625, 4.0, RAYLEIGH_SAFETY_FACTOR, 0, SOFT_STEEL_BALL),
    "L0.3": (0.3, 4.0, RAYLEIGH_SAFETY_FACTOR, 0, SOFT_STEEL_BALL),
    "dt0.4": (0.1, 4.0, 0.4, 0, SOFT_STEEL_BALL),
    "dt0.1": (0.1, 4.0, 0.1, 0, SOFT_STEEL_BALL),
    "seed1": (0.1, 4.0, RAYLEIGH_SAFETY_FACTOR, 1, SOFT_STEEL_BALL),
    "seed2": (0.1, 4.0, RAYLEIGH_SAFETY_FACTOR, 2, SOFT_STEEL_BALL),
    "E10GPa": (0.1, 3.0, RAYLEIGH_SAFETY_FACTOR, 0, STIFF_BALL),
}
ORE = "B"


def run_with_snapshots(section_length_m: float, total_rev: float, time_step_factor: float,
                       speed_frac_critical: float = SPEED, ball_filling: float = FILLING,
                       mill_diameter_m: float = 0.5, mill_length_m: float = 0.3, ball_diameter_m: float = 0.025,
                       n_lifters: int = 8, lifter_height_m: float = 0.01, lifter_width_m: float = 0.012,
                       random_state: int = 0, ball_material: Material = SOFT_STEEL_BALL) -> dict:
    """dem.drum.drum_test's set-up (:func:`dem.drum.drum_system`), run ``total_rev`` revolutions
    from rest; cumulative collision histograms and wall time every SNAP_REV revolution, the
    torque at every step."""
    t0 = time.perf_counter()
    st = drum_system(
        speed_frac_critical, ball_filling, mill_diameter_m=mill_diameter_m,
        mill_length_m=mill_length_m, ball_diameter_m=ball_diameter_m,
        section_length_m=section_length_m, n_lifters=n_lifters, lifter_height_m=lifter_height_m,
        lifter_width_m=lifter_width_m, ball_material=ball_material,
        time_step_factor=time_step_factor, random_state=random_state)
    s, omega, steps_rev = st.system, st.omega_rad_s, st.steps_per_rev
    n = s.pos.shape[0]
    chunk = max(1, steps_rev // 8)
    n_snap = int(round(total_rev / SNAP_REV))
    snap_steps = [int(round(k * SNAP_REV * steps_rev)) for k in range(n_snap + 1)]
    hpp, hpw, wall = [s.hist_pp.copy()], [s.hist_pw.copy()], [time.perf_counter() - t0]
    for k in range(1, n_snap + 1):
        todo = snap_steps[k] - s.steps
        while todo > 0:
            m = min(chunk, todo)
            s.run(m)
            todo -= m
        hpp.append(s.hist_pp.copy())
        hpw.append(s.hist_pw.copy())
        wall.append(time.perf_counter() - t0)
        if k % 5 == 0:
            print(f"  L={section_length_m} dtf={time_step_factor}: {k * SNAP_REV:.1f} rev, "
                  f"{wall[-1]:.0f} s", flush=True)
    return {"section_length_m": section_length_m, "time_step_factor": time_step_factor, "n_balls": n,
            "random_state": random_state, "ball_youngs_GPa": ball_material.youngs_modulus_Pa / 1e9,
            "omega_rad_s": omega, "dt_s": s.dt_s, "steps_rev": steps_rev,
            "scale": mill_length_m / section_length_m, "snap_steps": np.array(snap_steps),
            "hist_pp": np.array(hpp), "hist_pw": np.array(hpw), "wall_s": np.array(wall),
            "torque_Nm": np.concatenate(s.records.torque_Nm)}


def window(run: dict, settle_rev: float, measure_rev: float) -> dict:
    """Power and whole-mill spectrum of the window [settle, settle + measure] revolutions."""
    a = int(round(settle_rev / SNAP_REV))
    b = int(round((settle_rev + measure_rev) / SNAP_REV))
    if b >= len(run["snap_steps"]) or a < 0 or b <= a:
        raise ValueError(f"window {settle_rev}+{measure_rev} rev outside the run")
    sa, sb = int(run["snap_steps"][a]), int(run["snap_steps"][b])
    tq = run["torque_Nm"][sa:sb]
    power = float(-np.mean(tq) * run["omega_rad_s"] * run["scale"])
    t = (sb - sa) * run["dt_s"]
    f = (run["hist_pp"][b] - run["hist_pp"][a] + run["hist_pw"][b] - run["hist_pw"][a]) * run["scale"] / t
    edges = 10.0 ** (HIST_LO_LOG10 + HIST_DLOG10 * np.arange(HIST_NBINS + 1))
    mid = np.sqrt(edges[:-1] * edges[1:])
    per = int(round(1.0 / SNAP_REV))
    per_rev = [float(-np.mean(run["torque_Nm"][int(run["snap_steps"][a + per * k]):int(run["snap_steps"][a + per * (k + 1)])])
                     * run["omega_rad_s"] * run["scale"])
               for k in range(int(measure_rev + 1e-9) if measure_rev >= 2 else 0)]
    keep = f > 0
    return {"power_W": power, "energy_mid_J": mid[keep].tolist(), "collisions_per_s_by_class": f[keep].tolist(),
            "collisions_per_s": float(f.sum()), "wall_s": float(run["wall_s"][b]),
            "power_per_rev_W": per_rev}


def selection(drum: dict) -> dict:
    """S^E of ore B from a spectrum and power, as twin.calibration.dem_link computes it."""
    rec = load_calibration("dem").record["dem"]["ores"][ORE]["fracture_energy"]
    rho = load_ore(ORE).density_t_m3 * 1000.0
    drum = {**drum, "ball_diameter_m": dem_link.DRUM["ball_diameter_m"]}
    sizes = dem_link.fit_sizes_um(SizeGrid())
    se = dem_map.selection_energy_specific(sizes, drum, rec["e50_j_kg"], rec["sigma"], rho)
    fit = dem_map.fit_austin_selection(sizes, se)
    se1 = float(dem_map.selection_energy_specific([1000.0], drum, rec["e50_j_kg"], rec["sigma"], rho)[0])
    return {"SE_1mm_t_kWh": se1, "SE1_fit_t_kWh": fit["se_1mm_t_kwh"], "alpha": fit["alpha"],
            "mu_um": fit["mu_um"], "SE_curve": se}


#: (study, label, run, settle_rev, measure_rev)
SETTINGS = [
    ("revolutions", "measure 0.5 rev", "long", 1.0, 0.5),
    ("revolutions", "measure 1 rev (twin full)", "long", 1.0, 1.0),
    ("revolutions", "measure 2 rev", "long", 1.0, 2.0),
    ("revolutions", "measure 3 rev (dem_drum.md)", "long", 1.0, 3.0),
    ("revolutions", "settle 0.5 + measure 1", "long", 0.5, 1.0),
    ("revolutions", "settle 0.3 + measure 0.3 (0.1 m)", "long", 0.3, 0.3),
    ("revolutions", "measure 5 rev", "long", 1.0, 5.0),
    ("revolutions", "measure 10 rev (reference)", "long", 1.0, 10.0),
    ("balls", "0.0625 m, 315 balls", "L0.0625", 1.0, 3.0),
    ("balls", "0.0625 m, settle 0.3 + measure 0.3 (twin fast)", "L0.0625", 0.3, 0.3),
    ("balls", "0.1 m, 504 balls", "long", 1.0, 3.0),
    ("balls", "0.3 m, 1512 balls (reference)", "L0.3", 1.0, 3.0),
    ("time_step", "factor 0.4", "dt0.4", 1.0, 3.0),
    ("time_step", "factor 0.2 (default)", "long", 1.0, 3.0),
    ("time_step", "factor 0.1 (reference)", "dt0.1", 1.0, 3.0),
    ("seed", "seed 1", "seed1", 1.0, 3.0),
    ("seed", "seed 2", "seed2", 1.0, 3.0),
    ("seed", "seed 0 (reference)", "long", 1.0, 3.0),
    ("stiffness", "E_ball 1 GPa (default)", "long", 1.0, 2.0),
    ("stiffness", "E_ball 10 GPa (reference)", "E10GPa", 1.0, 2.0),
]
REFERENCE = {"revolutions": "measure 10 rev (reference)", "balls": "0.3 m, 1512 balls (reference)",
             "time_step": "factor 0.1 (reference)", "seed": "seed 0 (reference)",
             "stiffness": "E_ball 10 GPa (reference)"}


def load_run(cache: str, name: str):
    p = os.path.join(cache, name + ".npz")
    if not os.path.exists(p):
        return None
    z = np.load(p)
    return {k: (z[k].item() if z[k].ndim == 0 else z[k]) for k in z.files}


def table(cache: str) -> pd.DataFrame:
    rows, curves = [], {}
    for study, label, name, settle, measure in SETTINGS:
        run = load_run(cache, name)
        if run is None:
            continue
        w = window(run, settle, measure)
        sel = selection(w)
        curves[(study, label)] = sel.pop("SE_curve")
        rows.append({"study": study, "setting": label, "section_length_m": run["section_length_m"],
                     "n_balls": int(run["n_balls"]), "time_step_factor": run["time_step_factor"],
                     "seed": int(run.get("random_state", 0)),
                     "ball_youngs_GPa": float(run.get("ball_youngs_GPa", 1.0)),
                     "settle_rev": settle, "measure_rev": measure, "power_W": w["power_W"],
                     "power_rev_std_W": float(np.std(w["power_per_rev_W"], ddof=1)) if len(w["power_per_rev_W"]) > 1 else float("nan"),
                     "collisions_per_s": w["collisions_per_s"], **sel, "wall_s": w["wall_s"]})
    df = pd.DataFrame(rows)
    for c in ("power_W", "collisions_per_s", "SE_1mm_t_kWh", "SE1_fit_t_kWh", "alpha"):
        df["err_" + c.split("_t_")[0] + "_pct"] = np.nan
    df["err_SE_curve_max_pct"] = np.nan
    df["err_SE_curve_rms_pct"] = np.nan
    for study, ref_label in REFERENCE.items():
        m = (df["study"] == study) if len(df) else []
        if not len(df) or not np.any(m) or ref_label not in set(df.loc[m, "setting"]):
            continue
        ref = df[m & (df["setting"] == ref_label)].iloc[0]
        for i in df.index[m]:
            for c in ("power_W", "collisions_per_s", "SE_1mm_t_kWh", "SE1_fit_t_kWh", "alpha"):
                df.loc[i, "err_" + c.split("_t_")[0] + "_pct"] = 100.0 * (df.loc[i, c] - ref[c]) / ref[c]
            a, b = curves[(study, df.loc[i, "setting"])], curves[(study, ref_label)]
            df.loc[i, "err_SE_curve_max_pct"] = float(np.max(np.abs(a / b - 1.0)) * 100.0)
            df.loc[i, "err_SE_curve_rms_pct"] = float(np.sqrt(np.mean((a / b - 1.0) ** 2)) * 100.0)
    return df


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", nargs="*", default=list(RUNS))
    ap.add_argument("--cache", default=os.environ.get("DEM_DRUM_ACCURACY_CACHE", "/tmp/dem_drum_accuracy_cache"))
    ap.add_argument("--table-only", action="store_true")
    a = ap.parse_args(argv)
    os.makedirs(a.cache, exist_ok=True)
    if not a.table_only:
        for name in a.runs:
            if load_run(a.cache, name) is not None:
                print(f"{name}: cached", flush=True)
                continue
            L, rev, dtf, seed, mat = RUNS[name]
            print(f"{name}: L = {L} m, {rev} rev, time_step_factor {dtf}, seed {seed}, "
                  f"E_ball {mat.youngs_modulus_Pa / 1e9:g} GPa", flush=True)
            run = run_with_snapshots(L, rev, dtf, random_state=seed, ball_material=mat)
            np.savez(os.path.join(a.cache, name + ".npz"), **run)
            print(f"{name}: done in {run['wall_s'][-1]:.0f} s", flush=True)
            write(a.cache)
    write(a.cache)


def seed_noise(df: pd.DataFrame) -> str:
    """The seed rows' largest errors: the run-to-run noise, below which a difference is not resolved."""
    seed = df[(df["study"] == "seed") & (df["setting"] != REFERENCE["seed"])]
    if seed.empty:
        return ""
    big = {c: float(seed[c].abs().max()) for c in ("err_power_W_pct", "err_SE_1mm_pct", "err_SE_curve_rms_pct")}
    return (f"The seed rows are the run-to-run noise (up to: power {big['err_power_W_pct']:.1f} %, S^E_1mm "
            f"{big['err_SE_1mm_pct']:.1f} %, curve rms {big['err_SE_curve_rms_pct']:.1f} % at 3 revolutions): "
            "differences below that are not resolved.")


def drum_md_check(df: pd.DataFrame) -> str:
    """This run's (settle 1, measure 3) window beside dem_drum.md's 0.7 row (dem.drum.drum_test)."""
    mine, path = df.loc[df["setting"] == "measure 3 rev (dem_drum.md)", "power_W"], os.path.join(OUT, "dem_drum.csv")
    if mine.empty or not os.path.exists(path):
        return ""
    drum = pd.read_csv(path)
    theirs = drum.loc[(drum["case"] == "speed_sweep") & np.isclose(drum["speed_frac_critical"], 0.7), "power_W"]
    if theirs.empty:
        return ""
    return (f"The (settle 1, measure 3) row: {mine.iloc[0]:.1f} W; dem_drum.md's 0.7 row (drum_test, the same "
            f"settings): {theirs.iloc[0]:.1f} W.")


def shipped_drum() -> str:
    """What the shipped calibration's drum was (its settings and power, read from the file: the
    rows 'twin full' and 'twin fast' are these settings)."""
    cal = load_calibration("dem")
    s, d = cal.record["dem"]["settings"], cal.record["dem"]["drum"]
    return (f"The shipped calibration ({cal.identity()['path']}) ran its drum with settle "
            f"{s['drum_settle_rev']:g} + measure {s['drum_measure_rev']:g} rev on a {s['drum_section_length_m']:g} m "
            f"section: {d['power_W']:.1f} W.")


def write(cache: str) -> None:
    df = table(cache)
    if df.empty:
        return
    missing = [n for n in RUNS if load_run(cache, n) is None]
    write_table(df, "dem_drum_accuracy",
                "Drum DEM accuracy against time -> selection function (lab mill, 0.7 critical, J = 0.35, ore B)",
                "Errors in % of the study's reference row (longest / most balls / finest step / seed 0 / "
                "stiffer balls). S^E from twin.calibration.dem_map.selection_energy_specific with ore B's shipped DEM "
                "fracture energies (capture scale not applied; it cancels in the errors): SE_1mm is S^E at "
                "1 mm; SE1_fit, alpha, mu_um the fitted Austin form S1 (d/1 mm)^alpha / (1 + (d/mu)^Lambda) the "
                "twin uses (S1, mu and Lambda trade off in the fit, so S1 alone scatters ~10 % where the curve "
                "moves ~2 %); err_SE_curve_max/rms_pct the largest / rms deviation of S^E over the 17 sizes "
                "22 um - 5.6 mm (the largest is at the coarsest size, broken only by the rare highest-energy "
                "collisions, or for the stiffness study at the finest). wall_s: time to simulate settle + "
                "measure revolutions from rest (the revolutions rows are windows of one 11-revolution run, so "
                "their wall time is where that run was when the window closed), single thread on a 2-core "
                "machine shared with other jobs (upper bounds). power_rev_std_W: spread of the per-revolution "
                "power. " + seed_noise(df) + " " + drum_md_check(df) + " " + shipped_drum()
                + (f" Not run: {', '.join(missing)}." if missing else ""))
    print(df.to_string(), flush=True)


if __name__ == "__main__":
    main()
