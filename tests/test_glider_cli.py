"""``shipid glider launch`` / ``shipid glider optimise`` in-process."""
import json

import pandas as pd
import pytest

from shipid.cli import main


def test_launch_writes_summary_and_trajectory(tmp_path, capsys):
    out, traj = tmp_path / "out.json", tmp_path / "traj.csv"
    rc = main(["glider", "launch", "--speed", "5", "--angle", "45", "--fin", "0", "--cg", "0.01",
               "-o", str(out), "--trajectory", str(traj)])
    assert rc == 0
    doc = json.loads(out.read_text())
    for k in ("max_depth_m", "horizontal_m", "exit_angle_deg", "duration_s", "exit_speed_m_s"):
        assert isinstance(doc[k], float)
    assert doc["max_depth_m"] == pytest.approx(1.721, abs=0.005)
    assert doc["horizontal_m"] == pytest.approx(3.737, abs=0.005)
    assert doc["params"]["x_g"] == 0.01 and doc["model"] == "glider"
    df = pd.read_csv(traj)  # units in the header (z and depth positive down)
    assert list(df.columns) == ["time [s]", "x [m]", "z [m (down)]", "theta [rad]", "u [m/s]", "w [m/s]", "q [rad/s]",
                                "depth [m (down)]"]
    assert df["z [m (down)]"].iloc[-1] == 0.0 and df["z [m (down)]"].max() == pytest.approx(doc["max_depth_m"])
    assert "max depth 1.72" in capsys.readouterr().out
    # refuses to overwrite; --force overwrites
    assert main(["glider", "launch", "--speed", "5", "--angle", "45", "-o", str(out)]) == 2
    assert "output exists" in capsys.readouterr().err
    assert main(["glider", "launch", "--speed", "3", "--angle", "45", "-o", str(out), "--force"]) == 0
    assert json.loads(out.read_text())["speed_m_s"] == 3.0


def test_launch_with_a_fit_result_and_bad_inputs(tmp_path, capsys):
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"model": "glider", "coef": {"c": 0.9, "CL_alpha": 4.0}}))
    out = tmp_path / "o.json"
    assert main(["glider", "launch", "--speed", "5", "--angle", "45", "--model", str(fit), "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["params"]["c"] == 0.9 and doc["max_depth_m"] < 1.64     # more drag, less depth
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"model": "kcs-response", "coef": {}}))
    assert main(["glider", "launch", "--speed", "5", "--angle", "45", "--model", str(wrong), "-o", str(tmp_path / "x.json")]) == 2
    assert "expected 'glider'" in capsys.readouterr().err
    assert main(["glider", "launch", "--speed", "-2", "--angle", "45", "-o", str(tmp_path / "y.json")]) == 2
    err = capsys.readouterr().err
    assert "speed = -2.0" in err and "Traceback" not in err
    assert main(["glider", "launch", "--speed", "5", "--angle", "45", "--model", str(tmp_path / "none.json"), "-o", str(tmp_path / "z.json")]) == 2
    assert "not found" in capsys.readouterr().err
    assert not (tmp_path / "y.json").exists()


def test_optimise_writes_best(tmp_path):
    out = tmp_path / "best.json"
    rc = main(["glider", "optimise", "--speed", "5", "5", "--cg", "0", "0", "--fin", "0", "0",
               "--popsize", "3", "--maxiter", "2", "-o", str(out)])
    assert rc == 0
    doc = json.loads(out.read_text())
    assert doc["x"]["speed"] == 5.0 and 15.0 <= doc["x"]["angle_deg"] <= 60.0
    assert doc["objective"] <= 1.0 + 1e-9 and doc["settings"]["max_exit_angle_deg"] == 75.0
