"""Write notebooks/02_validate_kvlcc2.ipynb (run: python notebooks/make_02_validate_kvlcc2.py)."""
from pathlib import Path

import nbformat as nbf

nb = nbf.v4.new_notebook()
md, code = nbf.v4.new_markdown_cell, nbf.v4.new_code_cell
nb.cells = [
    md("""# 02 — Validate identified models on measured KVLCC2 manoeuvres (MARIN, SIMMAN 2008)

Real free-running model tests, full scale (Lpp 320 m), read from `../shared/data/kvlcc2_marin`
(not part of the repository). We (1) compute the standard-manoeuvre metrics from the
measurements, (2) check the published MMG set, (3) fit `kcs-response`, `response-nl` and
`mmg` on the turning circles and the 10/10 zigzags with the same public calls `shipid fit`
makes, and (4) predict the 20/20 zigzags they have not seen, with the models' own
closed-loop manoeuvres.

`SHIPID_FAST=1` (the test suite) fits one model on two decimated runs only."""),
    code("""import os
from pathlib import Path
import numpy as np, pandas as pd, matplotlib.pyplot as plt
import shipid
from studies import kvlcc2 as ks
from shipid.manoeuvres import metrics

FAST = os.environ.get("SHIPID_FAST") == "1"
folder = Path("..") / ".." / "shared" / "data" / "kvlcc2_marin"
if not folder.is_dir():
    folder = Path.cwd().parents[1] / "shared" / "data" / "kvlcc2_marin"
HAVE_DATA = folder.is_dir()
print("MARIN data:", folder.resolve() if HAVE_DATA else "not found -- the rest of the notebook is skipped")"""),
    md("## 1. Metrics of the measured runs (logged reference point) vs the data README"),
    code("""if HAVE_DATA:
    runs = ks.load_runs(folder, decimate=1)
    rows = []
    for k, lg in runs.items():
        m = metrics(lg).to_dict()
        for c, v in ks.MEASURED_README[k].items():
            rows.append({"run": k, "metric": c, "shipid": round(m[c], 3), "README": v})
    display(pd.DataFrame(rows))"""),
    md("## 2. The published MMG KVLCC2 set (Yasukawa & Yoshimura 2015), Froude-scaled to 320 m"),
    code("""if HAVE_DATA:
    pub = shipid.get_model("mmg", "kvlcc2", lpp=320.0)
    names = ks.TEST if FAST else ks.RUNS
    display(ks.evaluate(pub, runs, names).round(3))"""),
    md("""## 3. Fit on tc±35 and zz±10, predict zz±20 -- the calls `shipid fit` / `shipid validate` make

`shipid.identify.recipe.fit_logs` is what `shipid fit` runs: the ship length from the logs, the sampling
step from the model's fastest time constant (here every 4th sample), the rudder neutral angle from the
straight approaches, staged start values, the EKF, then the output-error refinement with the training
runs' own tactical diameters and overshoots in the objective at weight 0.1 (each step is printed with its reason).
`shipid.validation.validate` is what `shipid validate` runs: the replay and each model's closed-loop
standard manoeuvre with the log's own rudder and check angles. The held-out zz±20 enter no fit."""),
    code("""if HAVE_DATA:
    from shipid.identify.recipe import fit_logs
    from shipid.validation import validate
    train = ("zz_10", "zz_-10") if FAST else ks.TRAIN
    setups = {"kcs-response": None} if FAST else {"kcs-response": None, "response-nl": None, "mmg": "kvlcc2"}
    rows, fits = [], {}
    for name, params in setups.items():
        fit = fit_logs([runs[k] for k in train], name, params, n_passes=1 if FAST else 2,
                       dt=8 if FAST else "auto", refine=None if FAST else "auto", log=print)
        fits[name] = fit
        for k, v in zip(ks.TEST, validate(fit.result(), [runs[k] for k in ks.TEST])):
            for c in ("overshoot1_deg", "overshoot2_deg"):
                m, p = v["measured"].get(c), v["standard"].get(c)
                rows.append({"model": name, "run": k, "metric": c, "measured": m, "predicted": p,
                             "error": None if (m is None or p is None) else p - m})
    summary = pd.DataFrame(rows)
    display(summary.round(3))"""),
    md("""## 4. What each model achieves

Goals of the issue: first overshoot within 2° and second within 3° on the held-out 20/20
zigzags, tactical diameter within 5 % on the training turns. The measured tactical
diameters differ by 8.5 % between port and starboard (3.07 vs 3.33 L); a port/starboard
symmetric model therefore misses one side by at least 4 %. The asymmetry comes from the
propeller: the rudder that holds the ship straight before each execute is not zero
(+0.92° over the straight approaches of the training runs). `mmg` takes it as its
rudder neutral angle `delta0`; `response-nl` holds its propeller terms `b0 n², c0 n²` at 0."""),
    code("""if HAVE_DATA:
    from shipid.identify.recipe import neutral_rudder_angle
    d0, n_logs = neutral_rudder_angle([runs[k] for k in train])
    print(f"neutral rudder angle of the training runs: {np.rad2deg(d0):+.2f} deg ({n_logs} straight approaches)")"""),
    code("""if HAVE_DATA:
    piv = summary.pivot_table(index=["run", "metric"], columns="model", values="error")
    display(piv.round(2))
    from shipid.manoeuvres import zigzag
    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    for ax, k in zip(axs, ks.TEST):
        lg = runs[k]
        d = lg["delta"] - lg["delta"][0]
        first = "starboard" if d[np.argmax(np.abs(d) > np.deg2rad(0.5))] > 0 else "port"
        te = lg.time[np.argmax(np.abs(d) > np.deg2rad(0.5))]
        ax.plot(lg.time - te, np.rad2deg(lg["psi"] - lg["psi"][0]), "k", lw=1.5, label="measured")
        for name, fit in fits.items():
            z = zigzag(fit.to_model(), rudder_deg=20.0, speed=float(lg["u"][0]), first=first)
            df = z.member(0)
            t0 = z.metrics[0].execute_time  # the simulated first execute [s]: both curves from their execute
            ax.plot(df.index - t0, np.rad2deg(df["psi"]), label=f"{name} (closed loop)")
        ax.set_title(k); ax.set_xlabel("time from first execute [s]"); ax.set_ylabel("heading change [deg]")
    axs[0].legend()"""),
]
nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
nbf.write(nb, Path(__file__).with_name("02_validate_kvlcc2.ipynb"))
