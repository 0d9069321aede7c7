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
`mmg` on the turning circles and the 10/10 zigzags, and (4) predict the 20/20 zigzags they
have not seen, with the models' own closed-loop manoeuvres.

`SHIPID_FAST=1` (the test suite) fits one model on two decimated runs only."""),
    code("""import os
from pathlib import Path
import numpy as np, pandas as pd, matplotlib.pyplot as plt
import shipid
from shipid.studies import kvlcc2 as ks
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
    md("""## 3. Fit on tc±35 and zz±10, predict zz±20

Decimated to every 4th sample (0.54 s at full scale, still far below the ship's time
constants of ~40 s). The MMG fit re-identifies the linear and main non-linear hull
derivatives and the resistance with the EKF, with the rudder neutral angle `delta0` fixed at the
measured straight-course rudder (section 4); rudder and propeller interaction stay published.
It then refines them (and `delta0`) by output error on the training replays, with the training
runs' tactical diameters and overshoots in the objective (`ks.refine_fit`; `refine=None` gives the
EKF stage alone). The held-out zz±20 enter no fit."""),
    code("""if HAVE_DATA:
    dec = ks.load_runs(folder, decimate=8 if FAST else 4)
    setups = ["kcs-response"] if FAST else list(ks.DEFAULT_SETUPS)
    train = ("zz_10", "zz_-10") if FAST else ks.TRAIN
    tables, fits = {}, {}
    for name in setups:
        fit = ks.fit_model(name, dec, train=train, n_passes=1 if FAST else 2)
        fits[name] = fit
        print(f"{name}: {fit.message_}; warnings: {len(fit.diagnostics_['warnings'])}")
        tables[name] = ks.evaluate(fit.result(), runs, ks.TEST if FAST else ks.RUNS)
    summary = pd.concat(tables, names=["model"]).reset_index(level=0)
    display(summary.round(3))"""),
    md("""## 4. What each model achieves

Goals of the issue: first overshoot within 2° and second within 3° on the held-out 20/20
zigzags, tactical diameter within 5 % on the training turns. The measured tactical
diameters differ by 8.5 % between port and starboard (3.07 vs 3.33 L); a port/starboard
symmetric model therefore misses one side by at least 4 %. The asymmetry comes from the
propeller: the rudder that holds the ship straight before each execute is not zero
(`ks.neutral_rudder_angle`, +0.92° pooled over the training runs). `mmg` takes it as its
rudder neutral angle `delta0`, `response-nl` as the propeller terms `b0 n², c0 n²`."""),
    code("""if HAVE_DATA:
    print(f"neutral rudder angle of the training runs: {np.rad2deg(ks.neutral_rudder_angle(dec, train)):+.2f} deg")"""),
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
            z = zigzag(fit.to_model(), rudder_deg=20.0, speed=float(lg["u"][0]), first=first, lpp=320.0)
            df = z.member(0)
            t0 = z.metrics[0].to_dict().get("execute_time_s", 0.0) or 0.0
            ax.plot(df.index - t0, np.rad2deg(df["psi"]), label=f"{name} (closed loop)")
        ax.set_title(k); ax.set_xlabel("time from first execute [s]"); ax.set_ylabel("heading change [deg]")
    axs[0].legend()"""),
]
nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
nbf.write(nb, Path(__file__).with_name("02_validate_kvlcc2.ipynb"))
