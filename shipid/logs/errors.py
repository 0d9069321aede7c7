"""The error of an unusable log (:class:`LogError`) and how messages name its places (file rows or array
indices)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["LogError"]


class LogError(ValueError):
    """A trial log (file or arrays) cannot be used as given.

    Attributes
    ----------
    path : pathlib.Path or None
        The file, or None for arrays.
    column : str or None
        Our channel name (or the file's column name) concerned.
    row : int or None
        1-based line number in the file (header = line 1 when there are no
        comment lines), or the 0-based sample index for arrays.
    value : object
        The offending value, when there is one.
    """

    def __init__(self, message: str, *, path=None, column: str | None = None, row: int | None = None, value=None):
        super().__init__(message)
        self.path = Path(path) if path is not None else None
        self.column = column
        self.row = row
        self.value = value


def _fmt_value(v) -> str:
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if math.isnan(v):
            return "blank/NaN"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return f"{v:.6g}"
    if isinstance(v, str):
        return repr(v if len(v) <= 40 else v[:37] + "...")
    return str(v)


class _Where:
    """How to name places in messages: a file (rows are file lines) or arrays (indices)."""

    def __init__(self, path: Path | None, name: str, rows: np.ndarray | None = None):
        self.path = path
        self.name = name
        self.rows = rows
        self.sources: dict[str, str] = {}   # channel -> the file's column, e.g. "column 7 'r [deg/s]'"

    @property
    def label(self) -> str:
        return f"`{self.path.name}`" if self.path is not None else f"log '{self.name}'"

    def row_of(self, i: int) -> int:
        return int(self.rows[i]) if self.rows is not None else int(i)

    def place(self, column: str | None = None, i: int | None = None, *, row: int | None = None) -> str:
        s = self.label
        if column is not None:
            s += f" column '{column}'"
        if row is None and i is not None:
            row = self.row_of(i)
        if row is not None:
            s += f" {'row' if self.path is not None else 'index'} {row}"
        return s

    def error(self, msg: str, column: str | None = None, i: int | None = None, *, row: int | None = None, value=None):
        if row is None and i is not None:
            row = self.row_of(i)
        return LogError(f"{self.place(column, row=row)}: {msg}", path=self.path, column=column, row=row, value=value)
