"""The Esso Osaka 3 m model's measured outdoor runs through the product: horizon prediction, and the
``fit`` / ``validate`` / ``sample`` commands on wind-and-current logs (the study that chose the defaults is
``studies/esso_osaka.py``, its tests are in ``studies/tests/``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parents[1] / ".." / "shared" / "data" / "esso_osaka_frt"

pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"Esso Osaka data set (FRT-DS-ESSO) not found at {DATA}")


def test_horizon_prediction_on_a_measured_run():
    from shipid.logs import read_log
    from shipid.validation.horizon import dead_reckoning, horizon_prediction

    lg = read_log(DATA / "berthing" / "berthing_12-Nov-2020_11_07_23.csv", schema="esso-frt")
    r = horizon_prediction(dead_reckoning(), lg)
    s = r.to_records()
    assert [e["seconds"] for e in s] == [10.0, 30.0, 60.0]
    assert s[0]["n_starts"] >= s[1]["n_starts"] >= s[2]["n_starts"] > 20
    assert s[0]["position_error_median_m"] < s[1]["position_error_median_m"] < s[2]["position_error_median_m"]
    # starts every 5 s: the first start is the first sample, the next 50 samples (5 s) later
    assert np.diff(r.start_times[:2])[0] == pytest.approx(5.0)
    with pytest.raises(ValueError, match="lacks input channel"):
        from shipid.environment import with_environment
        from shipid.models import get_model

        horizon_prediction(with_environment(get_model("lowspeed"), wind="esso-osaka-3m"), lg.data.drop(
            columns=["wind_speed_true"]))


def test_blowups_are_counted_not_dropped():
    from shipid.logs import read_log
    from shipid.models import get_model
    from shipid.validation.horizon import horizon_prediction

    lg = read_log(DATA / "random" / "random_31-Jul-2020_12_29_58.csv", schema="esso-frt")
    bad = get_model("lowspeed").with_params({"Nr": 3.0, "Yv": 2.0})  # unstable: yaw and sway amplify
    r = horizon_prediction(bad, lg.data.iloc[:1500], horizons=(30.0,))
    e = r.to_records()[0]
    assert e["n_blowups"] > 0 and not r.success and "blew up" in r.message
    assert e["n_starts"] == int(np.sum(~np.isnan(r.position_error[:, 0])))


@pytest.mark.slow
def test_cli_fit_wind_current_then_validate_and_report_with_horizons(tmp_path, capsys):
    import json

    import pandas as pd

    from shipid.cli import main

    src = DATA / "random" / "random_31-Jul-2020_12_29_58.csv"
    short = tmp_path / "random_short.csv"
    pd.read_csv(src).iloc[:900].to_csv(short, index=False)  # 90 s of a measured run, the file's own columns
    res = tmp_path / "fit.json"
    rc = main(["fit", str(short), "--schema", "esso-frt", "--model", "lowspeed", "--wind", "--current",
               "--estimate", "Yv,Nr,wY1", "--passes", "1", "--no-progress", "-o", str(res)])
    doc = json.loads(res.read_text())
    # 3: written, but flagged not consistent with its noise model (measured, pre-filtered channels with gusty wind)
    assert rc == 0 or (rc == 3 and doc["diagnostics"]["consistency"]["consistent"] is False)
    assert doc["model"] == "with-environment" and doc["model_options"]["current"] == "constant"
    assert doc["model_options"]["wind"]["A_L"] == pytest.approx(0.52038)
    out = tmp_path / "val.json"
    rc = main(["validate", str(res), str(short), "--schema", "esso-frt", "--horizon", "10,30", "--no-closed-loop",
               "-o", str(out)])
    assert rc == 0
    h = json.loads(out.read_text())[0]["horizon"]
    assert [e["seconds"] for e in h] == [10.0, 30.0]
    assert set(h[0]) == {"seconds", "position_error_median_m", "position_error_p90_m", "heading_error_median_deg",
                         "n_starts", "n_blowups"}
    assert h[0]["n_starts"] == 18 - 2 and h[1]["n_starts"] == 18 - 6  # starts every 5 s that reach the horizon
    html = tmp_path / "r.html"
    assert main(["report", str(res), str(short), "--schema", "esso-frt", "--horizon", "10", "--no-closed-loop",
                 "-o", str(html)]) == 0
    assert "Open-loop prediction from the measured state" in html.read_text()
    assert main(["validate", str(res), str(short), "--schema", "esso-frt", "--horizon", "ten", "-o",
                 str(tmp_path / "x.json")]) == 2
    assert "--horizon ten" in capsys.readouterr().err



def _wind_copies(tmp_path, rows: int):
    """The first ``rows`` samples of a measured random run, in the file's own columns, three times: as they are,
    without the true-wind columns (apparent wind only), and with no wind at all."""
    import pandas as pd

    raw = pd.read_csv(DATA / "random" / "random_31-Jul-2020_12_29_58.csv").iloc[:rows]
    orig, app, none = tmp_path / "orig.csv", tmp_path / "apparent_only.csv", tmp_path / "no_wind.csv"
    raw.to_csv(orig, index=False)
    true_cols = ["wind_velo_true [m/s]", "wind_dir_true [rad]"]
    raw.drop(columns=true_cols).to_csv(app, index=False)
    raw.drop(columns=true_cols + ["wind_velo_relative_mid [m/s]", "wind_dir_relative_mid [rad]"]).to_csv(
        none, index=False)
    return orig, app, none

def test_cli_validate_converts_an_apparent_wind_only_log_at_the_edge(tmp_path, capsys):
    """A wind-aware fit validated on a copy of a measured run without its true-wind columns: the true wind
    is converted from the apparent one in memory (said once on stderr), the horizon numbers equal those on
    the original file within the conversion's own error, the file is untouched; no wind at all: exit 2."""
    import hashlib
    import json

    from shipid.cli import main
    from shipid.environment.cli import add_true_wind
    from shipid.logs import read_log
    from shipid.validation import resolve_model
    from shipid.validation.horizon import horizon_prediction

    orig, app, none = _wind_copies(tmp_path, 400)  # 40 s
    sha = hashlib.sha256(app.read_bytes()).hexdigest()
    res = tmp_path / "fit.json"
    # the fit reads the apparent-only copy too (the esso-frt schema's wind columns are optional) and converts it
    rc = main(["fit", str(app), "--schema", "esso-frt", "--model", "lowspeed", "--wind", "--estimate", "Yv,Nr,wY1",
               "--passes", "1", "--no-progress", "-o", str(res)])
    assert rc in (0, 3) and res.is_file()  # 3: written, flagged inconsistent with its noise model (measured data)
    assert capsys.readouterr().err.count("`apparent_only.csv`: true wind converted from the apparent wind") == 1
    hz = {}
    for f in (orig, app):
        out = tmp_path / f"val_{f.stem}.json"
        assert main(["validate", str(res), str(f), "--schema", "esso-frt", "--horizon", "10,30", "--no-closed-loop",
                     "-o", str(out)]) == 0
        err = capsys.readouterr().err
        assert err.count("true wind converted") == (1 if f is app else 0)
        hz[f] = json.loads(out.read_text())[0]["horizon"]
    assert hashlib.sha256(app.read_bytes()).hexdigest() == sha  # the user's file is not touched

    # Tolerance from the data's own agreement: the converted true wind differs from the logged one by
    # eps = max |w_conv - w_true| / |w_true| (wind vectors; 6.5e-4 on this cut, median 5.8e-5; the same
    # relative to the apparent wind).  The wind force |w_A|^2 C(angle) then changes by at most
    # (2 + 5) eps relative: 2 eps from the square of the speed, 5 eps from the angle (C is a Fourier series
    # of degree 5 in it, wX5/wY5, and by Bernstein's inequality such a series changes by at most 5 x its
    # largest value per radian).  Each start's predicted position (heading) moves by about that fraction of
    # the wind's whole displacement of it (the prediction with the wind switched off), a start's error by
    # no more than its prediction, a median or p90 by no more than the largest start's error.  Allowed:
    # 7 eps x the largest displacement at that horizon.  Measured: up to 2.0 eps x it (heading, 30 s:
    # 3.2e-3 deg), positions 0.11 eps x it (9e-6 m).
    lg = read_log(orig, schema="esso-frt", consistency_checks=False).data
    conv = lg.drop(columns=["wind_speed_true", "wind_dir_true"])
    add_true_wind(conv)
    w_true = lg.wind_speed_true * np.exp(1j * lg.wind_dir_true)
    w_conv = conv.wind_speed_true * np.exp(1j * conv.wind_dir_true)
    eps = float(np.max(np.abs(w_conv - w_true) / np.abs(w_true)))
    assert 0 < eps < 2e-3, eps  # the logged apparent wind is the conversion of the true wind (docs: 6e-5 median)
    model, _ = resolve_model(res)
    assert "cx" not in model.state_names  # no start current: the library calls below start as validate does
    r = {w: horizon_prediction(model, f, horizons=(10.0, 30.0))
         for w, f in (("wind", lg), ("calm", lg.assign(wind_speed_true=0.0)))}
    dt = float(np.median(np.diff(lg.time)))
    ix, iy, ip = (model.state_index(s) for s in ("x", "y", "psi"))
    for j, (a, b) in enumerate(zip(hz[orig], hz[app])):
        assert a["seconds"] == b["seconds"] and a["n_starts"] == b["n_starts"] > 0 and b["n_blowups"] == 0
        kh = int(round(a["seconds"] / dt))
        counted = ~np.isnan(r["wind"].position_error[:, j])  # the starts that reach this horizon
        assert counted.sum() == a["n_starts"]
        d = r["wind"].tracks["x"][counted, kh] - r["calm"].tracks["x"][counted, kh]
        moved = {"position_error_median_m": np.max(np.hypot(d[:, ix], d[:, iy])),
                 "position_error_p90_m": np.max(np.hypot(d[:, ix], d[:, iy])),
                 "heading_error_median_deg": np.degrees(np.max(np.abs(d[:, ip])))}
        assert moved["position_error_median_m"] > 0.01  # the wind moves the predictions: the check is not empty
        for k, m in moved.items():
            assert abs(b[k] - a[k]) <= 7 * eps * m, (a["seconds"], k, a[k], b[k], eps, m)

    # neither true nor apparent wind: the house error (exit 2, one line naming the file and the columns)
    assert main(["validate", str(res), str(none), "--schema", "esso-frt", "--horizon", "10", "--no-closed-loop",
                 "-o", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "error: wind-aware model: `no_wind.csv` has no channel(s) ['wind_speed_true', 'wind_dir_true'], nor " \
           "['wind_speed_rel', 'wind_dir_rel']" in err and "--columns" in err and "Traceback" not in err
    assert not (tmp_path / "x.json").exists()



def test_cli_sample_converts_an_apparent_wind_only_log_at_the_edge(tmp_path, capsys):
    """`shipid sample` reads the logs as `validate` does: a wind-aware fit sampled on a copy of a measured run
    without its true-wind columns gets the true wind converted in memory (said once on stderr), the file is
    untouched and the samples are written; a copy with no wind at all stops with the house error (exit 2)."""
    import hashlib
    import json

    from shipid.cli import main

    _, app, none = _wind_copies(tmp_path, 300)  # 30 s
    sha = hashlib.sha256(app.read_bytes()).hexdigest()
    res = tmp_path / "fit.json"
    assert main(["fit", str(app), "--schema", "esso-frt", "--model", "lowspeed", "--wind", "--estimate", "Yv,Nr,wY1",
                 "--passes", "1", "--no-progress", "-o", str(res)]) in (0, 3)
    capsys.readouterr()
    out = tmp_path / "s.json"
    rc = main(["sample", str(res), str(app), "--schema", "esso-frt", "--walkers", "8", "--steps", "10", "--burn", "0",
               "--seed", "1", "--no-progress", "-o", str(out)])
    assert rc in (0, 1)  # 1: not converged (10 steps), written all the same
    assert capsys.readouterr().err.count("`apparent_only.csv`: true wind converted from the apparent wind") == 1
    assert hashlib.sha256(app.read_bytes()).hexdigest() == sha
    doc = json.loads(out.read_text())
    assert doc["names"] == ["Yv", "Nr", "wY1"] and np.isfinite(np.asarray(doc["samples"], dtype=float)).all()
    assert main(["sample", str(res), str(none), "--schema", "esso-frt", "--walkers", "8", "--steps", "10",
                 "--no-progress", "-o", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "`no_wind.csv` has no channel(s)" in err and "Traceback" not in err
    assert not (tmp_path / "x.json").exists()
