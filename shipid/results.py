"""One shape for every result shipid returns.

Every public result -- a fit, a trial log, a simulation, a manoeuvre, a validation, a horizon
prediction, posterior samples, a control solution, a route, a glider launch, a campaign -- answers
the same questions the same way, as python-control's time responses and scipy's ``OptimizeResult``
do:

``success``, ``message``
    Did it work, and one line saying what happened.
``summary()``
    The numbers a user quotes, as a :class:`pandas.DataFrame`.
``to_pandas()``
    The full table behind the result (time series, per-member rows, draws).
``plot(ax=None)``
    A figure of the result on ``ax`` (new axes when None); returns the axes.  Angles and angular
    rates are drawn in degrees.
``_repr_html_()``
    A compact card for Jupyter: status, verdict where there is one, key numbers and the head of
    ``summary()``.

:class:`ResultMixin` supplies ``_repr_html_`` from the class's ``summary()``; each class supplies its
own table and figure.  This module imports only numpy, pandas and the standard library (matplotlib
is imported by the plotting helpers when they are called).
"""
from __future__ import annotations

import html
import math
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["ResultMixin", "result_html", "verdict_grade", "in_degrees", "axes_column", "plot_series",
           "coefficient_table", "plot_coefficients"]

#: Units drawn in degrees, and the unit they are shown in.
_ANGLE_UNITS = {"rad": "deg", "rad/s": "deg/s", "rad/s^2": "deg/s^2", "rad/s2": "deg/s^2"}

_HTML_ROWS = 12      # rows of summary() shown in the notebook card
_HTML_COLS = 10      # columns of summary() shown in the notebook card
_HTML_TEXT = 120     # characters of a text cell or of the message shown


def in_degrees(values, unit: str | None):
    """``(values, unit)`` with radians and radians per second converted to degrees (others unchanged)."""
    unit = unit or ""
    if unit in _ANGLE_UNITS:
        return np.degrees(np.asarray(values, dtype=float)), _ANGLE_UNITS[unit]
    return values, unit


def axes_column(ax, n: int, *, height: float = 1.6, width: float = 7.0) -> np.ndarray:
    """``n`` axes stacked in one column sharing the time axis (new figure when ``ax`` is None); a single
    given axes is reused for every panel."""
    if ax is None:
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        _, axs = plt.subplots(max(n, 1), 1, sharex=True, figsize=(width, height * max(n, 1)), squeeze=False)
        return axs[:, 0]
    axs = np.atleast_1d(ax).ravel()
    if axs.size < n:
        axs = np.resize(axs, n)
    return axs


def plot_series(axs, t, frame: pd.DataFrame, names, units: dict, **kw) -> None:
    """Plot ``frame[name]`` against ``t`` on one axes per name, angles in degrees, labelled with units."""
    for a, name in zip(axs, names):
        if name not in frame:
            continue
        y, unit = in_degrees(frame[name].to_numpy(), units.get(name, ""))
        a.plot(t, y, **kw)
        a.set_ylabel(f"{name} [{unit}]" if unit else name)


def coefficient_table(value: pd.Series, std: pd.Series) -> pd.DataFrame:
    """The coefficient table of a fit: ``value``, ``std``, ``rel_std_%`` (of the absolute value), and the 95 % interval
    ``ci95_low``/``ci95_high`` (value -/+ 1.96 std), one row per estimated coefficient."""
    v, sd = value.astype(float), std.astype(float)
    return pd.DataFrame({"value": v, "std": sd, "rel_std_%": 100 * sd / v.abs().where(v.abs() > 0),
                         "ci95_low": v - 1.96 * sd, "ci95_high": v + 1.96 * sd})


def plot_coefficients(table: pd.DataFrame, ax=None, title: str | None = None):
    """Each estimated coefficient's 95 % interval relative to its value (1 = the estimate), so coefficients of
    every size share one axis; a wide bar is a poorly determined coefficient.  Returns the axes."""
    if ax is None:
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        _, ax = plt.subplots(figsize=(6, 0.3 * len(table) + 1.2))
    v = table["value"].to_numpy(dtype=float)
    half = 1.96 * table["std"].to_numpy(dtype=float) / np.where(np.abs(v) > 0, np.abs(v), np.nan)
    pos = np.arange(len(table))
    ax.errorbar(np.ones(len(table)), pos, xerr=half, fmt="o", capsize=3)
    ax.axvline(1.0, color="0.6", lw=0.8)
    ax.set_yticks(pos, [str(i) for i in table.index])
    ax.invert_yaxis()
    ax.set_xlabel("95 % interval / estimate")
    if title:
        ax.set_title(title)
    return ax


def verdict_grade(result) -> str | None:
    """The graded verdict of a fit (``result.verdict.grade``, or ``verdict_`` of a fitted estimator) when the
    result carries one, else None."""
    v = getattr(result, "verdict", None)
    if v is None:
        v = getattr(result, "verdict_", None)
    if v is None:
        return None
    g = getattr(v, "grade", None)
    if g is None and isinstance(v, dict):
        g = v.get("grade")
    return None if g is None else str(g)


def _clip(text: Any, n: int = _HTML_TEXT) -> str:
    s = " ".join(str(text).split())
    return s if len(s) <= n else s[: n - 3] + "..."


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return "" if math.isnan(v) else f"{float(v):.4g}"
    return _clip(v)


def _table_html(df: pd.DataFrame) -> str:
    head = df.iloc[:_HTML_ROWS, :_HTML_COLS].copy()
    for c in head.columns:
        if head[c].dtype == object:
            head[c] = head[c].map(lambda v: _clip(v, 60) if isinstance(v, str) else v)
    body = head.to_html(float_format=lambda v: f"{v:.4g}", border=0, na_rep="", max_cols=_HTML_COLS,
                        classes="shipid-summary")
    more = []
    if len(df) > _HTML_ROWS:
        more.append(f"{len(df) - _HTML_ROWS} more rows")
    if df.shape[1] > _HTML_COLS:
        more.append(f"{df.shape[1] - _HTML_COLS} more columns")
    tail = f"<p style='margin:2px 0;color:#666'>{', '.join(more)}: see <code>.summary()</code></p>" if more else ""
    return body + tail


def result_html(result, title: str | None = None, key_numbers: dict | None = None) -> str:
    """A compact HTML card of a result: title, success, verdict grade, message, key numbers, the head
    of ``summary()`` and where the full tables are (a few kB whatever the result's size)."""
    title = title or type(result).__name__
    parts = [f"<div class='shipid-result' style='font-size:90%'><p style='margin:2px 0'><b>{html.escape(title)}</b>"]
    ok = getattr(result, "success", None)
    if ok is not None:
        colour, word = ("#1a7f37", "success") if ok else ("#cf222e", "not successful")
        parts.append(f" &middot; <span style='color:{colour}'>{word}</span>")
    grade = verdict_grade(result)
    if grade is not None:
        parts.append(f" &middot; verdict <b>{html.escape(grade)}</b>")
    parts.append("</p>")
    msg = getattr(result, "message", "")
    if msg:
        parts.append(f"<p style='margin:2px 0'>{html.escape(_clip(msg))}</p>")
    if key_numbers:
        cells = "".join(f"<tr><th style='text-align:left'>{html.escape(str(k))}</th><td>{html.escape(_fmt(v))}</td></tr>"
                        for k, v in key_numbers.items())
        parts.append(f"<table class='shipid-keys'>{cells}</table>")
    try:
        table = result.summary()
    except Exception as exc:  # a card must render even for a result whose table cannot be built
        parts.append(f"<p>summary unavailable: {html.escape(_clip(exc))}</p>")
    else:
        if isinstance(table, pd.Series):
            table = table.to_frame()
        if isinstance(table, pd.DataFrame) and len(table):
            parts.append(_table_html(table))
    parts.append("<p style='margin:2px 0;color:#666'>full tables: <code>.summary()</code>, "
                 "<code>.to_pandas()</code>; figure: <code>.plot()</code></p></div>")
    return "".join(parts)


class ResultMixin:
    """The result contract (see the module docstring).

    A class using it defines ``success`` and ``message`` (attributes or properties), ``summary()``
    returning a DataFrame, ``to_pandas()`` and ``plot(ax=None)``; it may override :meth:`_html_title`
    and :meth:`_key_numbers` to shape its notebook card.
    """

    def summary(self) -> pd.DataFrame:  # pragma: no cover - every result class overrides it
        raise NotImplementedError(f"{type(self).__name__} does not define summary()")

    def to_pandas(self) -> pd.DataFrame:  # pragma: no cover - every result class overrides it
        raise NotImplementedError(f"{type(self).__name__} does not define to_pandas()")

    def plot(self, ax=None):  # pragma: no cover - every result class overrides it
        raise NotImplementedError(f"{type(self).__name__} does not define plot()")

    def _html_title(self) -> str:
        return type(self).__name__

    def _key_numbers(self) -> dict:
        return {}

    def _repr_html_(self) -> str:
        return result_html(self, self._html_title(), self._key_numbers())
