"""Text-file helpers shared by the format readers (path checks, decoding, header cells, numbers)."""
from __future__ import annotations

import importlib.util
import io
import json
import os
import re
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from .._io import loads_json, loads_yaml
from .errors import LogError, _Where

#: cell texts read as a missing sample (compared in lower case): blanks, NaN spellings, a dash, Excel's #N/A
_MISSING_TOKENS = {"", "nan", "na", "n/a", "null", "none", "-nan", "-", "--", "#n/a"}

_DELIMS = {",": "comma", ";": "semicolon", "\t": "tab", "whitespace": "whitespace"}


def _check_path(p: Path, what: str = "log file") -> None:
    if not p.exists() and p.is_symlink():
        try:
            target = os.readlink(p)
        except OSError:
            target = "?"
        raise LogError(f"`{p}`: a symbolic link to {target!r}, which is missing or links back in a loop; give the "
                       f"{what} itself or fix the link", path=p)
    if not p.exists():
        hint = ""
        parent = p.parent if str(p.parent) else Path(".")
        if parent.is_dir():
            near = sorted(x.name for x in parent.iterdir() if x.suffix.lower() == p.suffix.lower())[:5]
            if near:
                hint = f" (files there: {', '.join(near)})"
        raise LogError(f"`{p}`: {what} does not exist; check the path{hint}", path=p)
    if p.is_dir():
        raise LogError(f"`{p}`: is a directory, not a {what}; give the file inside it", path=p)
    if not p.is_file():   # a FIFO, socket or device: reading it could block forever
        raise LogError(f"`{p}`: is not a regular file (a pipe, socket or device); give the {what} itself "
                       "(save the stream to a file first)", path=p)


_HEADER_RE = re.compile(r"^\s*(?P<name>.*?)\s*(?:[\[(](?P<unit>[^\])]*)[\])])?\s*$")


def _split_header(cell: str) -> tuple[str, str | None]:
    m = _HEADER_RE.match(cell)
    name = m.group("name").strip().strip('"').strip()
    unit = m.group("unit")
    unit = unit.strip() if unit is not None else None
    return name, (unit if unit and unit != "-" else None)  # "[-]": no unit given


def _decode(raw: bytes, p: Path) -> str:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):  # UTF-16 with BOM (Excel "Unicode text")
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError:
            pass
    nul = raw.find(b"\x00")
    if nul >= 0:
        line = raw.count(b"\n", 0, nul) + 1
        raise LogError(f"`{p.name}` row {line}: NUL byte at byte offset {nul}; this is a binary file, not a text "
                       "log: export the log as CSV text", path=p, row=line, value="\\x00")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        bad = raw[exc.start:exc.start + 1]
        # Latin-1 text (e.g. a degree sign from Excel) is readable; other bytes are not text
        if sum(1 for b in raw[:4096] if b < 9 or 13 < b < 32) == 0:
            try:
                text = raw.decode("cp1252")
            except UnicodeDecodeError:
                text = None
            if text is not None:
                return text
        raise LogError(f"`{p.name}` row {line}: byte 0x{bad.hex()} is not UTF-8 text; this looks like a binary "
                       "file: export the log as CSV text (UTF-8)", path=p, row=line, value=f"0x{bad.hex()}") from None


def _parse_meta(line: str, meta: dict, p: Path | None = None, row: int | None = None) -> None:
    """``# shipid-log: {...}`` / ``# shipid-ship: {...}`` comment lines -> ``meta`` (malformed JSON is ignored;
    hostile JSON, nested too deeply to parse, is an error naming the row)."""
    m = re.match(r"#\s*shipid-(log|ship):\s*(.*)$", line)
    if not m:
        return
    try:
        meta[m.group(1)] = json.loads(m.group(2))
    except json.JSONDecodeError:
        pass
    except RecursionError:
        name = p.name if p is not None else "log"
        raise LogError(f"`{name}` row {row}: the '# shipid-{m.group(1)}:' line is nested too deeply to be "
                       "metadata; delete the line or give a flat JSON mapping", path=p, row=row) from None


_NA_TOKENS = ["", "nan", "NaN", "NAN", "na", "NA", "n/a", "N/A", "null", "NULL", "Null", "none", "None", "NONE",
              "-nan", "-NaN", "-", "--", "#N/A", "#n/a"]


# pandas < 3 parses floats with "high" precision by default (last-digit differences possible);
# pandas 3 deprecates the argument and parses exactly by default
_EXACT_FLOATS = {"float_precision": "round_trip"} if int(pd.__version__.split(".")[0]) < 3 else {}


def _fast_table(lines: list[str], data_idx: list[int], delim: str, ncol: int):
    """Parse the data rows with pandas' C parser when that is unambiguous, else None.

    Used only when no cell is quoted, every row has ``ncol`` fields and every cell is a
    number or a missing-value token; any irregularity returns None and the careful
    row-by-row path (which names the offending row and value) takes over.  Values are
    parsed exactly as Python's ``float`` does (round-trip precision).
    Returns (table (n_rows, ncol) float, keep mask dropping all-blank rows).
    """
    if len(data_idx) < 50:
        return None
    body = [lines[k] for k in data_idx]
    text = "\n".join(body)
    if '"' in text or "'" in text:
        return None
    if delim == "whitespace":
        if any(len(b.split()) != ncol for b in body):
            return None
        sep = r"\s+"
    else:
        if any(b.count(delim) != ncol - 1 for b in body):
            return None
        sep = delim
    # bytes, not a StringIO: io.StringIO keeps 4 bytes a character (a 35 MB log took 140 MB more)
    data = text.encode("utf-8")
    del text, body
    try:
        df = pd.read_csv(io.BytesIO(data), sep=sep, header=None, names=list(range(ncol)), dtype=float,
                         na_values=_NA_TOKENS, keep_default_na=False, skip_blank_lines=False, engine="c",
                         **_EXACT_FLOATS)
    except (ValueError, TypeError, pd.errors.ParserError):
        return None
    if len(df) != len(data_idx):
        return None
    table = df.to_numpy(dtype=float)
    keep = ~np.isnan(table).all(axis=1)
    return table[keep], keep


def _mostly_numeric(cells) -> bool:
    if isinstance(cells, np.ndarray):
        return True
    vals = [c.strip() for c in cells if c.strip().lower() not in _MISSING_TOKENS]
    if not vals:
        return True
    return sum(_is_number(c) for c in vals[:200]) >= 0.5 * min(len(vals), 200)


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


_ISO_RE = re.compile(r"^\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}")
_DECIMAL_COMMA_RE = re.compile(r"^[-+]?\d*,\d+([eE][-+]?\d+)?$")


def _iso_seconds(cells: Sequence[str], col: str, where: _Where) -> np.ndarray:
    """ISO 8601 date-time stamps -> seconds after the first one."""
    stamps = pd.to_datetime(pd.Series([c.strip() for c in cells]), format="ISO8601", errors="coerce")
    bad = stamps.isna().to_numpy()
    if bad.any():
        i = int(np.argmax(bad))
        raise where.error(f"value {cells[i].strip()!r} is not a date-time stamp like the first one "
                          f"({cells[0].strip()!r}); fix the cell (every sample needs a time)", col, i,
                          value=cells[i].strip())
    if getattr(stamps.dt, "tz", None) is not None:
        stamps = stamps.dt.tz_convert("UTC")
    ns = stamps.to_numpy().astype("datetime64[ns]").astype(np.int64)
    return (ns - ns[0]) * 1e-9


#: a clock time ``HH:MM:SS[.fff]``, after an optional date in any spelling (``01/05/2024 10:00:00.1``)
_CLOCK_RE = re.compile(r"^(?:(?P<date>\S+)[ T])?(?P<h>\d{1,2}):(?P<m>[0-5]\d):(?P<s>[0-5]\d(?:[.,]\d+)?)$")


def _clock_seconds(cells: Sequence[str], col: str, where: _Where) -> np.ndarray:
    """Clock times ``HH:MM:SS[.fff]`` (time-of-day loggers) -> seconds after the first.

    A date before the clock time is accepted when it is written the same on every row (its day/month order
    then does not matter); a date that changes is an error (``01/05`` may be 1 May or 5 January: ISO 8601
    stamps say which).  A clock that steps back by more than 12 h has passed midnight: a day is added.
    """
    out = np.empty(len(cells))
    date0 = None
    for i, c in enumerate(cells):
        s = c.strip()
        m = _CLOCK_RE.match(s)
        if m is None or int(m.group("h")) > 23:
            raise where.error(f"value {s!r} is not a clock time like the first one ({cells[0].strip()!r}); fix "
                              "the cell (every sample needs a time)", col, i, value=s)
        if i == 0:
            date0 = m.group("date")
        elif m.group("date") != date0:
            raise where.error(f"the date changes from {date0!r} to {m.group('date')!r}; write the time as seconds "
                              "or as ISO 8601 stamps (2024-05-01T10:00:00.1): a date like 01/05 is ambiguous "
                              "(1 May or 5 January)", col, i, value=s)
        out[i] = int(m.group("h")) * 3600.0 + int(m.group("m")) * 60.0 + float(m.group("s").replace(",", "."))
    d = np.diff(out)
    if (d < -43200.0).any():
        out[1:] += 86400.0 * np.cumsum(d < -43200.0)
    return out - out[0]


def _to_float(cells: Sequence[str], ours: str, col: str, where: _Where, decimal_comma: bool = False) -> np.ndarray:
    if isinstance(cells, np.ndarray) and cells.dtype.kind == "f":
        return cells.copy()
    try:
        return np.asarray(cells, dtype=float)  # fast path: no blanks, all numbers
    except ValueError:
        pass
    out = np.empty(len(cells))
    for i, c in enumerate(cells):
        s = c.strip()
        if s.lower() in _MISSING_TOKENS:
            out[i] = np.nan
            continue
        try:
            out[i] = float(s)
        except ValueError:
            if decimal_comma and _DECIMAL_COMMA_RE.match(s):
                out[i] = float(s.replace(",", "."))
                continue
            hint = ""
            if re.fullmatch(r"[-+]?\d+,\d+", s):
                hint = " (decimal comma? save the file with decimal points)"
            raise LogError(f"{where.place(col, i)}: value {s!r} is not a number{hint}; fix the cell or leave it "
                           "blank for a missing sample", path=where.path, column=ours, row=where.row_of(i),
                           value=s) from None
    return out


#: largest schema/ship/metadata text read (bytes); such files are a few hundred bytes
_MAX_MAPPING_BYTES = 1_000_000


def parse_mapping_text(s: str, source: str, *, yaml_text: bool, what: str = "file") -> object:
    """JSON (or YAML) text -> the parsed object, through the guarded readers of :mod:`shipid._io` (syntax,
    nesting deeper than ``_io.MAX_DEPTH`` and size give one-line ValueErrors naming ``source``)."""
    if len(s) > _MAX_MAPPING_BYTES:
        raise ValueError(f"{source}: {len(s)} characters is far too large for a {what} "
                         f"(limit {_MAX_MAPPING_BYTES}); give a small mapping")
    kind = what.removesuffix(" file")
    if yaml_text:
        if importlib.util.find_spec("yaml") is None:
            raise ValueError(f"{source}: reading YAML needs PyYAML (pip install pyyaml); or write the "
                             f"{what} as JSON")
        return loads_yaml(s, source, kind)
    return loads_json(s, source, kind)


def load_mapping_file(p: Path, what: str) -> object:
    """Read a small JSON/YAML file (ship particulars, schema) -> the parsed object."""
    _check_path(p, what=what)
    if p.stat().st_size > _MAX_MAPPING_BYTES:
        raise ValueError(f"`{p.name}`: {p.stat().st_size} bytes is far too large for a {what} "
                         f"(limit {_MAX_MAPPING_BYTES}); give the small JSON mapping")
    try:
        s = p.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"`{p.name}`: {what} is not UTF-8 text; write it as JSON") from None
    yaml_text = p.suffix.lower() in (".yaml", ".yml")
    return parse_mapping_text(s, f"`{p.name}`", yaml_text=yaml_text, what=what)
