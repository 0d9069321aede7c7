"""Hold-out validation on the measured MARIN KVLCC2 runs (issue 3, point 5).

Fit on tc+-35 and zz+-10, predict zz+-20 with each model's closed-loop zigzag.
Goals: first overshoot within 2 deg and second within 3 deg on the held-out
zigzags, tactical diameter within 5 % on the training turns.  The tests assert
what each model achieves (measured here) and show where a goal is missed; the
numbers are in docs/validation.md and the issue notes.
"""
from __future__ import annotations

import numpy as np
import pytest

from shipid import kvlcc2_study as ks


@pytest.fixture(scope="module")
def runs(request):
    from conftest import MARIN_DIR

    if not MARIN_DIR.is_dir():
        pytest.skip(f"measured KVLCC2 data not found at {MARIN_DIR} (../shared/data/kvlcc2_marin beside the repo)")
    return ks.load_runs(MARIN_DIR), ks.load_runs(MARIN_DIR, decimate=4)


def _err(table, run, metric):
    row = table[(table.run == run) & (table.metric == metric)]
    return float(row["error"].iloc[0]) if row["error"].notna().all() else np.nan


def test_symmetric_models_cannot_meet_5_percent_on_both_turns(runs):
    """The measured tactical diameters differ by 8.5 % between sides: a port/starboard symmetric
    model misses one of them by at least (3.33 - 3.07) / 2 / 3.2 = 4.1 %."""
    full, _ = runs
    from shipid.manoeuvres import metrics

    td = {k: metrics(full[k]).to_dict()["tactical_diameter_L"] for k in ("tc_35", "tc_-35")}
    spread = abs(td["tc_35"] - td["tc_-35"]) / np.mean(list(td.values()))
    assert 0.07 < spread < 0.10


@pytest.mark.slow
def test_mmg_refit_predicts_turns_and_heldout_zigzags(runs):
    full, dec = runs
    fit = ks.fit_model("mmg", dec)
    assert fit.success_, fit.message_
    tab = ks.evaluate(fit.result(), full)
    print(tab.round(3).to_string())
    # training turns: tactical diameter within 6 % (5 % met on tc_35; tc_-35 is the asymmetric side)
    for run in ("tc_35", "tc_-35"):
        rel = tab[(tab.run == run) & (tab.metric == "tactical_diameter_L")]["rel_error_%"].iloc[0]
        assert abs(rel) < 6.0, (run, rel)
    # held-out zigzags: first overshoot within 5 deg (measured +4.2 / +1.0 deg: the 2 deg goal is
    # met on zz_-20 only), second within 7 deg
    for run in ks.TEST:
        assert abs(_err(tab, run, "overshoot1_deg")) < 5.0
        assert abs(_err(tab, run, "overshoot2_deg")) < 7.0


@pytest.mark.slow
def test_seed_linear_model_cannot_do_both(runs):
    """kcs-response (the seed's linear sway/yaw) fitted to turns and zigzags together: it follows
    the zigzags (held-out first overshoots within 5 deg; measured +1.0 / +3.9 deg) but turns far
    too tightly (tactical diameter 33 % / 44 % small) -- the issue's warning, on measured data."""
    full, dec = runs
    fit = ks.fit_model("kcs-response", dec)
    assert fit.success_, fit.message_
    tab = ks.evaluate(fit.result(), full)
    print(tab.round(3).to_string())
    rel = tab[(tab.metric == "tactical_diameter_L")].set_index("run")["rel_error_%"]
    assert rel["tc_35"] < -25 and rel["tc_-35"] < -25, rel
    for run in ks.TEST:
        assert abs(_err(tab, run, "overshoot1_deg")) < 5.0


@pytest.mark.slow
def test_response_nl_predicts_heldout_zigzags(runs):
    """response-nl (the seed's terms + non-linear damping), started from a kcs-response fit:
    port/starboard symmetric, so it matches the port turn (TD +1.2 %) and misses the 8.5 % wider
    starboard turn (-7.5 %); held-out first overshoots -3.2 / -0.4 deg, second -1.5 / -4.8 deg
    (the 2 / 3 deg goals are met on one of the two runs each)."""
    full, dec = runs
    fit = ks.fit_model("response-nl", dec)
    assert fit.success_, fit.message_
    tab = ks.evaluate(fit.result(), full)
    print(tab.round(3).to_string())
    rel = tab[(tab.metric == "tactical_diameter_L")].set_index("run")["rel_error_%"]
    assert abs(rel["tc_35"]) < 5.0 and abs(rel["tc_-35"]) < 9.0, rel
    for run in ks.TEST:
        assert abs(_err(tab, run, "overshoot1_deg")) < 4.0
        assert abs(_err(tab, run, "overshoot2_deg")) < 6.0
