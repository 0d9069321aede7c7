"""Write notebooks/03_optimal_control.ipynb (run: python notebooks/make_03_optimal_control.py)."""
from pathlib import Path

import nbformat as nbf

cells = [
    nbf.v4.new_markdown_cell("""# 03 Time-optimal manoeuvres

Ghorbani et al. (Ghorbani, Salarieh, Assadian): minimum-time manoeuvres of a 7.95 m planing boat with two
vectored outboards, solved here with shipid's indirect method (costates + linear extended penalty,
steepest descent or BFGS) and a direct multiple-shooting method, plus a time-optimal turn of a
KCS response model as it comes out of `shipid fit`.

`SHIPID_FAST=1` (set by the test) uses coarse grids and skips scenarios 2-3."""),
    nbf.v4.new_code_cell("""import os
import numpy as np
import matplotlib.pyplot as plt
from shipid.models import get_model
from shipid.control import (bang_bang_straight, paper_problem, solve_direct, solve_indirect,
                            kcs_turn_problem)
FAST = os.environ.get("SHIPID_FAST") == "1"
boat = get_model("planing-boat")
boat.describe().head(8)"""),
    nbf.v4.new_markdown_cell("""## Savitsky resistance of the Table 1 hull
Planing range (Savitsky 1964 equilibrium, all validity limits met) above `planing_speed`; below it
the documented pre-planing bridge (ITTC-57 friction + residuary part matched in value and slope)."""),
    nbf.v4.new_code_cell("""R = boat.resistance
v = np.linspace(0, 25, 251)
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.plot(v, R(v) / 1e3, label="R_T (Savitsky + bridge)")
ax.axhline(7.5, ls="--", c="k", label="T_max = 7.5 kN")
ax.axvline(R.planing_speed, ls=":", c="gray", label=f"planing range from {R.planing_speed:.2f} m/s")
ax.set_xlabel("u [m/s]"); ax.set_ylabel("force [kN]"); ax.legend(); R.source"""),
    nbf.v4.new_markdown_cell("""## Scenario 1: rest to x = 300 m and stop
The switching curve in the u-x phase plane: full thrust forward from (0, 0), coasting backward from
(300 m, 0.5 m/s) -- "stopped" means |u| <= 0.5 m/s because the resistance vanishes like u^2 and an
unbraked hull never reaches u = 0 in finite time."""),
    nbf.v4.new_code_cell("""s = boat.params_series()
M = s["m"] - s["X_udot"]
b = bang_bang_straight(R, M, 7500.0, 300.0, 0.5)
b_paper = bang_bang_straight(lambda u: 1.10 * R(u), M, 7500.0, 300.0, 0.5)
print(f"analytic: switch at {b.switch_t:.2f} s, x = {b.switch_x:.1f} m, u = {b.switch_u:.2f} m/s; tf = {b.final_time:.2f} s")
print(f"paper:    switch at 37 s, x = 258 m, u = 9 m/s; tf = 53 s")
print(f"with R_T x 1.10: switch at {b_paper.switch_t:.1f} s, x = {b_paper.switch_x:.1f} m, u = {b_paper.switch_u:.2f} m/s; tf = {b_paper.final_time:.1f} s")
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.plot(b.accel[1], b.accel[2], label="full thrust from rest")
ax.plot(b.coast[1], b.coast[0], label="coasting to (300 m, 0.5 m/s)")
ax.plot(b.switch_x, b.switch_u, "ko", label="switch")
ax.set_xlabel("x [m]"); ax.set_ylabel("u [m/s]"); ax.legend();"""),
    nbf.v4.new_code_cell("""kw = dict(n_intervals=10, substeps=8) if FAST else {}
direct = solve_direct(paper_problem(1, **kw))
print(direct.method, direct.final_time, direct.switch_time, direct.max_constraint_violation, direct.message)
if not FAST:
    indirect = solve_indirect(paper_problem(1, **kw))
    print(indirect.method, indirect.final_time, indirect.switch_time, indirect.max_constraint_violation)
df = direct.to_pandas()
fig, axs = plt.subplots(1, 3, figsize=(12, 3))
axs[0].plot(df.index, df["x"]); axs[0].set_ylabel("x [m]")
axs[1].plot(df.index, df["u"]); axs[1].set_ylabel("u [m/s]")
axs[2].step(df.index, df["T"] / 1e3, where="post"); axs[2].set_ylabel("T [kN]")
for a in axs: a.set_xlabel("t [s]")"""),
    nbf.v4.new_markdown_cell("""## Scenarios 2 and 3: initial heading 90 and 180 deg
With the paper's limits (u <= 20 m/s, |p| <= 10 deg/s, |r| <= 15 deg/s, |phi| <= 20 deg,
|phi_p| <= 45 deg). These solves take minutes; skipped in fast mode."""),
    nbf.v4.new_code_cell("""def show(res):
    df = res.to_pandas()
    fig, axs = plt.subplots(2, 3, figsize=(12, 6))
    axs[0, 0].plot(df["x"], df["y"]); axs[0, 0].set_xlabel("x [m]"); axs[0, 0].set_ylabel("y [m]"); axs[0, 0].axis("equal")
    axs[0, 1].plot(df.index, df["u"], label="u"); axs[0, 1].plot(df.index, df["v"], label="v"); axs[0, 1].legend(); axs[0, 1].set_ylabel("m/s")
    for n in ("phi", "psi"):
        axs[0, 2].plot(df.index, np.degrees(df[n]), label=n)
    axs[0, 2].legend(); axs[0, 2].set_ylabel("deg")
    for n in ("p", "r"):
        axs[1, 0].plot(df.index, np.degrees(df[n]), label=n)
    axs[1, 0].legend(); axs[1, 0].set_ylabel("deg/s")
    axs[1, 1].step(df.index, df["T"] / 1e3, where="post"); axs[1, 1].set_ylabel("T [kN]")
    axs[1, 2].step(df.index, np.degrees(df["phi_p"]), where="post"); axs[1, 2].set_ylabel("phi_p [deg]")
    fig.suptitle(f"{res.problem.name}: {res.method}, tf = {res.final_time:.1f} s, max violation {res.max_constraint_violation:.1e}")

if not FAST:
    for k in (2, 3):
        show(solve_direct(paper_problem(k)))"""),
    nbf.v4.new_markdown_cell("""## A plan for an identified model
A KCS response model (here the synthetic-truth coefficients, as a `shipid fit` result would give them):
minimum-time 90 deg heading change with |delta| <= 35 deg, |d delta/dt| <= 16.8 deg/s, 5 <= n <= 13 rps."""),
    nbf.v4.new_code_cell("""fit = {"model": "kcs-response", "coef": get_model("kcs-response").params_series().to_dict()}
ship = get_model(fit["model"], fit["coef"])
pr = kcs_turn_problem(ship, n_intervals=8 if FAST else 20, substeps=2 if FAST else 4)
turn = solve_direct(pr, n_segments=2 if FAST else 5)
print(turn.final_time, turn.max_constraint_violation, turn.message)
df = turn.to_pandas()
fig, axs = plt.subplots(1, 3, figsize=(12, 3))
axs[0].plot(df["y"], df["x"]); axs[0].set_xlabel("y [m]"); axs[0].set_ylabel("x [m]"); axs[0].axis("equal")
axs[1].plot(df.index, np.degrees(df["psi"])); axs[1].set_ylabel("psi [deg]")
axs[2].step(df.index, np.degrees(df["delta"]), where="post"); axs[2].set_ylabel("delta [deg]")
for a in axs[1:]: a.set_xlabel("t [s]")"""),
    nbf.v4.new_markdown_cell("""The same transcription solved by IPOPT through CasADi (optional extra `pip install shipid[casadi]`;
the model's `rhs` enters as a CasADi callback with its protocol Jacobians)."""),
    nbf.v4.new_code_cell("""from shipid.control.ipopt import have_casadi
if have_casadi():
    turn_ip = solve_direct(pr, method="ipopt", n_segments=2 if FAST else 5)
    print(f"IPOPT {turn_ip.final_time:.3f} s ({turn_ip.nit} iterations) vs SLSQP {turn.final_time:.3f} s ({turn.nit}); "
          f"max violation {turn_ip.max_constraint_violation:.1e}")
else:
    print("CasADi not installed (pip install shipid[casadi]): IPOPT comparison skipped")"""),
]
nb = nbf.v4.new_notebook(cells=cells, metadata={"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}})
nbf.write(nb, Path(__file__).with_name("03_optimal_control.ipynb"))
