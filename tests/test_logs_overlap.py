"""Logs that repeat each other's samples (shipid.logs.overlap) and the fit recipe's step 0 (repeated runs)."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shipid.logs.overlap import drop_contained, repeated_samples

ESSO = Path(__file__).parents[1] / ".." / "shared" / "data" / "esso_osaka_frt"


def _run(seed, n=200, t0=0.0):
    """A run's samples: time and noisy channels (two seeds: two runs)."""
    rng = np.random.default_rng(seed)
    t = t0 + 0.1 * np.arange(n)
    return pd.DataFrame({"time": t, **{c: rng.normal(size=n) for c in ("x", "y", "psi", "u", "v", "r")},
                         "delta": 0.1 * np.sign(np.sin(t)), "n": np.full(n, 10.0)})


def test_a_trimmed_copy_is_found_and_dropped_other_runs_are_not():
    a, b = _run(1), _run(2)  # two runs with the same clock and inputs: different samples
    cut = a.iloc[20:150].reset_index(drop=True)
    rows = repeated_samples([a, b, cut])
    assert [(r["index"], r["in_index"], r["shared"], r["samples"]) for r in rows] == [(0, 2, 130, 200), (2, 0, 130, 130)]
    assert rows[1]["share"] == 1.0 and rows[0]["share"] == pytest.approx(0.65)
    kept, gone = drop_contained([a, b, cut])
    assert len(kept) == 2 and kept[0] is a and kept[1] is b and [g["index"] for g in gone] == [2]
    assert repeated_samples([a, b], min_share=0.0) == []  # same time stamps, inputs and clock: not the same samples


def test_twins_keep_the_first_zero_signs_and_missing_values():
    a = _run(3)
    twin = a.copy()
    twin.loc[5, "x"] = np.nan  # a missing value: that row is not compared
    a.loc[7, "v"] = 0.0
    twin.loc[7, "v"] = -0.0  # equal numbers: the same sample
    kept, gone = drop_contained([a, twin])
    assert len(kept) == 1 and kept[0] is a and gone[0]["index"] == 1 and gone[0]["samples"] == 199
    # a value changed in one row: the twin is no longer contained, only overlapping
    other = a.copy()
    other.loc[50, "psi"] += 1e-12
    rows = repeated_samples([a, other])
    assert [r["shared"] for r in rows] == [199, 199] and all(r["share"] < 1 for r in rows)
    assert drop_contained([a, other])[1] == []
    with pytest.raises(ValueError, match="min_share"):
        repeated_samples([a, other], min_share=2)


def test_overlapping_segments_below_the_share_are_not_reported():
    a = _run(4, n=1000)
    s1, s2 = a.iloc[:520], a.iloc[480:]  # 40 samples in common: 7.7 % of s1, 7.7 % of s2
    assert repeated_samples([s1, s2]) == []
    rows = repeated_samples([s1, s2], min_share=0.05)
    assert [(r["shared"], r["samples"]) for r in rows] == [(40, 520), (40, 520)]


@pytest.mark.skipif(not ESSO.is_dir(), reason=f"Esso Osaka data set (FRT-DS-ESSO) not found at {ESSO}")
def test_the_esso_osaka_trimmed_copy_is_the_only_repeat_among_the_runs():
    """The data set's README: ``turn_cut_*`` are trimmed copies of a run.  Among the 33 files here exactly one
    is a copy of another file (the study's ``DUPLICATES``); the consecutive segments of one random session
    (``random_06-Aug-2020_16_24_25_*``) share no sample, and neither does the other cut, whose full run is not
    among these files."""
    from shipid.logs import read_log
    from studies.esso_osaka import DUPLICATES

    files = sorted(ESSO.glob("*/*.csv"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        logs = [read_log(f, schema="esso-frt") for f in files]
    kept, gone = drop_contained(logs)
    assert tuple(g["log"] for g in gone) == DUPLICATES and len(kept) == len(logs) - 1
    assert gone[0]["in"] == "turn_14-Sep-2020_15_58_08" and gone[0]["samples"] == 2869
    assert {(r["log"], r["in"]) for r in repeated_samples(logs, min_share=0.0)} == {
        ("turn_cut_14-Sep-2020_15_58_08", "turn_14-Sep-2020_15_58_08"),
        ("turn_14-Sep-2020_15_58_08", "turn_cut_14-Sep-2020_15_58_08")}


def test_fit_recipe_drops_a_trimmed_copy_and_says_so():
    """fit_logs on two bundled KCS logs plus a trimmed copy of one: the copy is dropped (step 'repeated runs'),
    the fit equals the fit without it; asked to keep it, the copy counts twice (a warning, other coefficients);
    two overlapping windows of one run are kept with a warning (step 'overlapping runs')."""
    from shipid.datasets import bundled_kcs_logs
    from shipid.identify.recipe import fit_logs
    from shipid.logs import read_log

    tc, zz = [read_log(p) for p in bundled_kcs_logs()[1:3]]
    cut = zz.window(0.0, 30.0)
    cut.name = "zz_cut"
    opts = dict(n_passes=1, refine=None)
    base = fit_logs([tc, zz], "kcs-response", **opts).result()
    lines = []
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # dropping is said in the step, not warned
        fit = fit_logs([tc, cut, zz], "kcs-response", log=lines.append, **opts).result()
    steps = {s["step"]: s for s in fit.settings["recipe"]}
    assert steps["repeated runs"]["value"] == {"dropped": ["zz_cut"]}
    assert f"all {cut.data.shape[0]} samples of zz_cut are samples of {zz.name}" in steps["repeated runs"]["reason"]
    assert lines[0].startswith("recipe: repeated runs:")
    assert fit.coef == base.coef
    with pytest.warns(UserWarning, match="fitted twice: all 301 samples of zz_cut"):
        twice = fit_logs([tc, cut, zz], "kcs-response", drop_repeated=False, **opts).result()
    assert {s["step"]: s for s in twice.settings["recipe"]}["repeated runs"]["value"] == {"kept": ["zz_cut"]}
    assert twice.coef != base.coef
    w1, w2 = zz.window(0.0, 40.0), zz.window(20.0, None)
    w1.name, w2.name = "zz_a", "zz_b"
    with pytest.warns(UserWarning, match="logs share samples"):
        over = fit_logs([tc, w1, w2], "kcs-response", **opts).result()
    st = {s["step"]: s for s in over.settings["recipe"]}
    assert "repeated runs" not in st and st["overlapping runs"]["value"] == {"kept": ["zz_a"]}
