"""MARIN SIMMAN 2008 ``.dat`` files (KVLCC2 free-running manoeuvres).

Conventions: two title lines, a blank line, then rows of 11 numbers
``time x0 y0 phi psi u v p r delta rev`` in s, m, deg, m/s (earth-fixed
dx0/dt, dy0/dt), deg/s, deg, rpm; time printed with 3 significant digits.
The reader returns the file's channels in SI with u, v still earth-fixed; the
``marin`` schema (:data:`shipid.logs.schema.PRESETS`) states the frame and the
rudder sign that :func:`shipid.logs.schema.apply_conventions` applies.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from ._text import _fast_table, _is_number, _to_float
from .trial_log import LogError, _convert_units, _fmt_value, _Where

_MARIN_COLS = ("time", "x", "y", "phi", "psi", "u_e", "v_e", "p", "r", "delta", "n")
_MARIN_UNITS = {"time": "s", "x": "m", "y": "m", "phi": "deg", "psi": "deg", "u_e": "m/s", "v_e": "m/s",
                "p": "deg/s", "r": "deg/s", "delta": "deg", "n": "rpm"}


_MARIN_FILE_NAMES = {"x": "x0", "y": "y0", "phi": "phi", "psi": "psi", "u_e": "u", "v_e": "v", "p": "p", "r": "r",
                     "delta": "delta", "n": "rev"}


def _looks_marin(text: str) -> bool:
    return text.lstrip()[:200].upper().startswith("MARIN")


def _read_marin(text: str, p: Path, units: Mapping[str, str], marin_time: str):
    if units:
        raise LogError(f"`{p.name}`: units= (CLI: --units) does not apply to a MARIN .dat file (its units are fixed: "
                       "degrees, rpm); to read it as a table of your own, pass fmt='csv' (CLI: --format csv)", path=p)
    if marin_time not in ("uniform", "drop"):
        raise ValueError(f"marin_time={marin_time!r}: use 'uniform' or 'drop'")
    lines = text.splitlines()
    start = None
    for k, line in enumerate(lines):
        if k >= 2 and line.strip() and _is_number(line.split()[0]):
            start = k
            break
        if k > 10:
            break
    if start is None:
        raise LogError(f"`{p.name}`: no data rows after the MARIN title lines; expected two title lines, a blank "
                       "line and rows of 11 numbers", path=p)
    idx = [k for k in range(start, len(lines)) if lines[k].strip()]
    fast = _fast_table(lines, idx, "whitespace", 11)
    if fast is not None and fast[1].all():
        a = fast[0]
        rows = np.asarray(idx, dtype=np.int64) + 1
        where = _Where(p, p.stem, rows)
    else:
        a, rows, where = _marin_rows(lines, idx, p)
    notes: list[str] = []
    t = a[:, 0].copy()
    # --- repeated (rounded) time stamps ------------------------------------------------
    d = np.diff(t)
    if (d < 0).any():
        i = int(np.argmax(d < 0)) + 1
        raise where.error(f"time {_fmt_value(t[i])} goes back from {_fmt_value(t[i - 1])}; the file is not in time "
                          "order", "time", i, value=t[i])
    nrep = int(np.sum(d == 0))
    if nrep:
        if marin_time == "uniform":
            tu, dev = _uniform_time(t)
            if tu is None:
                # a row written twice breaks the uniform time base: repair it (drop the exact repeat) if that
                # makes the stamps uniform again, else refuse (dropping every repeated stamp loses ~70 %)
                dup = np.flatnonzero((a[1:] == a[:-1]).all(axis=1)) + 1
                if dup.size:
                    keep = np.ones(len(a), dtype=bool)
                    keep[dup] = False
                    tu, dev = _uniform_time(t[keep])
                    if tu is not None:
                        notes.append(f"{dup.size} row(s) repeating the previous row exactly dropped (rows "
                                     f"{', '.join(str(int(r)) for r in rows[dup][:5])}): a duplicated row breaks "
                                     "the uniform time base")
                        a, rows = a[keep], rows[keep]
                        where.rows = rows
                        nrep = int(np.sum(np.diff(a[:, 0]) == 0))
                if tu is None:
                    i = _first_off_uniform(a[:, 0])
                    raise where.error(f"time stamps are not consistent with uniform sampling from this row on "
                                      f"(printed {_fmt_value(a[i, 0])} s): a row is missing, duplicated with changes "
                                      "or out of place; fix the file, or pass marin_time='drop' (CLI: --marin-time "
                                      "drop) to keep only the first sample of each repeated stamp", "time", i,
                                      value=a[i, 0])
            notes.append(f"time printed with 3 significant digits: {nrep} repeated stamps; time rebuilt as "
                         f"t0 + k dt (dt = {tu[1] - tu[0]:.6g} s), which rounds to every printed stamp "
                         f"(max deviation {dev:.2f} of the printed resolution)")
            t = tu
        if marin_time == "drop":
            keep = np.concatenate([[True], d != 0])
            a, t, rows = a[keep], t[keep], rows[keep]
            where.rows = rows
            notes.append(f"{nrep} samples with a repeated time stamp dropped (first of each kept)")
    ch_units = dict(_MARIN_UNITS)
    arrays = {c: a[:, j] for j, c in enumerate(_MARIN_COLS)}
    arrays["time"] = t
    t2, ch, units_in = _convert_units(arrays, ch_units, {}, where)
    # u, v stay earth-fixed (dx0/dt, dy0/dt) here: the marin schema (velocity_frame="earth") rotates them
    order = ("x", "y", "psi", "u_e", "v_e", "r", "delta", "n", "phi", "p")
    ch_out = {c.removesuffix("_e"): ch[c] for c in order}
    units_in = {c.removesuffix("_e"): units_in.get(c, "") for c in ("time",) + order}
    where.sources = {c.removesuffix("_e"): f"column {_MARIN_COLS.index(c) + 1} '{_MARIN_FILE_NAMES[c]}'"
                     for c in order}
    return t2, ch_out, where, units_in, notes


def _marin_rows(lines: list[str], idx: list[int], p: Path):
    """Careful row-by-row parse of MARIN data lines (names the row of any irregularity)."""
    rows_l, vals = [], []
    for k in idx:
        parts = lines[k].split()
        if len(parts) != 11:
            raise LogError(f"`{p.name}` row {k + 1}: {len(parts)} number(s), a MARIN row has 11 (time x0 y0 phi psi "
                           "u v p r delta rev); fix or delete the row", path=p, row=k + 1, value=lines[k].strip()[:60])
        rows_l.append(k + 1)
        vals.append(parts)
    rows = np.asarray(rows_l, dtype=np.int64)
    where = _Where(p, p.stem, rows)
    try:
        a = np.asarray(vals, dtype=float)
    except ValueError:
        cols = list(zip(*vals))
        for j, c in enumerate(_MARIN_COLS):
            _to_float(cols[j], c, c, where)
        raise  # pragma: no cover (_to_float raised)
    return a, rows, where


def _first_off_uniform(t: np.ndarray) -> int:
    """Index of the first stamp from which no uniform time base fits (the longest uniform prefix)."""
    lo, hi = 2, t.size   # _uniform_time(t[:lo]) fits, t[:hi] does not
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if _uniform_time(t[:mid])[0] is not None:
            lo = mid
        else:
            hi = mid
    return hi - 1


def _uniform_time(t: np.ndarray) -> tuple[np.ndarray | None, float]:
    """Fit t0 + k dt to stamps rounded to 3 significant digits; None when inconsistent."""
    k = np.arange(t.size, dtype=float)
    ulp = np.where(t != 0, 10.0 ** (np.floor(np.log10(np.abs(np.where(t != 0, t, 1.0)))) - 2), 1e-3)
    w = 1.0 / ulp
    # two candidates: anchored at the first stamp (dt by weighted least squares), and t0, dt both
    # fitted; keep the one that deviates least from the printed stamps
    dt = float(np.sum(k * w * (t - t[0]) * w) / np.sum((k * w) ** 2))
    cands = [t[0] + k * dt]
    # weighted least squares for (t0, dt) in closed form (no BLAS: threaded BLAS stalls on a busy machine)
    w2 = w * w
    sw, sk, skk = np.sum(w2), np.sum(w2 * k), np.sum(w2 * k * k)
    st, skt = np.sum(w2 * t), np.sum(w2 * k * t)
    det = sw * skk - sk * sk
    dt_free = (sw * skt - sk * st) / det
    t0_free = (st - dt_free * sk) / sw
    cands.append(t0_free + k * dt_free)
    devs = [float(np.max(np.abs(c - t) / ulp)) for c in cands]
    j = int(np.argmin(devs))
    tu, dev = cands[j], devs[j]
    if not tu[-1] > tu[0] or dev > 1.0:
        return None, dev
    return tu, dev
