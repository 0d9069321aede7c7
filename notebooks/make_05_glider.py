"""Write notebooks/05_glider.ipynb (run: python notebooks/make_05_glider.py).

The notebook is generated so it stays reviewable as code; outputs are not committed.
"""
from pathlib import Path

import nbformat as nbf

cells = []


def md(s):
    cells.append(nbf.v4.new_markdown_cell(s.strip()))


def code(s):
    cells.append(nbf.v4.new_code_cell(s.strip()))


md("""
# 05 — Underwater glider: launch study and launch optimisation (Divsalar et al.)

The spherical-nose glider of Divsalar et al. as a `shipid` protocol model (`glider`): Fossen's
equations in surge/heave/pitch, hull drag `C_D = a α² + b|α| + c`, lift `C_Lα`, moment
`C_Mα`, NACA0009 fins by the paper's aspect-ratio formulas (with the `V²` the paper's
fin-force formulas omit).  Depth `z` is positive down; the launch angle is measured from
the vertical.  See `docs/glider.md` for every reference area and correction.

`SHIPID_FAST=1` (set by the test that runs this notebook) shrinks the sweep and the optimiser.
""")
code("""
import os
import numpy as np
import pandas as pd
import matplotlib
import matplotlib.pyplot as plt
from shipid.models import get_model
from shipid.glider import launch, sweep, paper_reference_case, optimise_launch, launch_objective

FAST = os.environ.get("SHIPID_FAST") == "1"
model = get_model("glider")
model.describe()
""")
md("""
## The paper's reported launch

5 m/s, 45° from the vertical, fin 0°, CG 1 cm ahead of the centre of buoyancy: the paper
reports a maximum depth of 1.68 m and 4.73 m of horizontal travel.
""")
code("""
ref = paper_reference_case()
ref.round(3)
""")
code("""
alts = {
    "paper set (rho 1025, no added mass)": model,
    "fresh water (rho 1000)": model.with_params({"rho": 1000.0}),
    "with spheroid added mass": get_model("glider", "paper-added-mass"),
}
pd.DataFrame({k: paper_reference_case(m)[["max_depth_m", "horizontal_m", "depth_rel_diff", "horizontal_rel_diff"]]
              for k, m in alts.items()}).T.round(3)
""")
code("""
r = launch(5.0, 45.0, 0.0, 0.01)
ax = r.plot()
ax.set_title(f"max depth {r.max_depth_m:.2f} m, horizontal {r.horizontal_m:.2f} m, exit {r.exit_angle_deg:.0f} deg");
""")
md("""
## The paper's sweeps, one batch

Full factorial 7 speeds × 4 angles × 5 fin angles × 4 CG offsets = 560 launches in one
vectorised RK4 run (fast mode: 2 × 4 × 3 × 2 = 48).
""")
code("""
if FAST:
    res = sweep([3.0, 5.0], [15.0, 30.0, 45.0, 60.0], [0.0, 5.0, 10.0], [0.0, -0.01])
else:
    res = sweep()
df = res.summary()
print(res.message, f"({len(df)} launches)")
df.pivot_table(index="angle_deg", columns="fin_deg", values="horizontal_m",
               aggfunc="first").round(2) if FAST else df[df.cg_m == 0].pivot_table(
    index=["speed_m_s", "angle_deg"], columns="fin_deg", values="max_depth_m").round(2)
""")
code("""
five = df[(df.speed_m_s == 5.0) & (df.cg_m == 0.0)]
fig, axs = plt.subplots(1, 2, figsize=(10, 3.5))
for fin, g in five.groupby("fin_deg"):
    axs[0].plot(g.angle_deg, g.max_depth_m, "o-", label=f"fin {fin:g}")
    axs[1].plot(g.angle_deg, g.horizontal_m, "o-", label=f"fin {fin:g}")
axs[0].set_ylabel("max depth [m]"); axs[1].set_ylabel("horizontal travel [m]")
for a in axs:
    a.set_xlabel("launch angle from vertical [deg]")
axs[1].legend();
""")
code("""
tr = launch(5.0, [15.0, 30.0, 45.0, 60.0], 0.0, -0.01)
ax = tr.plot(); ax.legend(fontsize=7);
""")
md("""
## Optimiser

Differential evolution over speed, angle, fin and CG, each generation one batch.  The
objective is the max-min reading of the paper's "close to the maximum of each":
`J = min(depth / depth_ref, horizontal / horizontal_ref)`, penalised when the exit angle
exceeds 75°.
""")
code("""
if FAST:
    opt = optimise_launch(bounds={"speed": (5.0, 5.0), "cg_m": (0.0, 0.0)}, popsize=4, maxiter=3)
else:
    opt = optimise_launch(popsize=10, maxiter=30, progress=True)
pd.Series(opt.x).round(3), opt.launch[["max_depth_m", "horizontal_m", "exit_angle_deg", "J"]]
""")
code("""
paper = launch(5.0, 30.0, 5.0, [0.0, -0.01]).summary()
paper["J"] = launch_objective(paper, opt.depth_ref, opt.horizontal_ref)
paper[["angle_deg", "fin_deg", "cg_m", "max_depth_m", "horizontal_m", "exit_angle_deg", "J"]].round(3)
""")

md("""
## Identifying the hydrodynamic coefficients from a dive log

A noisy log of a launch (depth, pitch, DVL velocities, gyro; no position under water) and
the project's augmented-state EKF, starting from coefficients 40-100 % wrong.  The
diagnostics name what the manoeuvre leaves undetermined.
""")
code("""
from shipid.glider import dive_log, DEFAULT_SENSOR_STD
from shipid.identify import EKFIdentifier

est = ["a", "b", "c", "CL_alpha", "CM_alpha"]
logs = [dive_log(5.0, 45.0, 0.0, rng=11)] + ([] if FAST else [dive_log(3.0, 60.0, 8.0, rng=12)])
start = model.with_params({"a": 3.0, "b": 0.0, "c": 1.0, "CL_alpha": 3.5, "CM_alpha": 0.2})
idf = EKFIdentifier(start, estimate=est, init="model", meas_std=DEFAULT_SENSOR_STD,
                    prior_std={"a": 5.0, "b": 1.0, "c": 1.0, "CL_alpha": 5.0, "CM_alpha": 1.0},
                    initial_state_std={"x": 0.01, "z": 0.05, "theta": 0.05, "u": 1.0, "w": 0.3, "q": 0.5},
                    n_passes=1 if FAST else 2, substeps=4).fit(logs)
table = pd.DataFrame({"truth": model.params_series()[est], "estimate": idf.coef_[est], "sigma": idf.coef_std_[est]})
table["error/sigma"] = (table.estimate - table.truth) / table.sigma
table.round(4)
""")
code("""
idf.diagnostics_["correlation"].round(2), idf.diagnostics_["warnings"]
""")

nb = nbf.v4.new_notebook()
nb["cells"] = cells
nb["metadata"]["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
out = Path(__file__).with_name("05_glider.ipynb")
nbf.write(nb, out)
print(f"wrote {out}")
