"""Write notebooks/06_esso_osaka_wind.ipynb (run: python notebooks/make_06_esso_osaka_wind.py)."""
from pathlib import Path

import nbformat as nbf

nb = nbf.v4.new_notebook()
md, code = nbf.v4.new_markdown_cell, nbf.v4.new_code_cell
nb.cells = [
    md("""# 06 — Wind, current and low speed: the Esso Osaka outdoor runs

Measured free-running runs of the 3 m Esso Osaka model in an outdoor pond (FRT-DS-ESSO,
NAOE-5thLab, CC BY-NC-SA 4.0; Wakita et al. 2022, Miyauchi et al. 2022), read from
`../shared/data/esso_osaka_frt` (not part of the repository). We (1) look at the wind the
ship met, (2) predict with dead reckoning, the published KVLCC2 MMG set Froude-scaled to 3 m
and the unfitted `lowspeed` prior, (3) fit `lowspeed` with and without wind + current on some
runs and predict the others (multi-start open-loop prediction, starts every 5 s).

`SHIPID_FAST=1` (the test suite) uses two random runs, two folds and coarse decimation; the
full study is `python -m studies.esso_osaka` (docs/environment.md)."""),
    code("""import os
from pathlib import Path
import numpy as np, pandas as pd, matplotlib.pyplot as plt
from studies import esso_osaka as es
from shipid.environment import WindForce, apparent_wind
from shipid.validation.horizon import horizon_prediction, dead_reckoning

FAST = os.environ.get("SHIPID_FAST") == "1"
folder = Path("..") / ".." / "shared" / "data" / "esso_osaka_frt"
HAVE_DATA = folder.is_dir()
print("Esso Osaka data:", folder.resolve() if HAVE_DATA else "not found -- the rest of the notebook is skipped")"""),
    md("## 1. Wind: Fujiwara's coefficients for this ship, and the wind of one run"),
    code("""w = WindForce.esso_osaka_3m()
g = np.radians(np.arange(0, 181, 5))
CX, CY, CN = w.coefficients(g)
fig, ax = plt.subplots(figsize=(6, 3))
for c, lab in ((CX, "C_X"), (CY, "C_Y"), (CN, "C_N")):
    ax.plot(np.degrees(g), c, label=lab)
ax.set_xlabel("apparent wind from [deg, starboard +]"); ax.legend(); ax.grid(True)
if HAVE_DATA:
    runs = es.load_runs(folder, types=("random",), max_runs=1)
    d = runs[0].data
    V, ga = apparent_wind(d.wind_speed_true, d.wind_dir_true, d.psi, d.u, d.v)
    print("true wind speed: median %.2f m/s, ship speed median %.2f m/s" % (d.wind_speed_true.median(),
          np.hypot(d.u, d.v).median()))
    print("logged apparent wind vs converted true wind: median |dV| = %.1e m/s" % np.median(np.abs(V - d.wind_speed_rel)))"""),
    md("## 2. Open-loop prediction from the measured state, no fit"),
    code("""if HAVE_DATA:
    from shipid.models import get_model
    lg = runs[0]
    for name, m in {"dead reckoning": dead_reckoning(), "mmg kvlcc2 3 m": get_model("mmg", "kvlcc2", lpp=3.0),
                    "lowspeed prior": get_model("lowspeed")}.items():
        r = horizon_prediction(m, lg.data.iloc[::2])
        print(name, [(e["seconds"], round(e["position_error_median_m"], 3)) for e in r.to_records()])
    ax = r.plot(every=6)
    ax.set_title("lowspeed prior: 60 s predictions from every 30 s")"""),
    md("## 3. Fit with and without wind + current, predict held-out runs"),
    code("""if HAVE_DATA:
    # fast mode: two random runs, two folds, no per-type or calm-water fits; full: the documented 8-fold study
    kw = (dict(types=("random",), max_runs=2, folds=2, fit_every=20, eval_every=5, by_type=False, calm_water=(),
               turning=False) if FAST else dict(folds=8, fit_every=20))
    res = es.run_study(folder, progress=False, **kw)
    for H in (10.0, 30.0, 60.0):
        print(f"median position error after {H:g} s [m] (held-out runs)")
        display(res.table(H).round(3))
    display(res.currents.round(4))
    display(res.goals().round(3))"""),
    md("""## 4. Do the estimated currents follow the wind?

Each training run gets its own constant current in the fit. Projected on the run's mean air velocity
(where the true wind blows to), the estimated current pointed downwind in 27 of the 32 runs in the full
study (about 0.65 % of the wind speed): partly a wind-driven drift, partly a per-run absorber of
unmodelled force. A held-out run starts with the training runs' mean current; starting it with a
wind-driven current instead helped the turning runs and hurt the zigzags (
docs/environment.md), so the mean stays."""),
    code("""if HAVE_DATA:
    display(es.current_vs_wind(res, folder).round(4))"""),
    md("""## 5. The same from the command line

What a user runs on their own files: `shipid fit --wind --current` takes the study's setting as the
`lowspeed` recipe's defaults (estimate list, start, 2 s sampling, the `esso-frt` schema's sensor noise;
each step printed with its reason), and `shipid validate --horizon` predicts a run the fit has not seen
from its measured states and the fit's mean current. Leave-one-run-out through this path gives the
study's numbers (`es.recipe_loro`, docs/environment.md). Exit status 3 of the fit: flagged not
consistent with its noise model, as every fit on these runs (the a-priori noise levels are
conservative)."""),
    code("""if HAVE_DATA:
    import json, tempfile
    from shipid.cli import main
    files = sorted(str(p) for p in (folder / "random").glob("*.csv"))
    train, test = (files[:2], files[2]) if FAST else (files[:-1], files[-1])
    tmp = Path(tempfile.mkdtemp())
    rc = main(["fit", *train, "--schema", "esso-frt", "--model", "lowspeed", "--wind", "--current",
               "-o", str(tmp / "fit.json"), "--no-progress"])
    print("shipid fit exit status", rc)
    rc = main(["validate", str(tmp / "fit.json"), test, "--schema", "esso-frt", "--horizon", "10,30,60",
               "-o", str(tmp / "val.json"), "--no-progress"])
    print("shipid validate exit status", rc)
    for e in json.loads((tmp / "val.json").read_text())[0]["horizon"]:
        print(f"{e['seconds']:4.0f} s: median position error {e['position_error_median_m']:.3f} m "
              f"({e['n_starts']} starts, {e['n_blowups']} blow-ups)")"""),
]
Path(__file__).with_name("06_esso_osaka_wind.ipynb").write_text(nbf.writes(nb), encoding="utf-8")
