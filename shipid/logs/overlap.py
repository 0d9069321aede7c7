"""Logs that repeat each other's samples: a trimmed copy of a run, overlapping segments of one session.

Two logs of *different* runs never share a sample: a sample is the time stamp together with the measured
position, heading, velocities and inputs, and sensor noise alone makes two runs differ in the last digits.
A log whose every sample is also a sample of another log is a copy of (part of) that run; fitted together,
that run counts twice -- its weight in the fit doubles and the coefficients' standard deviations shrink as
if it were new evidence -- and in a leave-one-run-out check the copy leaks the held-out run into the
training set.  (The Esso Osaka data set ships ``turn_cut_14-Sep-2020_15_58_08.csv``, the first 2869 of the
4336 samples of ``turn_14-Sep-2020_15_58_08.csv``.)

:func:`repeated_samples` finds such pairs by exact comparison of the samples as read (same file format,
same units conversion: equal numbers); :func:`drop_contained` keeps one of each.
"""
from __future__ import annotations

import numpy as np

__all__ = ["KEY_CHANNELS", "repeated_samples", "drop_contained"]

#: The channels a sample is compared on (those present in every log; ``time`` and at least one other needed).
KEY_CHANNELS = ("time", "x", "y", "psi", "u", "v", "r", "delta", "n")


def _frame(lg):
    return getattr(lg, "data", lg)


def _name(lg, i) -> str:
    return str(getattr(lg, "name", None) or f"log {i}")


def repeated_samples(logs, min_share: float = 0.1) -> list[dict]:
    """Ordered pairs of ``logs`` (TrialLogs or DataFrames in shipid's channels) that share samples.

    A sample is the row of :data:`KEY_CHANNELS` present in every log (rows with a missing value are not
    compared); two samples are the same when every value is equal.  For each log ``a`` and each other log
    ``b`` holding at least ``min_share`` of ``a``'s compared samples, one dict: ``log``/``index`` (a),
    ``in``/``in_index`` (b), ``shared`` (how many of a's samples b holds), ``samples`` (a's compared samples),
    ``share`` (their ratio; 1.0: every sample of a is in b).  Empty when fewer than two logs or no common key
    beyond time.
    """
    frames = [_frame(lg) for lg in logs]
    if min_share < 0 or min_share > 1:
        raise ValueError(f"min_share={min_share!r}: give a fraction between 0 and 1")
    if len(frames) < 2:
        return []
    key = [c for c in KEY_CHANNELS if all(c in f.columns for f in frames)]
    if "time" not in key or len(key) < 2:
        return []
    arrays, hashes, spans = [], [], []
    for f in frames:
        a = f[key].to_numpy(dtype=float) + 0.0  # (+0.0: -0.0 and 0.0 compare equal, so must their bits)
        a = np.ascontiguousarray(a[np.isfinite(a).all(axis=1)])
        arrays.append(a)
        hashes.append(_row_hash(a))
        spans.append((a[:, 0].min(), a[:, 0].max()) if len(a) else (np.inf, -np.inf))
    orders = [np.argsort(g, kind="stable") for g in hashes]
    ranked = [g[o] for g, o in zip(hashes, orders)]
    out = []
    for i, (a, h) in enumerate(zip(arrays, hashes)):
        n = len(a)
        for j, (b, g) in enumerate(zip(arrays, hashes)):
            if j == i or n == 0 or len(b) == 0 or spans[i][1] < spans[j][0] or spans[j][1] < spans[i][0]:
                continue
            pos = np.minimum(np.searchsorted(ranked[j], h), len(g) - 1)
            hit = np.flatnonzero(ranked[j][pos] == h)
            if hit.size == 0:
                continue
            cand = orders[j][pos[hit]]
            c = int((b[cand] == a[hit]).all(axis=1).sum())  # the hash finds the row, the values decide
            if c and c >= min_share * n:
                out.append({"log": _name(logs[i], i), "index": i, "in": _name(logs[j], j), "in_index": j,
                            "shared": c, "samples": int(n), "share": c / n})
    return out


def _row_hash(a: np.ndarray) -> np.ndarray:
    """One 64-bit number per row of ``a`` from the bits of its values (equal rows, equal numbers)."""
    bits = a.view(np.uint64) if a.size else np.zeros((0, a.shape[1]), np.uint64)
    h = np.full(len(a), np.uint64(1469598103934665603))
    with np.errstate(over="ignore"):
        for c in range(bits.shape[1]):
            h = (h ^ bits[:, c]) * np.uint64(1099511628211)
            h ^= h >> np.uint64(29)
    return h


def drop_contained(logs, rows=None) -> tuple[list, list[dict]]:
    """``logs`` without those whose every compared sample is a sample of another kept log (of two identical
    logs the first is kept), and the :func:`repeated_samples` rows of the dropped ones (share 1.0).  ``rows``:
    :func:`repeated_samples` of these logs, when the caller has them already (any ``min_share``)."""
    logs = list(logs)
    rows = repeated_samples(logs, min_share=1.0) if rows is None else rows
    full = [r for r in rows if r["shared"] == r["samples"]]
    dropped: set = set()
    why = []
    for r in sorted(full, key=lambda r: (r["samples"], -r["index"])):  # the shortest copies first
        i, j = r["index"], r["in_index"]
        if i in dropped or j in dropped:
            continue
        # two identical logs contain each other: keep the first of them
        twin = any(q["index"] == j and q["in_index"] == i for q in full)
        if twin and i < j:
            continue
        dropped.add(i)
        why.append(r)
    return [lg for k, lg in enumerate(logs) if k not in dropped], why
