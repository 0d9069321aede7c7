"""Write notebooks/04_routing.ipynb (run: python notebooks/make_04_routing.py). Outputs are not committed."""
from pathlib import Path

import nbformat as nbf

cells = []
md = lambda s: cells.append(nbf.v4.new_markdown_cell(s))  # noqa: E731
code = lambda s: cells.append(nbf.v4.new_code_cell(s))  # noqa: E731

md("""# 04 Routing in currents

Two planners from the papers (Zwierzewicz; Li et al.):

* **Zermelo**: the time-optimal route of a constant-speed boat through a current, by Pontryagin's
  principle (Zwierzewicz) and by direct transcription (any field, including currents faster than the boat);
* **PSO**: energy-optimal USV paths around circular obstacles (Li et al.): DOPSO (shortest),
  EOPSO (least energy), OCPSO (replanning when the measured current changes).

`SHIPID_FAST=1` (used by the test) shrinks the swarms.""")
code("""import os
import numpy as np
import matplotlib.pyplot as plt
from shipid.routing import (paper_problem, solve_pmp, solve_transcription, extremal, math_from_course,
                            ZermeloProblem, VortexField, GridField, linear_shear)
from shipid.routing.zermelo import PAPER_TF_CLOSED_FORM_H
FAST = os.environ.get("SHIPID_FAST") == "1"
ITER = 40 if FAST else 120""")
md("""## Fields
All fields share one interface: `field.velocity(t, xy)` and `field.gradient(t, xy)` in an east/north frame.
Below: the paper's linear shear `w = (k y, 0)`, a Lamb-Oseen vortex and the same shear given on a grid.""")
code("""fig, axs = plt.subplots(1, 3, figsize=(13, 4))
bbox = (-1, 5, -3, 3)
linear_shear(-0.5).plot(bbox, ax=axs[0]); axs[0].set_title("linear shear k = -0.5 1/h [kn]")
VortexField(2.0, 1.0, (2, 0)).plot(bbox, ax=axs[1]); axs[1].set_title("Lamb-Oseen vortex")
x, y = np.linspace(-1, 5, 7), np.linspace(-3, 3, 7)
X, Y = np.meshgrid(x, y)
GridField(x, y, -0.5 * Y, 0 * Y).plot(bbox, ax=axs[2]); axs[2].set_title("gridded (bilinear)")
plt.tight_layout()""")
md("""## Zermelo: the paper's example
V = 0.5 kn, w = (0, k x1) in the paper's frame (x1 north, x2 east), k = -0.5 1/h, A = (-1.86, 3.66) nm.
Here: east/north frame, start (3.66, -1.86) nm.""")
code("""P = paper_problem()
r = solve_pmp(P)
q = solve_transcription(P, n=20)
print(f"PMP:           {r.time:.7f} h, u(0) = {np.degrees(r.course[0]):.3f} deg, u(tf) = {np.degrees(r.course[-1]):.3f} deg")
print(f"transcription: {q.time:.7f} h (relative difference {q.time / r.time - 1:.1e})")
print(f"straight line without current: {P.distance / P.speed:.3f} h")""")
md("""**The paper's 10.93 h.** The paper rounds the angles: with `alpha = 30 deg` (u(tf) = 210 deg) and u(0) = 345 deg its
closed form gives `tf = (cot(u0 - pi) - cot(alpha)) / k = 4 (1 + sqrt 3) = 10.928 h`. That extremal starts
about 0.004 nm from the printed A; the extremal through the printed A has u(0) = 344.98 deg and takes 10.9157 h.""")
code("""e = extremal(P, float(math_from_course(np.radians(210))), PAPER_TF_CLOSED_FORM_H)
print(f"extremal u(0)=345, u(tf)=210: time {PAPER_TF_CLOSED_FORM_H:.6f} h, starts at {e.xy[0].round(5)} nm, "
      f"{e.miss:.4f} nm from A, u(0) = {np.degrees(e.course[0]):.6f} deg")
fig, ax = plt.subplots(figsize=(6, 6))
linear_shear(-0.5).plot((-1, 5, -3, 2), n=13, ax=ax, color="0.7")
for th in np.radians(np.arange(-180, 180, 15)):
    try:
        f = extremal(P, th, 12.0, n=100)
        ax.plot(f.xy[:, 0], f.xy[:, 1], color="C7", lw=0.5)
    except ValueError:
        pass
r.plot(ax=ax, color="C0", lw=2, label=f"PMP {r.time:.4f} h")
ax.plot(q.xy[:, 0], q.xy[:, 1], "C1.", label=f"transcription {q.time:.4f} h")
ax.plot(*P.start, "ks"); ax.plot(0, 0, "k*")
ax.set_xlim(-1, 5); ax.set_ylim(-3, 2); ax.legend(); ax.set_xlabel("east [nm]"); ax.set_ylabel("north [nm]")
ax.set_title("extremals from the target (grey) and the time-optimal route")""")
md("""## A current faster than the boat
A vortex whose peak speed (about 1.5 m/s) exceeds the boat's 1 m/s. Fast marching needs the boat to outrun the
current everywhere; the PMP shooting and the direct transcription do not.""")
code("""f = VortexField(gamma=2 * np.pi * 300 * 1.5 / (1 - np.exp(-1)), rc=300.0)
Pv = ZermeloProblem(1.0, f, (-600.0, -250.0), (650.0, 200.0))
rv = solve_pmp(Pv)
qv = solve_transcription(Pv, n=30, guess=rv)
print(f"PMP {rv.time:.3f} s, transcription {qv.time:.3f} s, straight line in still water {Pv.distance:.1f} s")
ax = f.plot((-900, 900, -700, 700), n=15, color="0.7")
rv.plot(ax=ax); ax.plot(qv.xy[:, 0], qv.xy[:, 1], "C1."); ax.set_title("route through a strong vortex")""")
md("""## PSO: energy-optimal USV planning (Li et al.)
Start/goal, wind (from the east, 7 m/s) and current speed (1.2 m/s) are the paper's; the obstacle positions and
the current directions exist only in the paper's figures, so they are ours (`paper_scenario` docstring). The
paper's event times (minutes 8 and 32) are scaled by 0.1: with the paper's own thrust and drag curves the USV
makes 1.77 m/s through the water and the 305 m voyage lasts only a few minutes.""")
code("""from shipid.routing.pso import paper_scenario, compare_planners
pr = paper_scenario()
res = compare_planners(pr, rng=0, max_iter=ITER)
do, eo, oc = res["dopso"], res["eopso"], res["ocpso"]
print(f"DOPSO: {do.length:.1f} m, sailed energy {res['dopso_voyage'].total_energy:.0f} J")
print(f"EOPSO (t=0 field, sailed through the changing field): {eo.length:.1f} m, {res['eopso_voyage'].total_energy:.0f} J")
print(f"OCPSO: {oc.length:.1f} m, {oc.energy:.0f} J -> saving vs DOPSO {100 * res['saving_vs_distance_optimal']:+.2f} % (paper: +10.37 %)")
for ev in oc.events:
    print({k: (round(v, 1) if isinstance(v, float) else v) for k, v in ev.items()})""")
code("""fig, ax = plt.subplots(figsize=(5, 8))
for o in pr.obstacles:
    ax.add_patch(plt.Circle((o.x, o.y), o.radius, color="0.8"))
for r_ in pr.radii:
    ax.add_patch(plt.Circle(pr.start, r_, fill=False, ls=":", color="0.6"))
for name, pts, c in (("DOPSO", do.points, "k"), ("EOPSO t=0", eo.points, "0.5"), ("OCPSO", oc.points, "C3")):
    ax.plot(pts[:, 0], pts[:, 1], "-s", color=c, label=name, ms=4)
ax.set_aspect("equal"); ax.set_xlim(-150, 150); ax.set_ylim(-330, 20); ax.legend()
ax.set_xlabel("east [m]"); ax.set_ylabel("north [m]"); ax.set_title("dimension circles (dotted) and paths")""")
md("""## Plug-in: the leg speed and power of a shipid model
`ModelSpeedPower` takes any protocol model with a surge state `u` and an input `n`: the leg's through-water speed is
the root of the surge equation at the given rpm, and the power follows `P = c_P n^3` (stated; calibrate it from one
measured point). Here the `kcs-response` model (synthetic-truth set, 1.7 m/s at 10 rps).""")
code("""from shipid.models import get_model
from shipid.routing.energy import ModelSpeedPower
from shipid.routing.pso import USVProblem, Obstacle, plan_eopso, plan_dopso
from shipid.routing.fields import UniformField
vessel = ModelSpeedPower.calibrated(get_model("kcs-response"), 10.0, n_ref=10.0, power_ref=40.0)
print(vessel)
pm = USVProblem((0, 0), (0, -300), [Obstacle(10, -100, 25), Obstacle(-15, -200, 25)],
                current=UniformField(0.4, 0.0), vessel=vessel)
e1, d1 = plan_eopso(pm, rng=0, max_iter=ITER), plan_dopso(pm, rng=0, max_iter=ITER)
print(f"EOPSO {e1.energy:.0f} J in {e1.time:.1f} s over {e1.length:.1f} m; DOPSO {d1.energy:.0f} J over {d1.length:.1f} m")""")

nb = nbf.v4.new_notebook()
nb["cells"] = cells
nb["metadata"]["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
nbf.write(nb, Path(__file__).with_name("04_routing.ipynb"))
