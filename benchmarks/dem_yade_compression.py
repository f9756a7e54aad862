# Yade script (run inside Yade: ``yade -n -x benchmarks/dem_yade_compression.py PACK OUT [DT_FACTOR]
# [dt=DT_S] [steps=N] [every=K]``): dt= sets the time step in seconds (else DT_FACTOR x
# PWaveTimeStep); steps=N times N steps of the loading phase recording nothing and writes one JSON
# line (steps, wall_s, cpu_s) to OUT; otherwise the full test, recorded every K (20) steps.
# Yade is a benchmark peer only, never a dependency of grindtwin.
# The test: sphere D = 22 mm of dense random packing (read from PACK, the same packing
# as the grindtwin run), radii r(1 +- 0.25), bonds between neighbours within 1.3 (R1 + R2),
# E = 30 GPa, ks/kn = 0.4, tensile 10 MPa, cohesion 20 MPa, friction 30 deg, density 2700 kg/m3
# (scaled by the solid fraction like grindtwin), platen speed 0.1 m/s, local damping 0.7.
# Yade's bonded rock model JCFpm (Scholtes & Donze 2012): linear bonds kn = 2 E R1 R2/(R1+R2),
# ks = poisson * kn = 0.4 kn, strengths times pi min(R)^2, stress-free at creation (initD),
# no bond moments; broken bonds become frictional linear contacts.
import json
import math
import sys
import time

pack, out = sys.argv[1], sys.argv[2]
script_args = dict(a.split("=", 1) for a in sys.argv[3:] if "=" in a)
plain = [a for a in sys.argv[3:] if "=" not in a]
dt_factor = float(plain[0]) if plain else 0.5  # O.dt = dt_factor * PWaveTimeStep()
rows = [list(map(float, l.split())) for l in open(pack) if l.strip() and not l.startswith("#")]
solid = float(open(pack).readline().split()[-1])
mat = O.materials.append(JCFpmMat(young=30e9, poisson=0.4, frictionAngle=math.radians(30),
                                  density=2700.0 / solid, tensileStrength=10e6, cohesion=20e6,
                                  label="rock"))
wmat = O.materials.append(FrictMat(young=210e9, poisson=0.3, frictionAngle=math.radians(30),
                                   density=7800, label="steel"))
for x, y, z, r in rows:
    O.bodies.append(sphere((x, y, z), r, material=mat))
zlo = min(z - r for x, y, z, r in rows)
zhi = max(z + r for x, y, z, r in rows)
bot = O.bodies.append(utils.wall(zlo, axis=2, sense=1, material=wmat))
top = O.bodies.append(utils.wall(zhi, axis=2, sense=-1, material=wmat))
O.bodies[top].state.vel = (0, 0, -0.1)
O.bodies[top].state.blockedDOFs = "xyzXYZ"
O.bodies[bot].state.blockedDOFs = "xyzXYZ"
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(aabbEnlargeFactor=1.3, label="aabb"), Bo1_Wall_Aabb()]),
    InteractionLoop(
        [Ig2_Sphere_Sphere_ScGeom(interactionDetectionFactor=1.3, label="ig2"), Ig2_Wall_Sphere_ScGeom()],
        [Ip2_JCFpmMat_JCFpmMat_JCFpmPhys(cohesiveTresholdIteration=1), Ip2_FrictMat_FrictMat_FrictPhys()],
        [Law2_ScGeom_JCFpmPhys_JointedCohesiveFrictionalPM(label="jcf"), Law2_ScGeom_FrictPhys_CundallStrack()]),
    NewtonIntegrator(damping=0.7),
]
O.dt = float(script_args["dt"]) if "dt" in script_args else dt_factor * PWaveTimeStep()
O.step()
aabb.aabbEnlargeFactor = 1.0
ig2.interactionDetectionFactor = 1.0
n_bonds = sum(1 for i in O.interactions if isinstance(i.phys, JCFpmPhys) and i.phys.isCohesive)
if "steps" in script_args:
    O.run(20, True)
    t0, c0 = time.time(), time.process_time()
    O.run(int(script_args["steps"]), True)
    with open(out, "w") as fh:
        fh.write(json.dumps({"steps": int(script_args["steps"]), "wall_s": time.time() - t0,
                             "cpu_s": time.process_time() - c0, "dt_s": O.dt, "n_bonds": n_bonds}))
    sys.exit(0)
rec = []
peak = 0.0
t0 = time.time()
steps = 0
every = int(script_args.get("every", 20))  # often enough to catch the peak (every 200 steps read 3543 N for 3611 N)
while True:
    O.run(every, True)
    steps += every
    ft = O.forces.f(top)[2]
    fb = -O.forces.f(bot)[2]
    disp = zhi - O.bodies[top].state.pos[2]
    rec.append((O.time, disp, ft, fb, jcf.nbTensCracks, jcf.nbShearCracks))
    peak = max(peak, ft)
    if peak > 0 and ft < 0.3 * peak and disp > 1.2 * max(r[1] for r in rec if r[2] == peak):
        break
    if disp > 0.15 * (zhi - zlo):
        break
wall = time.time() - t0
with open(out, "w") as fh:
    fh.write(f"# n_spheres {len(rows)} n_bonds {n_bonds} dt_s {O.dt} steps {steps} wall_s {wall}\n")
    fh.write("time_s,displacement_m,force_top_N,force_bottom_N,broken_tension,broken_shear\n")
    for r in rec:
        fh.write(",".join(f"{v:.9g}" for v in r) + "\n")
sys.exit(0)  # leave before Yade starts its interactive session
