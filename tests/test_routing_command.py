"""``shipid route``: paper examples, JSON problems, outputs and error handling (in-process)."""
import json

import numpy as np
import pandas as pd
import pytest

from shipid.cli import main


def test_zermelo_paper(tmp_path, capsys):
    out = tmp_path / "z.json"
    assert main(["route", "paper-zermelo", "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["time_h"] == pytest.approx(10.9157305, rel=1e-7)
    assert doc["solvers"]["transcription"]["time_h"] == pytest.approx(doc["solvers"]["pmp"]["time_h"], rel=1e-6)
    df = pd.read_csv(tmp_path / "z.csv")
    # units in the header: the paper example is in nautical units (h, nm)
    assert list(df.columns) == ["t [h]", "x [nm]", "y [nm]", "heading_deg [deg]", "course_deg [deg]"]
    np.testing.assert_allclose(df[["x [nm]", "y [nm]"]].iloc[0], [3.66, -1.86], atol=1e-6)
    # never overwrite without --force
    before = out.read_text()
    assert main(["route", "paper-zermelo", "-o", str(out)]) == 2
    assert "output exists" in capsys.readouterr().err
    assert out.read_text() == before
    assert main(["route", "paper-zermelo", "-o", str(out), "--force", "--method", "pmp"]) == 0


def test_zermelo_json_problem_with_grid_csv(tmp_path):
    x = np.linspace(-1000, 3000, 9)
    y = np.linspace(-1000, 1000, 5)
    X, Y = np.meshgrid(x, y)
    pd.DataFrame({"x": X.ravel(), "y": Y.ravel(), "u": 2.0 + 0 * X.ravel(), "v": 0 * X.ravel()}).to_csv(
        tmp_path / "cur.csv", index=False)
    spec = {"type": "zermelo", "speed": 1.0, "start": [0, 0], "target": [1000, 500],
            "current": {"type": "grid_csv", "path": "cur.csv"}, "solver": "both", "n": 10}
    (tmp_path / "p.json").write_text(json.dumps(spec))
    assert main(["route", str(tmp_path / "p.json"), "-o", str(tmp_path / "r.json")]) == 0
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["time_h"] * 3600 == pytest.approx(500.0, rel=1e-7)  # |w| = 2 V: analytic 500 s
    df = pd.read_csv(tmp_path / "r.csv")  # an SI problem: s and m in the header
    assert list(df.columns)[:3] == ["t [s]", "x [m]", "y [m]"]
    assert df["t [s]"].iloc[-1] == pytest.approx(500.0, rel=1e-6)
    np.testing.assert_allclose(df[["x [m]", "y [m]"]].iloc[-1], [1000, 500], atol=1e-3)


def test_pso_json_problem_with_model_vessel(tmp_path):
    spec = {"type": "pso", "start": [0, 0], "goal": [0, -300],
            "obstacles": [{"x": 10, "y": -100, "radius": 25}, {"x": -15, "y": -200, "radius": 25}],
            "current": {"type": "uniform", "speed": 0.5, "direction_deg": 90},
            "wind": {"type": "uniform", "speed": 7, "direction_deg": 90, "convention": "from"},
            "vessel": {"type": "model", "model": "kcs-response", "n": 10, "power_coefficient": 0.04},
            "seed": 3, "max_iter": 60}
    (tmp_path / "p.json").write_text(json.dumps(spec))
    assert main(["route", str(tmp_path / "p.json"), "-o", str(tmp_path / "r.json")]) == 0
    doc = json.loads((tmp_path / "r.json").read_text())
    # constant power 40 W: energy = 40 W x time; no replanning in a steady field -> saving >= 0
    assert doc["energy_J"] == pytest.approx(40.0 * doc["time_s"], rel=1e-9)
    assert doc["saving_vs_distance_optimal"] >= -1e-5  # up to the PSO tolerance (~1e-5 relative at 60 iterations)
    df = pd.read_csv(tmp_path / "r.csv")
    assert set(df.planner) == {"ocpso", "dopso", "eopso"}
    assert {"x [m]", "y [m]"} <= set(df.columns)


def test_pso_vessel_from_a_fit_result_json(tmp_path):
    from shipid.models import get_model

    m = get_model("kcs-response")
    coef = dict(zip(m.param_names, m.params))
    coef["a9"] = coef["a9"] * 1.1  # steady speed -a9 n^2 / (a1 + a8 n) = 1.1 * 1.7 m/s at 10 rps
    (tmp_path / "fit.json").write_text(json.dumps({"model": "kcs-response", "coef": coef, "coef_std": {}}))
    spec = {"type": "pso", "start": [0, 0], "goal": [0, -300], "obstacles": [{"x": 10, "y": -100, "radius": 25}],
            "vessel": {"type": "model", "result": "fit.json", "n": 10, "power_coefficient": 0.04},
            "seed": 1, "max_iter": 40}
    (tmp_path / "p.json").write_text(json.dumps(spec))
    assert main(["route", str(tmp_path / "p.json"), "-o", str(tmp_path / "r.json")]) == 0
    doc = json.loads((tmp_path / "r.json").read_text())
    # still water: time = distance / (1.1 * 1.7 m/s)
    assert doc["time_s"] == pytest.approx(doc["distance_m"] / (1.1 * 1.7), rel=1e-9)


@pytest.mark.slow
def test_pso_paper(tmp_path):
    out = tmp_path / "p.json"
    assert main(["route", "paper-pso", "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    for key in ("energy_J", "distance_m", "saving_vs_distance_optimal"):
        assert np.isfinite(doc[key])
    assert doc["saving_vs_distance_optimal"] == pytest.approx(1 - doc["energy_J"] / doc["dopso"]["energy_J"])
    assert {"lon [deg]", "lat [deg]"} <= set(pd.read_csv(tmp_path / "p.csv").columns)


@pytest.mark.parametrize("spec, match", [
    ({"type": "zermelo", "speed": 1.0, "start": [0, 0]}, "missing key 'target'"),
    ({"type": "zermelo", "speed": "fast", "start": [0, 0], "target": [1, 1]}, "speed: expected a number"),
    ({"type": "zermelo", "speed": 1, "start": [0, 0], "target": [1, 1], "current": {"type": "tide"}}, "unknown field type"),
    ({"type": "pso", "start": [0, 0], "goal": [0, -300], "obstacles": [{"x": 0, "y": -100}]}, r"obstacles\[0\]: missing key 'radius'"),
    ({"type": "route"}, "'type' must be 'zermelo' or 'pso'"),
])
def test_bad_problem_files_exit_2_with_a_named_message(tmp_path, capsys, spec, match):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(spec))
    assert main(["route", str(p), "-o", str(tmp_path / "o.json")]) == 2
    err = capsys.readouterr().err
    assert "bad.json" in err or "problem" in err
    import re
    assert re.search(match, err), err
    assert not (tmp_path / "o.json").exists()


def test_missing_and_malformed_files(tmp_path, capsys):
    assert main(["route", str(tmp_path / "nope.json"), "-o", str(tmp_path / "o.json")]) == 2
    assert "no such problem file" in capsys.readouterr().err
    (tmp_path / "m.json").write_text("{not json")
    assert main(["route", str(tmp_path / "m.json"), "-o", str(tmp_path / "o.json")]) == 2
    assert "not valid JSON" in capsys.readouterr().err
    assert main(["route", "paper-zermelo", "-o", str(tmp_path / "o.txt")]) == 2
    assert "must be a .json" in capsys.readouterr().err


def test_route_progress_on_request_same_result_and_quiet_off_a_terminal(tmp_path, capsys):
    args = ["route", "paper-pso", "--seed", "1"]
    assert main([*args, "-o", str(tmp_path / "a.json")]) in (0, 1)
    assert capsys.readouterr().err == ""  # stderr is not a terminal here: no progress by default
    assert main([*args, "--progress", "-o", str(tmp_path / "b.json")]) in (0, 1)
    assert "route (PSO iterations)" in capsys.readouterr().err
    a, b = (json.loads((tmp_path / f"{k}.json").read_text()) for k in "ab")
    assert a["energy_J"] == b["energy_J"]  # the progress callback draws no random numbers
    assert main(["route", "paper-zermelo", "--progress", "-o", str(tmp_path / "z.json")]) == 0
    assert "route (Zermelo solvers)" in capsys.readouterr().err
