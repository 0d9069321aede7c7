"""`shipid fit` on wind/current models: the fit recipe with the Esso Osaka study's setting as the default of
``lowspeed``; formats that declare their sensors' noise; the start current a result carries for `validate`."""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shipid.cli import main
from shipid.logs import TrialLog, read_log
from shipid.logs.schema import PRESETS, Schema, load_schema

DATA = Path(__file__).parents[1] / ".." / "shared" / "data" / "esso_osaka_frt"


def _esso(kind: str, n: int) -> list[Path]:
    if not DATA.is_dir():
        pytest.skip(f"Esso Osaka data not found at {DATA} (shared data set FRT-DS-ESSO)")
    return sorted((DATA / kind).glob("*.csv"))[:n]


def _read_esso(path: Path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the GNSS-freeze warnings of these runs
        return read_log(path, schema="esso-frt")


def test_schema_declares_sensor_noise():
    """A schema's ``meas_std`` (the facility's sensor noise, SI) is checked, kept by schema files and carried by
    the logs read with it; ``esso-frt`` declares the Esso Osaka study's values."""
    assert PRESETS["esso-frt"].meas_std == {"x": 0.01, "y": 0.01, "psi": 0.003, "u": 0.01, "v": 0.01, "r": 0.003}
    assert PRESETS["shipid"].meas_std == {}
    with pytest.raises(ValueError, match=r"meas_std\['x'\] = -1.*positive standard deviation"):
        Schema(name="s", meas_std={"x": -1})
    with pytest.raises(ValueError, match="meas_std must be a mapping"):
        Schema(name="s", meas_std=[0.1])
    d = PRESETS["esso-frt"].to_dict()
    assert d["meas_std"] == PRESETS["esso-frt"].meas_std and load_schema(d).meas_std == d["meas_std"]


def test_esso_logs_carry_the_schema_noise(tmp_path):
    (f,) = _esso("random", 1)
    lg = _read_esso(f)
    assert lg.meas_std == PRESETS["esso-frt"].meas_std
    assert lg.window(lg.time[0], lg.time[50]).meas_std == lg.meas_std
    p = tmp_path / "plain.csv"
    pd.DataFrame({"time": np.arange(50) * 0.1, "x": 0.0, "y": 0.0, "psi": 0.0, "u": 1.0, "v": 0.0, "r": 0.0,
                  "delta": 0.0, "n": 10.0}).to_csv(p, index=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        assert read_log(p).meas_std == {}


def test_sampling_uses_the_median_speed_of_logs_that_start_from_rest():
    """Step 2's time constant is taken at the speed the ship sails, not at the rest it starts from: the Esso
    Osaka turning runs start at 0.01 m/s, where the rule had given every 40th sample (4 s)."""
    from shipid.identify.recipe import choose_sampling
    from shipid.models import get_model

    m = get_model("kcs-response")
    t = np.arange(400) * 0.05
    u = np.concatenate([np.zeros(40), np.full(360, 1.7)])
    from_rest = TrialLog.from_arrays(t, name="r", u=u, v=np.zeros(400), r=np.zeros(400))
    moving = TrialLog.from_arrays(t, name="m", u=np.full(400, 1.7), v=np.zeros(400), r=np.zeros(400))
    k_rest, why = choose_sampling(m, [from_rest])
    assert "the median speed (the logs start from rest) of the logs, 1.7 m/s" in why
    assert k_rest == choose_sampling(m, [moving])[0]


def test_cli_fit_of_wind_current_model_is_the_study_setting(tmp_path, capsys):
    """`shipid fit --schema esso-frt --model lowspeed --wind --current` on three Esso runs estimates what the Esso
    Osaka study estimates, with the study's start, noise, sampling and substeps: the same coefficients as the
    study's own fit to 1e-9 (so the study's cross-validated errors are the CLI's); the result carries the runs'
    mean current, and `shipid validate` starts its replay and its predictions from it."""
    from shipid.environment import with_environment
    from shipid.models import get_model
    from studies import esso_osaka as S
    from shipid.validation.horizon import horizon_prediction

    files = _esso("random", 4)
    train, test = files[:3], files[3]
    out = tmp_path / "fit.json"
    rc = main(["fit", *map(str, train), "--schema", "esso-frt", "--model", "lowspeed", "--wind", "--current",
               "-o", str(out)])
    text = capsys.readouterr().out
    assert rc in (0, 3), text  # 3: not consistent with the noise model (the study's fits are not either)
    assert "recipe: sampling: 20 -- every 20th sample (2 s)" in text and "2 RK4 substeps" in text
    assert "schema meas_std" in text and "refinement: none" in text
    res = json.loads(out.read_text())
    # the study's fit of the same runs
    runs = [lg for lg in S.load_runs(S.DATA_DIR, ("random",)) if lg.name in {p.stem for p in train}]
    env0 = with_environment(get_model("lowspeed").with_params(S.PRIOR_PARAMS), wind="esso-osaka-3m",
                            current="constant")
    ident, _ = S._fit(env0, [S._frame(lg, 20) for lg in runs], S.ESTIMATE + S.ESTIMATE_WIND, 2)
    names = list(S.ESTIMATE + S.ESTIMATE_WIND)
    cli = res["coefficients"] if "coefficients" in res else res["coef"]
    got = np.array([cli[n] if not isinstance(cli[n], dict) else cli[n]["value"] for n in names], dtype=float)
    np.testing.assert_allclose(got, ident.coef_[names].to_numpy(float), rtol=1e-9)
    cs = res["settings"]["current_start"]
    mean = np.mean([(st.cx.iloc[0], st.cy.iloc[0]) for st in ident.states_], axis=0)
    np.testing.assert_allclose([cs["cx"], cs["cy"]], mean, rtol=1e-9, atol=1e-12)
    assert cs["n_logs"] == 3
    # validate: predictions from the fit's mean current
    val = tmp_path / "val.json"
    rc = main(["validate", str(out), str(test), "--schema", "esso-frt", "--horizon", "30", "--no-closed-loop",
               "-o", str(val)])
    err = capsys.readouterr().err
    assert rc == 0 and f"cx = {cs['cx']:.4g}" in err
    h = json.loads(val.read_text())[0]["horizon"][0]
    lg = _read_esso(test)
    from shipid.validation import resolve_model

    model, _ = resolve_model(out)
    mine = horizon_prediction(model, lg, horizons=(30.0,), initial={"cx": cs["cx"], "cy": cs["cy"]}).to_records()[0]
    zero = horizon_prediction(model, lg, horizons=(30.0,)).to_records()[0]
    assert h["position_error_median_m"] == pytest.approx(mine["position_error_median_m"], rel=1e-12)
    assert h["position_error_median_m"] != pytest.approx(zero["position_error_median_m"], rel=1e-6)
    # the replay starts with the same current
    from shipid.simulate import replay, replay_errors

    track = json.loads(val.read_text())[0]["track_rmse_m"]
    with_c = replay_errors(replay(model, lg.data, initial={"cx": cs["cx"], "cy": cs["cy"]}), lg.data).loc["track", "rmse"]
    without = replay_errors(replay(model, lg.data), lg.data).loc["track", "rmse"]
    assert track == pytest.approx(with_c, rel=1e-12) and track != pytest.approx(without, rel=1e-6)
    with pytest.raises(ValueError, match=r"initial: \['cz'\] are not states"):
        replay(model, lg.data, initial={"cz": 0.0})


def test_refinement_of_environment_models_is_refused_before_fitting(tmp_path, capsys):
    files = _esso("random", 1)
    rc = main(["fit", *map(str, files), "--schema", "esso-frt", "--model", "lowspeed", "--wind", "--current",
               "--refine", "metrics", "-o", str(tmp_path / "f.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "not available for models with wind or current" in err and "--refine none" in err
    assert not (tmp_path / "f.json").exists()


@pytest.mark.slow
def test_recipe_loro_reaches_the_study_numbers():
    """Leave-one-run-out through the product's path (`shipid fit` defaults on the files as the CLI reads them,
    `shipid validate --horizon` from the fit's mean current; :func:`recipe_loro`): the medians of the 30 s
    position error per run type are the study's (docs/environment.md: 0.243 / 0.430 / 0.184 / 0.205 m), so issue
    13's goals hold for a user's fit as they do for the study's -- met on turning, random, berthing (<= 0.3 /
    0.3 / 0.6 m), missed on zigzag (0.432 m, band: the measured value +-0.01 m, a regression check)."""
    from studies.esso_osaka import recipe_loro

    _esso("turning", 1)
    df = recipe_loro(DATA)
    assert len(df.run.unique()) == 32 and df.success.all() and df.n_blowups.sum() == 0
    med = {k: float(np.median(np.concatenate(g.errors.to_list())))
           for k, g in df[df.seconds == 30.0].groupby("run_type")}
    assert med["turning"] <= 0.3 and med["random"] <= 0.3 and med["berthing"] <= 0.6  # goals met
    measured = {"turning": 0.244, "zigzag": 0.432, "random": 0.184, "berthing": 0.206}  # measured once, the regression band's centre
    for k, v in measured.items():
        assert med[k] == pytest.approx(v, abs=0.01), (k, med[k])
    assert med["zigzag"] > 0.3  # goal missed (said in docs/environment.md)


def test_runs_with_the_propeller_astern_are_not_standard_manoeuvres():
    """Standard-manoeuvre metrics (and `shipid validate`'s measured/closed-loop comparison) are for turning
    circles and zigzags at the approach's engine setting: a run whose propeller goes astern after the execute
    (berthing, random runs) is said not to be one, instead of being read as a zigzag (it was, before)."""
    from shipid.manoeuvres import detect_manoeuvre, metrics

    d = np.radians(np.concatenate([np.zeros(10), np.full(40, 20.0), np.full(50, -20.0)]))
    assert detect_manoeuvre(d) == "zigzag"
    assert detect_manoeuvre(d, n=np.full(100, 10.0)) == "zigzag"
    n = np.concatenate([np.full(60, 10.0), np.full(40, -5.0)])
    with pytest.raises(ValueError, match=r"not a standard manoeuvre: the propeller runs astern after the execute "
                                         r"\(n from -5 to 10\).*--horizon"):
        detect_manoeuvre(d, n=n)
    n[:5] = -5.0  # astern before the execute only (e.g. stopping at the start): still a manoeuvre
    n[60:] = 10.0
    assert detect_manoeuvre(d, n=n) == "zigzag"
    (f,) = _esso("berthing", 1)
    with pytest.raises(ValueError, match="not a standard manoeuvre"):
        metrics(_read_esso(f))


def test_a_turn_with_a_brief_opposite_correction_is_a_turn():
    """A turning circle whose operator corrects briefly to the other side (the Esso Osaka turning runs: up to 8 %
    of the time beyond half the largest deflection) is a turn; a zigzag holds both sides (27 % or more)."""
    from shipid.manoeuvres import detect_manoeuvre

    turn = np.radians(np.concatenate([np.zeros(10), np.full(5, -20.0), np.full(95, 35.0)]))
    assert detect_manoeuvre(turn) == "turning"
    zz = np.radians(np.concatenate([np.zeros(10), np.full(30, 20.0), np.full(30, -20.0), np.full(30, 20.0)]))
    assert detect_manoeuvre(zz) == "zigzag"
    for f in _esso("turning", 12):
        lg = _read_esso(f)
        assert detect_manoeuvre(lg["delta"], n=lg["n"]) == "turning", f.name


def test_model_default_start_applies_to_names_not_to_a_callers_model(monkeypatch):
    """The model's recipe start (lowspeed: dgammaR 0.1225) replaces the default set's value when the model is named;
    a model object the caller built is the start the caller wants (unless ``start_defaults=True``)."""
    from dataclasses import replace

    from shipid.identify import recipe
    from shipid.models import get_model, model_class

    seen = []

    class Stop(Exception):
        pass

    def fake_sampling(model, logs):  # records the start model of step 2 and stops the fit there
        seen.append(float(model.params[model.param_index("dgammaR")]))
        raise Stop

    cls = model_class("lowspeed")
    monkeypatch.setattr(cls, "recipe_defaults", replace(cls.recipe_defaults, sampling=None))
    monkeypatch.setattr(recipe, "choose_sampling", fake_sampling)
    t = np.arange(100) * 0.1
    lg = TrialLog.from_arrays(t, name="a", ship={"lpp": 3.0}, x=t * 0.2, y=0 * t, psi=0 * t, u=0 * t + 0.2,
                              v=0 * t, r=0 * t, delta=0 * t, n=0 * t + 10)
    own = get_model("lowspeed").with_params({"dgammaR": 0.05})
    for model, kw in (("lowspeed", {}), (own, {}), (own, {"start_defaults": True})):
        with pytest.raises(Stop):
            recipe.fit_logs([lg], model, **kw)
    assert seen == [0.1225, 0.05, 0.1225]


def test_a_start_from_rest_is_not_a_standard_manoeuvre():
    """A standard turn or zigzag starts from a steady approach: a run whose rudder moves while the ship is still
    at rest (every Esso Osaka turning and zigzag run: 0.01-0.36 of the speed after it) has no meaningful execute,
    approach speed or advance (they had come out at 11-17 L of advance); the MARIN and KCS runs (1.0-2.6) pass."""
    from shipid.manoeuvres import metrics

    t = np.arange(0, 200, 0.5)
    delta = np.radians(np.where(t >= 20.0, 35.0, 0.0))
    r = np.where(t >= 20.0, 0.02, 0.0)
    psi = np.cumsum(r) * 0.5

    def log(u):
        x = np.cumsum(u * np.cos(psi)) * 0.5
        y = np.cumsum(u * np.sin(psi)) * 0.5
        return TrialLog.from_arrays(t, name="turn", ship={"lpp": 3.0}, x=x, y=y, psi=psi, u=u, v=0 * t, r=r,
                                    delta=delta, n=0 * t + 10)

    assert metrics(log(np.full(t.size, 0.3))).manoeuvre == "turning"
    from_rest = log(np.clip(t / 100.0, 0.0, 0.3))  # 0.2 m/s at the execute (20 s), 0.3 after: steady enough
    assert metrics(from_rest).manoeuvre == "turning"
    early = log(np.clip((t - 19.0) / 100.0, 0.0, 0.3))  # 0.01 m/s at the execute
    # (the execute is where the rudder left its approach angle, the sample before the step: 19.5 s)
    with pytest.raises(ValueError, match=r"turn: not a standard manoeuvre: the rudder moves at t = 19\.5 s at 0\.01 "
                                         r"m/s.*a start from rest, not a steady approach"):
        metrics(early)
    assert metrics(early, kind="turning").manoeuvre == "turning"  # asked for: computed (the study's steady part)
    (f,) = _esso("turning", 1)
    with pytest.raises(ValueError, match="a start from rest"):
        metrics(_read_esso(f))
