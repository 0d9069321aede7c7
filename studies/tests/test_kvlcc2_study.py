"""Hold-out validation on the measured MARIN KVLCC2 runs.

Fit on tc+-35 and zz+-10 with ``shipid fit`` (the fit recipe, default settings), predict zz+-20 with
``shipid validate`` (each model's closed-loop zigzag).  Goals: first overshoot within 2 deg and second
within 3 deg on the held-out zigzags, tactical diameter within 5 % on both turns.  The slow tests run the
two CLI commands as the README shows them and assert what each model reaches (goals where met, measured
bands where not); the numbers are in docs/validation.md.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from shipid.identify import recipe
from studies import kvlcc2 as ks

MARIN_DIR = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "kvlcc2_marin"


@pytest.fixture(scope="module")
def runs(request):
    if not MARIN_DIR.is_dir():
        pytest.skip(f"measured KVLCC2 data not found at {MARIN_DIR} (../shared/data/kvlcc2_marin beside the repo)")
    return ks.load_runs(MARIN_DIR), ks.load_runs(MARIN_DIR, decimate=4)


def marin_files(tmp_path, names) -> list[str]:
    """The MARIN runs ``names`` as files ``shipid fit`` reads in the models' rudder convention: the raw .dat
    files once the MARIN reader applies the convention itself (:func:`ks.rudder_sign` is +1 as read), else
    copies with the rudder flipped in ``tmp_path`` (the one place the tests flip it)."""
    import warnings

    from shipid.logs import TrialLog, read_log

    if not MARIN_DIR.is_dir():
        pytest.skip(f"measured KVLCC2 data not found at {MARIN_DIR} (../shared/data/kvlcc2_marin beside the repo)")
    out = []
    for k in names:
        path = MARIN_DIR / f"MARIN_FREE_KVLCC2_{k}_m.dat"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            lg = read_log(path)
        sign = ks.rudder_sign(lg)
        if sign > 0:
            out.append(str(path))
            continue
        ch = {c: lg[c] for c in lg.channels if c != "time"}
        ch["delta"] = sign * ch["delta"]
        out.append(str(TrialLog.from_arrays(lg.time, name=lg.name, ship=lg.ship, **ch).to_csv(tmp_path / f"{k}.csv")))
    return out


def test_symmetric_models_cannot_meet_5_percent_on_both_turns(runs):
    """The measured tactical diameters differ by 8.5 % between sides: a port/starboard symmetric
    model misses one of them by at least (3.33 - 3.07) / 2 / 3.2 = 4.1 %."""
    full, _ = runs
    from shipid.manoeuvres import metrics

    td = {k: metrics(full[k]).to_dict()["tactical_diameter_L"] for k in ("tc_35", "tc_-35")}
    spread = abs(td["tc_35"] - td["tc_-35"]) / np.mean(list(td.values()))
    assert 0.07 < spread < 0.10


def test_neutral_rudder_angle_of_the_straight_approaches(runs):
    """The rudder that holds the ship straight before each execute: +0.92 deg (models' sign) pooled over
    the four training runs, on the side that makes the turn with negative rudder (MARIN tc_35) the
    tighter one -- as measured (3.07 L vs 3.33 L); found from the data (straight approaches), not names."""
    full, dec = runs
    d0 = np.degrees(ks.neutral_rudder_angle(full))
    assert 0.85 < d0 < 1.0, d0
    assert abs(np.degrees(ks.neutral_rudder_angle(dec)) - d0) < 0.05
    assert abs(full["tc_35"]["delta"].min() - np.radians(-35.0)) < np.radians(0.3)  # tc_35 is the negative-rudder turn
    lg = type(full["tc_35"]).from_arrays(np.arange(10.0), name="x", delta=np.linspace(0, 0.5, 10))
    with pytest.raises(ValueError, match="no log has a straight approach"):
        recipe.neutral_rudder_angle([lg])
    # a turning approach is not straight: left out
    turning = type(full["tc_35"]).from_arrays(np.arange(10.0), name="t", delta=np.r_[np.zeros(5), np.full(5, 0.3)],
                                              psi=np.radians(np.arange(10.0)))
    assert recipe.approach_segment(turning) is None and recipe.approach_segment(full["zz_10"]) is not None


def test_recipe_sampling_step_from_the_time_constants(runs):
    """The MARIN runs (0.135 s) at the mmg KVLCC2 model's fastest time constant (13.7 s at 8 m/s):
    every 2nd sample (>= 50 steps per time constant for mmg, chosen by leave-one-run-out, ``ks.LORO_RULE``;
    every 4th at the other models' 25)."""
    from shipid.models import get_model

    full, _ = runs
    k, why = recipe.choose_sampling(get_model("mmg", "kvlcc2", lpp=320.0), [full[n] for n in ks.TRAIN])
    assert k == 2 and "13.7 s" in why and ">= 50 steps" in why
    assert recipe.choose_sampling(get_model("mmg", "kvlcc2", lpp=320.0), [full[n] for n in ks.TRAIN],
                                  samples_per_tau=25)[0] == 4


def test_common_grid_pads_shorter_runs_with_missing_samples():
    """Two runs of different lengths and time stamps on one grid from each run's start: interpolated
    inside, measured channels NaN past a run's end, inputs held; bad step refused."""
    from shipid.logs import TrialLog

    t1, t2 = 100.0 + np.arange(0.0, 10.01, 0.5), np.arange(0.0, 4.01, 0.25)
    runs = {"a": TrialLog.from_arrays(t1, name="a", u=2.0 + 0.1 * (t1 - 100), delta=0.01 * (t1 - 100), n=np.full(t1.size, 1.5)),
            "b": TrialLog.from_arrays(t2, name="b", u=3.0 - 0.2 * t2, delta=0.02 * t2, n=np.full(t2.size, 1.0))}
    a, b = ks.common_grid(runs, ("a", "b"), dt=1.0)
    np.testing.assert_allclose(a.time, np.arange(11.0))
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_allclose(a["u"], 2.0 + 0.1 * a.time)
    np.testing.assert_allclose(b["u"][:5], 3.0 - 0.2 * np.arange(5.0))
    assert np.isnan(b["u"][5:]).all() and b["delta"][5:] == pytest.approx(0.08) and (b["n"] == 1.0).all()
    with pytest.raises(ValueError, match="dt must be a positive"):
        ks.common_grid(runs, ("a",), dt=0.0)


def test_recipe_options_are_checked_before_fitting(runs):
    _, dec = runs
    with pytest.raises(ValueError, match="refine='ekf'"):
        ks.fit_model("mmg", dec, refine="ekf")
    with pytest.raises(ValueError, match="start='seed'"):
        ks.fit_model("mmg", dec, start="seed")


def test_metric_residuals_match_evaluate_and_batch(runs):
    """The closed-loop metric errors the refinement fits, for the published MMG set: a batch of parameter
    sets gives the single-set rows, and the zigzag errors equal evaluate()'s divided by the goal tolerances."""
    from shipid.models import get_model

    _, dec = runs
    pub = get_model("mmg", "kvlcc2", lpp=320.0)
    f = ks.metric_residuals(pub, dec, names=("tc_35", "zz_10"))
    one = f(pub.params)
    P = np.stack([pub.params, pub.params * np.where(np.array(pub.param_names) == "Nr", 1.05, 1.0)])
    both = f(P)
    assert one.shape == (3,) and both.shape == (2, 3)
    np.testing.assert_allclose(both[0], one, atol=1e-4)  # 1e-4 goal tolerances: the batch ends its chunks elsewhere
    assert np.all(np.abs(both[1] - one) > 1e-3)  # Nr moves every metric
    tab = ks.evaluate(pub, dec, names=("zz_10",)).set_index("metric")["error"]
    np.testing.assert_allclose(one[1:], [tab["overshoot1_deg"] / 2.0, tab["overshoot2_deg"] / 3.0], atol=1e-6)


def test_cli_fit_carries_the_logs_particulars_through_refinement(tmp_path, capsys):
    """``shipid fit`` on a MARIN zigzag (320 m) with kcs-response: the start is the shipped 4.36 m set
    Froude-scaled to the logs' 320 m, the refined result states Lpp 320 m (model options and ship),
    ``shipid simulate r.json --turning 35`` simulates the 320 m ship with no --lpp, and the refined result
    reloads from JSON to the same model."""
    from shipid.cli import main
    from shipid.identify.result import FitResult, load_result
    from shipid.logs import TrialLog, read_log
    from shipid.manoeuvres import ship_info, turning_circle

    (path,) = marin_files(tmp_path, ["zz_10"])
    lg = read_log(path)
    keep = np.arange(0, lg.time.size, 4)[lg.time[::4] <= 260.0]
    short = TrialLog.from_arrays(lg.time[keep], name=lg.name, ship=lg.ship,
                                 **{c: lg[c][keep] for c in lg.channels if c != "time"}).to_csv(tmp_path / "short.csv")
    out = tmp_path / "r.json"
    # sway/yaw re-identified, surge kept from the (scaled) start: a 260 s zigzag does not determine the surge terms
    code = main(["fit", str(short), "--model", "kcs-response", "--estimate", "b1,b2,b3,b4,c1,c2,c3", "--passes", "1",
                 "--refine", "--every", "1", "--no-progress", "-o", str(out)])
    res = load_result(out)
    # 3: the refinement hit its evaluation limit, which the verdict names; the result is written either way
    assert code == 0 or (code == 3 and any("did not converge" in r for r in res.verdict.reasons))
    assert res.method == "output-error"
    assert res.model_options["lpp"] == 320.0 and res.ship["lpp"] == 320.0 and res.ship["name"] == "KVLCC2"
    assert res.model_options["design_speed"] == pytest.approx(7.974)  # the logs' particulars
    assert [s["step"] for s in res.settings["recipe"]][:2] == ["ship", "sampling"]
    model = res.to_model()
    assert ship_info(model)["lpp"] == 320.0
    again = FitResult.from_dict(json.loads(out.read_text()))
    assert again.to_dict() == res.to_dict()
    np.testing.assert_array_equal(again.to_model().params, model.params)
    capsys.readouterr()
    main(["simulate", str(out), "--turning", "35", "--side", "starboard"])
    assert "turning" in capsys.readouterr().out  # the 320 m ship simulated (a 260 s fit: not a good model)
    run = turning_circle(model, 35.0, side="starboard", heading_change_deg=200.0)
    assert run.metrics[0].lpp == 320.0 and run.settings["speed"].iloc[0] == pytest.approx(7.974)
    # asked for another ship: Froude-scaled to it (and said so)
    main(["simulate", str(out), "--turning", "35", "--side", "starboard", "--lpp", "7.0"])
    assert "Froude-scaled from Lpp 320 m to 7 m" in capsys.readouterr().err


# ----------------------------------------------------------------------------- the CLI route (README)
def _cli_fit_validate(tmp_path, model, params=None, extra=()):
    """``shipid fit`` on tc+-35, zz+-10 with default settings, then ``shipid validate`` on zz+-20 and tc+-35 (the
    README's two commands);
    returns {run: {metric: error}} of the closed-loop standard manoeuvres (TD in %, overshoots in deg)
    and the result."""
    from shipid.cli import main
    from shipid.identify.result import load_result

    files = dict(zip(ks.RUNS, marin_files(tmp_path, ks.RUNS)))
    out, val = tmp_path / "r.json", tmp_path / "v.json"
    args = ["fit", *[files[k] for k in ks.TRAIN], "--model", f"{model}:{params}" if params else model, "-o", str(out),
            "--no-progress"]
    args += list(extra)
    # 3: done, but the EKF stage is not consistent with its noise model -- on these measured runs it is
    # flagged (x innovations ~2x the model's, not white, ~12 % gated: model error), said on stderr and in
    # the result; the fit is still written and used
    assert main(args) in (0, 1, 3)
    shown = ("zz_20", "zz_-20", "tc_35", "tc_-35")  # the README's validate command
    assert main(["validate", str(out), *[files[k] for k in shown], "-o", str(val)]) in (0, 1)
    res = load_result(out)
    assert [m["name"] for m in res.inputs] == [f"MARIN_FREE_KVLCC2_{k}_m" for k in ks.TRAIN]  # zz+-20 never enter
    errs = {}
    for k, v in zip(shown, json.loads(val.read_text())):
        m, s = v["measured"], v["standard"]
        if k.startswith("tc"):
            td = s.get("tactical_diameter_L")
            errs[k] = {"TD": np.nan if td is None else 100 * (td - m["tactical_diameter_L"]) / m["tactical_diameter_L"]}
        else:
            assert m["switch_deg"] == m["rudder_deg"] and m["check_source"] == "log"  # 10/10, 20/20 read from the logs
            errs[k] = {c: np.nan if s.get(c) is None else s[c] - m[c] for c in ("overshoot1_deg", "overshoot2_deg")}
    print(json.dumps(errs, indent=1))
    return errs, res


@pytest.mark.slow
def test_cli_mmg_default_recipe_on_the_holdout(tmp_path):
    """README: ``shipid fit tc_35 tc_-35 zz_10 zz_-10 --model mmg -o r.json`` then ``shipid validate r.json
    zz_20 zz_-20 tc_35 tc_-35``.  The recipe: every 2nd sample (tau 13.7 s, >= 50 steps per time constant),
    delta0 +0.90 deg from the straight approaches, EKF on eight hull terms, R0, the side-dependent wake
    correction C2p, C2m and the rudder-hull interaction aH, xH, metric-augmented refinement at weight 0.1,
    nothing held by the identifiable subset -- each chosen by leave-one-run-out within the training runs
    (``ks.LORO_RULE``; the numbers are in ``studies/kvlcc2.py``).  Measured (one BLAS thread, as the recipe
    runs): TD +0.93 % / -2.01 %; held-out zz_20 +2.31 / +4.18 deg, zz_-20 +2.19 / +5.06 deg -- two of the six
    goals; without aH, xH five of six (+1.42 / -1.08 %, +1.62 / +2.65, +1.71 / +3.03 deg).  The rule does not
    let the hold-out feed back, so the default stays as leave-one-run-out chose it (docs/validation.md).
    The bands are centred on that one measurement, as a regression check."""
    errs, res = _cli_fit_validate(tmp_path, "mmg")
    steps = {s["step"]: s["value"] for s in res.settings["recipe"]}
    assert steps["sampling"] == 2 and steps["neutral rudder angle"] == pytest.approx(0.904, abs=0.01)
    assert steps["refinement"] == "metrics" and res.method == "output-error" and res.success
    assert "weight 0.1" in next(s["reason"] for s in res.settings["recipe"] if s["step"] == "metric residuals")
    assert res.settings["metric_weight"] == 0.1 and res.settings["held"] == []
    assert {"C2p", "C2m", "aH", "xH"} <= set(res.coef) and 1.0 < res.coef["C2p"] < 1.2 and 1.0 < res.coef["C2m"] < 1.3
    assert 0.4 < res.coef["aH"] < 0.65 and -0.3 < res.coef["xH"] < -0.05    # measured 0.512, -0.164
    assert -0.1 < errs["tc_35"]["TD"] < 1.9                                    # goal met (+0.93 %)
    assert -3.0 < errs["tc_-35"]["TD"] < -1.0                                  # goal met (-2.01 %)
    assert 1.8 < errs["zz_20"]["overshoot1_deg"] < 2.8                         # goal missed (+2.31)
    assert 3.5 < errs["zz_20"]["overshoot2_deg"] < 4.9                         # goal missed (+4.18)
    assert 1.7 < errs["zz_-20"]["overshoot1_deg"] < 2.7                        # goal missed (+2.19)
    assert 4.3 < errs["zz_-20"]["overshoot2_deg"] < 5.8                        # goal missed (+5.06)


@pytest.mark.slow
def test_cli_mmg_metric_refinement_on_the_holdout(tmp_path):
    """The same with ``--refine metrics --metric-weight 1`` (the training metrics at full weight; not the
    default: leave-one-run-out worst fold 1.885 against 0.945 at weight 0.1 with ten estimated coefficients,
    5.34 against 1.96 with eight).  Measured (C2p, C2m, aH, xH estimated, one BLAS thread): TD +0.10 % /
    -0.18 %, zz_20 +2.65 / +3.55 deg, zz_-20 +2.07 / +4.71 deg -- two of the six goals (a report, not a
    choice).  Bands centred on that one measurement."""
    errs, res = _cli_fit_validate(tmp_path, "mmg", extra=["--refine", "metrics", "--metric-weight", "1"])
    assert res.method == "output-error" and res.success and res.settings["metric_weight"] == 1.0
    assert -0.9 < errs["tc_35"]["TD"] < 1.1                                    # goal met (+0.09 %)
    assert -1.2 < errs["tc_-35"]["TD"] < 0.8                                   # goal met (-0.17 %)
    assert 2.1 < errs["zz_20"]["overshoot1_deg"] < 3.1                         # goal missed (+2.65)
    assert 2.9 < errs["zz_20"]["overshoot2_deg"] < 4.2                         # goal missed (+3.55)
    assert 1.5 < errs["zz_-20"]["overshoot1_deg"] < 2.6                        # goal missed (+2.07)
    assert 4.1 < errs["zz_-20"]["overshoot2_deg"] < 5.3                        # goal missed (+4.71)


@pytest.mark.slow
def test_cli_response_nl_default_recipe_on_the_holdout(tmp_path):
    """``shipid fit <tc+-35, zz+-10> --model response-nl -o r.json`` then ``shipid validate``: the default recipe
    (every 3rd sample, staged start from a kcs-response seed fitted up to 10 deg drift, 26 terms, metrics at
    weight 0.1, nothing held by the identifiable subset) with the own-damping constraint (step 6b: the
    unconstrained refinement had b1 +0.0177 and self-excited sway on 17 % of the logged states and at rest;
    constrained b1 < 0).  A physical requirement, not chosen by a score.  Measured, starting from the
    stern-rudder kcs-response set: TD +4.26 % / -5.10 %, zz_20 +0.85 / +7.95 deg, zz_-20 +4.00 / +4.09 deg -- two
    of the six goals (tc_35, zz_20's first overshoot).  The refinement is ill-conditioned on these runs: the
    start set moves its optimum (a3 -1896 from the earlier start set, +2848 from this one).  (A report, not a
    choice.)  The same answer to the bit with one and two BLAS threads (the recipe runs with
    one)."""
    errs, res = _cli_fit_validate(tmp_path, "response-nl")
    steps = {s["step"]: s["value"] for s in res.settings["recipe"]}
    assert steps["refinement"] == "metrics" and res.method == "output-error" and res.success
    assert steps["sampling"] == 3 and res.settings["held"] == []
    assert steps["physical damping"] is True and res.coef["b1"] < 0
    assert 3.2 < errs["tc_35"]["TD"] < 5.2                                     # goal met (+4.26 %)
    assert -6.2 < errs["tc_-35"]["TD"] < -4.2                                  # goal missed at its edge (-5.10 %)
    assert -0.2 < errs["zz_20"]["overshoot1_deg"] < 1.8                        # goal met (+0.85)
    assert 7.0 < errs["zz_20"]["overshoot2_deg"] < 9.0                         # goal missed (+7.95)
    assert 3.0 < errs["zz_-20"]["overshoot1_deg"] < 5.0                        # goal missed (+4.00)
    assert 3.1 < errs["zz_-20"]["overshoot2_deg"] < 5.1                        # goal missed (+4.09)


def test_leave_one_run_out_of_refinements_scores_each_variant_on_one_ekf_stage():
    """studies.kvlcc2.leave_one_run_out_refinements on the bundled KCS logs (one fold: fit on the turn
    and one zigzag, predict the other zigzag): one row per variant, a finite goal-normalised error; the
    metric residuals at weight 0 score exactly as the output-error refinement (same EKF stage, same fit)."""
    from shipid.datasets import bundled_kcs_logs
    from shipid.logs import read_log

    runs = {p.stem: read_log(p) for p in bundled_kcs_logs()[1:]}  # tc +35, zz -10, zz +20 (rpm change)
    variants = {"oe": {"mode": "output-error", "max_nfev": 3},
                "m0": {"mode": "metrics", "metric_weight": 0.0, "max_nfev": 3}}
    tab = ks.leave_one_run_out_refinements(runs, "kcs-response", variants=variants, train=tuple(runs),
                                           folds=["kcs_zz_p20_rpm"])
    assert list(tab["variant"]) == ["oe", "m0"] and set(tab["left_out"]) == {"kcs_zz_p20_rpm"}
    assert np.all(np.isfinite(tab["error"])) and tab["error"].iloc[0] > 0
    assert tab["error"].iloc[1] == tab["error"].iloc[0]


def test_leave_one_run_out_of_recipes_shares_ekf_stages_between_variants_with_the_same_fit_options():
    """studies.kvlcc2.leave_one_run_out_recipes on the bundled KCS logs, one fold:
    variants with the same ``fit`` options share one EKF stage (with nothing held by the identifiable subset,
    switching it off changes nothing), another sampling step is another EKF stage; one row per variant."""
    from shipid.datasets import bundled_kcs_logs
    from shipid.logs import read_log

    runs = {p.stem: read_log(p) for p in bundled_kcs_logs()[1:]}
    oe = {"mode": "output-error", "max_nfev": 3}
    variants = {"a": {"fit": {"n_passes": 1}, "refine": oe},
                "a, all refined": {"fit": {"n_passes": 1}, "refine": {**oe, "hold_unresolved": False}},
                "every 2nd": {"fit": {"n_passes": 1, "dt": 2}, "refine": oe}}
    tab = ks.leave_one_run_out_recipes(runs, "kcs-response", variants=variants, train=tuple(runs),
                                       folds=["kcs_zz_p20_rpm"])
    assert list(tab["variant"]) == list(variants) and set(tab["left_out"]) == {"kcs_zz_p20_rpm"}
    assert np.all(np.isfinite(tab["error"])) and list(tab["held"]) == [[], [], []]
    assert tab["error"].iloc[1] == tab["error"].iloc[0] and tab["error"].iloc[2] != tab["error"].iloc[0]
    assert ks.RECIPE_CANDIDATES["default"] == {"fit": {}, "refine": {"mode": "metrics"}} and "0.01" in ks.LORO_RULE
