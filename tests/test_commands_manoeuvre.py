"""CLI: shipid metrics / simulate / sweep (in-process through shipid.cli.main)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shipid.cli import main

MARIN = Path(__file__).parents[1] / ".." / "shared" / "data" / "kvlcc2_marin"


def test_metrics_on_marin_logs(tmp_path, capsys):
    if not MARIN.is_dir():
        pytest.skip(f"MARIN KVLCC2 data not found at {MARIN.resolve()}")
    files = [str(MARIN / f"MARIN_FREE_KVLCC2_{k}_m.dat") for k in ("tc_35", "zz_20")]
    out = tmp_path / "metrics.json"
    assert main(["metrics", *files, "--lpp", "320", "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert [d["file"] for d in doc] == files
    assert doc[0]["manoeuvre"] == "turning" and doc[0]["tactical_diameter_L"] == pytest.approx(3.07, abs=0.01)
    assert doc[1]["manoeuvre"] == "zigzag" and doc[1]["overshoot1_deg"] == pytest.approx(15.6, abs=0.15)
    assert "turning (port)" in capsys.readouterr().out
    # never overwrite without --force
    assert main(["metrics", files[0], "--lpp", "320", "-o", str(out)]) == 2
    assert "output exists" in capsys.readouterr().err
    assert main(["metrics", files[0], "--lpp", "320", "-o", str(out), "--force"]) == 0


def test_metrics_bad_input_is_one_line(tmp_path, capsys):
    bad = tmp_path / "log.csv"
    bad.write_text("time,psi,delta\n0,0,0\n1,0,0\n")
    assert main(["metrics", str(bad), "--lpp", "100"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("shipid metrics: error:") and "\n" not in err


def test_simulate_named_model_writes_csv_and_prints_metrics(tmp_path, capsys):
    out = tmp_path / "turn.csv"
    assert main(["simulate", "mmg:kvlcc2", "--turning", "35", "--side", "starboard", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "tactical_diameter_L=3.1" in text
    df = pd.read_csv(out)
    assert list(df.columns[:3]) == ["run", "time [s]", "x [m]"] and df["run"].unique().tolist() == [0]
    assert np.degrees(df["psi [rad]"].iloc[-1]) >= 540


def test_simulate_result_json_zigzag(tmp_path, capsys):
    res = tmp_path / "fit.json"
    res.write_text(json.dumps({"model": "mmg", "coef": {"Nr": -0.06}, "coef_std": {}}))
    assert main(["simulate", str(res), "--zigzag", "20/20", "--side", "port"]) == 0
    assert "overshoot1_deg=" in capsys.readouterr().out
    assert main(["simulate", str(res), "--zigzag", "20-20"]) == 2
    assert "give rudder/heading angles" in capsys.readouterr().err
    res.write_text(json.dumps({"coef": {}}))
    assert main(["simulate", str(res), "--turning", "35"]) == 2
    assert "no 'model' entry" in capsys.readouterr().err


def test_sweep_csv(tmp_path):
    out = tmp_path / "sweep.csv"
    assert main(["sweep", "mmg:kcs", "--rudder", "15,25", "--speed", "1.7,2.0", "-o", str(out)]) == 0
    df = pd.read_csv(out)
    assert len(df) == 4 and set(df.columns) >= {"rudder_deg [deg]", "speed [m/s]", "n [rps]", "tactical_diameter_L [Lpp]",
                                                "steady_diameter_L [Lpp]", "tactical_diameter [m]", "speed_loss [-]"}
    assert (df.groupby("speed [m/s]")["tactical_diameter_L [Lpp]"].apply(lambda s: s.iloc[0] > s.iloc[1])).all()
    # the two diameters agree: metres = Lpp units x the KCS model's Lpp
    ratio = df["tactical_diameter [m]"] / df["tactical_diameter_L [Lpp]"]
    assert ratio.min() == pytest.approx(ratio.max(), rel=1e-9)
    assert main(["sweep", "mmg:kcs", "--rudder", "a,b"]) == 2


def test_simulate_and_sweep_with_the_adaptive_integrator(tmp_path, capsys):
    def metrics(text):
        return dict(kv.split("=") for kv in text.split() if "=" in kv)

    assert main(["simulate", "mmg:kvlcc2", "--turning", "35", "--side", "starboard"]) == 0
    rk4 = metrics(capsys.readouterr().out)
    assert main(["simulate", "mmg:kvlcc2", "--turning", "35", "--side", "starboard", "--integrator", "dopri5", "--rtol", "1e-5"]) == 0
    dp = metrics(capsys.readouterr().out)
    for key in ("advance_L", "tactical_diameter_L", "steady_diameter_L"):
        assert float(dp[key]) == pytest.approx(float(rk4[key]), rel=5e-3), key
    out = tmp_path / "sweep.csv"
    assert main(["sweep", "mmg:kcs", "--rudder", "15,25", "--speed", "1.7", "--integrator", "dopri5", "-o", str(out)]) == 0
    assert len(pd.read_csv(out)) == 2
    assert main(["simulate", "mmg:kvlcc2", "--turning", "35", "--integrator", "dopri5", "--rtol", "0"]) == 2
    assert "--rtol" in capsys.readouterr().err
