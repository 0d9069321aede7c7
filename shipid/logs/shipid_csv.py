"""The default shipid CSV format: a header of channel names with bracketed units.

Conventions: one header line (``# ...`` comment lines before it are skipped;
``# shipid-log:`` / ``# shipid-ship:`` lines carry the name and particulars
written by :meth:`TrialLog.to_csv`), velocities in body axes, rudder and
heading in the shipid convention, units from the header or ``units=``
(default SI/radians).
"""
from __future__ import annotations

import csv
import re
import warnings
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ._text import (_CLOCK_RE, _DECIMAL_COMMA_RE, _DELIMS, _ISO_RE, _clock_seconds, _fast_table, _is_number,
                    _iso_seconds, _mostly_numeric, _parse_meta, _split_header, _to_float)
from .marin import _looks_marin
from .trial_log import LogError, _convert_units, _fmt_value, _short_list, _Where, required_channels
from .units import SCHEMA, SHIP_CHANNELS, UNITS, unit_key

def _read_csv(text: str, p: Path, columns: Mapping[str, str], units: Mapping[str, str],
              required: Sequence[str], delimiter: str | None, *, skip_rows: int = 0, header: bool = True,
              optional: Sequence[str] = ()):
    """Read a delimited or whitespace text table.

    ``optional``: channels of ``columns`` whose column may be absent (the log then has no such
    channel; a note says so), e.g. a schema's wind channels on a run logged without them.

    ``skip_rows`` lines are skipped first (a preamble); then ``#`` comment and
    blank lines; the next line is the header (``header=True``) or the first
    data row (``header=False``: columns are named ``col1, col2, ...`` and are
    mapped by number or by those names).
    """
    lines = text.splitlines()
    meta: dict = {}
    h = None
    if skip_rows >= len(lines):
        raise LogError(f"`{p.name}`: skip_rows = {skip_rows} but the file has only {len(lines)} line(s); "
                       "give a smaller --skip-rows", path=p, value=skip_rows)
    for k, line in enumerate(lines):
        if k < skip_rows:
            continue
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            _parse_meta(s, meta, p, k + 1)
            continue
        h = k
        break
    if h is None:
        raise LogError(f"`{p.name}`: file has no header line (only blank or # comment lines); "
                       "give a header like 'time [s], x [m], ...' and data rows", path=p)
    header_line = lines[h]
    data_idx = [k for k in range(h + (0 if not header else 1), len(lines)) if lines[k].strip()]
    # --- delimiter --------------------------------------------------------------
    if delimiter is None:
        delim = ","
        if "," not in header_line:
            # the header decides: a comma-free header holding ';' or a tab is a delimiter mistake
            shown = _fmt_value(header_line.strip())
            for cand, label, cli in ((";", "semicolon", ";"), ("\t", "tab", "tab")):
                if cand in header_line:
                    raise LogError(f"`{p.name}` row {h + 1}: the header has no commas but is {label}-separated "
                                   f"({shown}); pass delimiter={cand!r} (CLI: --delimiter {cli}) or save the file "
                                   "as comma-separated CSV", path=p, row=h + 1, value=header_line.strip())
            first = lines[data_idx[0]].split() if data_idx else []
            ntok = len(header_line.split())
            if ntok > 1 and len(first) == ntok and "," not in lines[data_idx[0]]:
                raise LogError(f"`{p.name}` row {h + 1}: the header has no commas but is whitespace-separated "
                               f"({shown}); pass delimiter='whitespace' (CLI: --delimiter whitespace) or save the "
                               "file as comma-separated CSV", path=p, row=h + 1, value=header_line.strip())
    else:
        delim = {"tab": "\t", "\\t": "\t", "space": "whitespace", "spaces": "whitespace"}.get(delimiter, delimiter)
        if delim not in _DELIMS:
            raise ValueError(f"delimiter={delimiter!r}: use ',', ';', '\\t' (tab) or 'whitespace'")

    def split(s: str) -> list[str]:
        if delim == "whitespace":
            return s.split()
        try:
            return next(csv.reader([s], delimiter=delim))
        except csv.Error as exc:
            raise _cell_error(p, h, s, exc) from None

    hdr = [c.strip() for c in split(header_line)]
    if not header:  # no header line: the first data row gives the number of columns
        hdr = [f"col{j + 1}" for j in range(len(hdr))]
    else:  # look-alike letters (Cyrillic 'р' for 'p', full-width 'ｕ') and invisible characters: read as plain,
        # and said (shipid.logs.sensors): else they make an extra channel and leave the real one unlogged
        from .sensors import plain_header

        for j, cell in enumerate(hdr):
            fixed, chars = plain_header(cell)
            if chars:
                meta.setdefault("_lookalike", []).append((j, cell, fixed.strip(), chars))
                hdr[j] = fixed.strip()
    if not hdr or all(not c for c in hdr):
        raise LogError(f"`{p.name}` row {h + 1}: empty header", path=p, row=h + 1)
    parsed = [_split_header(c) for c in hdr]
    names = [n for n, _ in parsed]
    # numeric header: the file has no header line
    if header and all(_is_number(n) for n in names if n):
        raise LogError(f"`{p.name}` row {h + 1}: the first line is numbers, not a header "
                       f"({_fmt_value(header_line.strip())}); add a header line like "
                       "'time [s], x [m], y [m], psi [rad], u [m/s], v [m/s], r [rad/s], delta [rad], n [rps]', "
                       "or pass header=False (CLI: --no-header) and map the columns by number",
                       path=p, row=h + 1, value=header_line.strip())
    # --- map file columns to our names ---------------------------------------------
    colmap: dict[str, int] = {}   # our name -> column index
    absent: list[str] = []        # optional channels whose column is not in the file
    taken: set[int] = set()
    for ours, theirs in columns.items():
        if isinstance(theirs, (int, np.integer)) and not isinstance(theirs, bool):
            if not 1 <= theirs <= len(hdr):
                raise LogError(f"`{p.name}` row {h + 1}: columns maps '{ours}' to column number {theirs} but the "
                               f"header has {len(hdr)} columns (numbers count from 1)", path=p, column=ours,
                               row=h + 1, value=theirs)
            j = int(theirs) - 1
        else:
            j = _find_col(str(theirs), hdr, names)
            if j is None and str(theirs).strip().isdigit() and 1 <= int(theirs) <= len(hdr):
                j = int(theirs) - 1  # a column number given as text (CLI --column u=5)
        if j is None and ours in optional:
            absent.append(f"{ours} ('{theirs}')")
            continue
        if j is None:
            raise LogError(f"`{p.name}` row {h + 1}: columns maps '{ours}' to '{theirs}' but the header has no such "
                           f"column; header: {', '.join(hdr)}", path=p, column=ours, row=h + 1, value=theirs)
        colmap[ours] = j
        taken.add(j)
    known = set(SHIP_CHANNELS) | set(required)
    for j, nm in enumerate(names):  # exact names of known channels
        if j in taken or nm not in known or nm in colmap:
            continue
        colmap[nm] = j
        taken.add(j)
    # case-insensitive fallback ("Time", "PSI") for known names, never stealing a known name ("U" stays U)
    for want in list(dict.fromkeys([*required, *SCHEMA])):
        if want in colmap:
            continue
        cands = [j for j, nm in enumerate(names)
                 if j not in taken and nm.lower() == want.lower() and nm not in SHIP_CHANNELS]
        if len(cands) == 1:
            colmap[want] = cands[0]
            taken.add(cands[0])
    kept = required_channels(required, colmap)[0]  # (velocities may be missing beside a track; said later)
    def near(c):  # a known channel of another case ('U', the speed over ground) is never taken for 'u' unasked
        return next((nm for nm in names if nm.lower() == c.lower() and nm in SHIP_CHANNELS), None)

    for c in [c for c in required if c not in kept]:
        other = near(c)
        if other:  # not logged -- unless the file's 'U' (the speed over ground) was meant: say how to map it
            absent.append(f"{c} (the file's '{other}' is read as channel '{other}'; if it is '{c}': "
                          f"--columns {c}={other})")
    required = kept
    missing_cols = [c for c in required if c not in colmap]
    if missing_cols:
        c = missing_cols[0]
        single = " (the header is a single column: is the file comma-separated?)" if len(hdr) == 1 else ""
        other = [d for d in (";", "\t") if d != delim and d in header_line]
        if len(hdr) == 1 and other:   # delimiter=',' given for a semicolon/tab file
            cli = "tab" if other[0] == "\t" else other[0]
            raise LogError(f"`{p.name}` row {h + 1}: the header is one column holding {_DELIMS[other[0]]}s "
                           f"({_fmt_value(header_line.strip())}); pass delimiter={other[0]!r} (CLI: --delimiter {cli})",
                           path=p, row=h + 1, value=header_line.strip())
        if _looks_marin(header_line):
            single = " (this looks like a MARIN .dat file: pass fmt='marin')"
        other = near(c)
        if other:
            single = f" ('{other}' is read as channel '{other}', not '{c}'; if it is '{c}': --column {c}={other})"
        raise LogError(f"`{p.name}` row {h + 1}: required column '{c}' not found; header has "
                       f"{', '.join(repr(x) for x in hdr)}{single}; rename the column or map it with "
                       f"columns={{'{c}': 'your name'}} (CLI: --column {c}=NAME)", path=p, column=c, row=h + 1)
    # --- a units row right under the header ("s, m, m, deg, ..."), as some loggers write ----------
    data_idx = [k for k in data_idx if not lines[k].lstrip().startswith("#")]
    units_row = None
    if header and data_idx:
        cells = split(lines[data_idx[0]])
        row_units = _units_row(cells, len(hdr))
        if row_units is not None:
            units_row = data_idx.pop(0) + 1
            for j, u in enumerate(row_units):
                if u is None:
                    continue
                if parsed[j][1] is not None and unit_key(parsed[j][1]) != unit_key(u):
                    raise LogError(f"`{p.name}` row {units_row}: column '{hdr[j]}' has the unit {parsed[j][1]!r} in "
                                   f"the header but {u!r} in the units row below it; fix one of them, or declare "
                                   f"the unit with units= (CLI: --units CH=UNIT)", path=p, row=units_row, value=u)
                parsed[j] = (parsed[j][0], u)
    header_units = {ours: parsed[j][1] for ours, j in colmap.items() if parsed[j][1] is not None}
    file_col = {ours: names[j] or hdr[j] for ours, j in colmap.items()}
    # --- data rows -----------------------------------------------------------------
    if not data_idx:
        raise LogError(f"`{p.name}`: header only, no data rows; the log needs samples below the header",
                       path=p, row=h + 1)
    ncol = len(hdr)
    rows_txt: list = []
    keep_rows: list[int] = []
    blank_rows: list[int] = []   # rows of empty cells (bare delimiters), dropped with a note
    cut = _cut_last_row(text, lines, data_idx, split, ncol) if header and data_idx else None
    if cut is not None:  # a last row cut short (no line end): dropped, and said (shipid.logs.sensors)
        meta["_truncated"] = cut
        data_idx = data_idx[:-1]
    fast = _fast_table(lines, data_idx, delim, ncol)
    if fast is not None:  # all cells numeric or blank, every row complete: pandas' C parser did the work
        table, keep = fast
        rows_txt = [None] * int(keep.sum())
        keep_rows = [k + 1 for k, ok in zip(data_idx, keep) if ok]
        blank_rows = [k + 1 for k, ok in zip(data_idx, keep) if not ok]
        data_idx = []
    if delim == "whitespace":
        split_rows = (lines[k].split() for k in data_idx)
    else:
        split_rows = csv.reader((lines[k] for k in data_idx), delimiter=delim)
    try:
        for k, cells in zip(data_idx, split_rows):
            s = lines[k]
            if (not cells or not cells[0].strip()) and all(not c.strip() for c in cells):  # bare delimiters
                blank_rows.append(k + 1)
                continue
            if len(cells) != ncol:
                other = [d for d in (";", "\t") if d != delim and d in s]
                extra = f"; the row contains {_DELIMS[other[0]]}s: wrong delimiter?" if other and len(cells) == 1 else ""
                raise LogError(f"`{p.name}` row {k + 1}: {len(cells)} field(s) but the header has {ncol}{extra}; "
                               "fix the row (every row needs one cell per header column, blank = missing)",
                               path=p, row=k + 1, value=s.strip()[:60])
            rows_txt.append(cells)
            keep_rows.append(k + 1)
    except csv.Error as exc:
        k = data_idx[max(split_rows.line_num - 1, 0)]
        raise _cell_error(p, k, lines[k], exc) from None
    if not rows_txt:
        raise LogError(f"`{p.name}`: header only, no data rows; the log needs samples below the header",
                       path=p, row=h + 1)
    rows = np.asarray(keep_rows, dtype=np.int64)
    where = _Where(p, p.stem, rows)
    cols = list(table.T) if fast is not None else list(zip(*rows_txt))
    arrays: dict[str, np.ndarray] = {}
    first_stamp = None
    for ours, j in colmap.items():
        if ours == "time" and fast is None and _ISO_RE.match(cols[j][0].strip()):
            arrays[ours] = _iso_seconds(cols[j], names[j] or hdr[j], where)
            first_stamp = cols[j][0].strip()
            continue
        if ours == "time" and fast is None and _CLOCK_RE.match(cols[j][0].strip()):
            arrays[ours] = _clock_seconds(cols[j], names[j] or hdr[j], where)
            first_stamp = cols[j][0].strip()
            continue
        arrays[ours] = _to_float(cols[j], ours, names[j] or hdr[j], where, decimal_comma=delim != ",")
    if "time" not in arrays:
        raise LogError(f"`{p.name}` row {h + 1}: no 'time' column; header has {', '.join(repr(x) for x in hdr)}; "
                       "map it with columns={'time': 'your name'}", path=p, column="time", row=h + 1)
    # unknown extra columns: keep when numeric, else ignore with a warning
    notes: list[str] = []
    if units_row is not None:
        notes.append(f"row {units_row} under the header read as the columns' units: "
                     + ", ".join(f"{hdr[j]} [{u}]" for j, (_, u) in enumerate(parsed) if u is not None))
    if absent:
        notes.append(f"optional channel(s) not in the file: {', '.join(absent)}")
    if first_stamp is not None:
        notes.append(f"time given as date-time or clock stamps; t = 0 s at {first_stamp}")
    if blank_rows:
        trailing = blank_rows[0] > rows[-1]
        notes.append(f"{len(blank_rows)} {'trailing ' if trailing else ''}row(s) of empty cells dropped "
                     f"(rows {_short_list(blank_rows, 3)})")
    order = ["time"] + [c for c in SCHEMA[1:] if c in arrays] + [c for c in arrays if c not in SCHEMA]
    arrays = {c: arrays[c] for c in order}
    extra_at: dict[str, int] = {}   # extra channel -> its column index
    for j, nm in enumerate(names):
        if j in taken:
            continue
        label = nm or f"column {j + 1}"
        empty = (np.isnan(cols[j]).all() if isinstance(cols[j], np.ndarray)
                 else all(not c.strip() for c in cols[j]))
        if not nm and empty:  # trailing delimiter: an empty unnamed column
            continue
        if not _mostly_numeric(cols[j]):
            notes.append(f"column '{hdr[j]}' is not numeric; ignored")
            warnings.warn(f"`{p.name}`: column '{hdr[j]}' is not numeric; ignored", stacklevel=3)
            continue
        # a mostly numeric column: a bad cell is an error
        if label in arrays and label in columns:
            notes.append(f"column '{hdr[j]}' ignored: columns= maps '{label}' to '{columns[label]}'")
            continue
        if label in arrays:
            first = colmap.get(label, extra_at.get(label, j))
            raise LogError(f"`{p.name}` row {h + 1}: column '{label}' appears twice (columns {first + 1} and "
                           f"{j + 1} of the header); rename one, or pick one by number with "
                           f"columns={{'{label}': {first + 1}}}",
                           path=p, column=label, row=h + 1, value=hdr[j])
        a = _to_float(cols[j], label, label, where, decimal_comma=delim != ",")
        arrays[label] = a
        extra_at[label] = j
        if parsed[j][1] is not None and (unit_key(parsed[j][1]) in UNITS or label in units):
            header_units[label] = parsed[j][1]
            file_col[label] = label
        elif parsed[j][1] is not None:  # an extra column in a unit shipid does not convert (V, %, degC): as is
            notes.append(f"column '{hdr[j]}' kept as channel '{label}' in its own unit {parsed[j][1]!r} "
                         "(not a unit shipid converts; the channel is not used by the models)")
    where.sources = {c: f"column {j + 1} '{hdr[j]}'" for c, j in {**colmap, **extra_at}.items()}
    t, ch, units_in = _convert_units(arrays, units, header_units, where, file_col)
    return t, ch, where, units_in, notes, meta


def _cut_last_row(text: str, lines: list, data_idx: list, split, ncol: int) -> dict | None:
    """``{"row", "why"}`` when the file's last row lacks its line end and is cut short: fewer cells than the
    header, or a last cell shorter than that column's cell in every one of the 20 rows before it (a number
    cut mid-way; the columns of one log are printed at a steady width)."""
    if text.endswith(("\n", "\r")) or len(data_idx) < 2:
        return None
    k = data_idx[-1]
    try:
        cells = split(lines[k])
    except Exception:  # noqa: BLE001 - an unparsable last row is reported by the row checks
        return None
    if len(cells) < ncol:
        return {"row": k + 1, "why": f"{len(cells)} of {ncol} cells"}
    if len(cells) != ncol:
        return None
    prev = []
    for kk in data_idx[-21:-1]:
        try:
            c = split(lines[kk])
        except Exception:  # noqa: BLE001
            return None
        if len(c) == ncol:
            prev.append(len(c[-1].strip()))
    last = cells[-1].strip()
    if len(prev) >= 5 and len(last) < min(prev):
        return {"row": k + 1, "why": f"its last value {last!r} is shorter than that column's others"}
    return None


def _cell_error(p: Path, k: int, line: str, exc: Exception) -> LogError:
    """csv module errors (a field over its size limit, a NUL, a stray quote) as one line naming the row."""
    msg = str(exc)
    if "field larger than field limit" in msg:
        what = (f"a cell of more than {csv.field_size_limit()} characters (the row has {len(line)}); a log cell "
                "holds a number or a short text: fix or delete the row")
    else:
        what = f"cannot be split into cells ({msg}); fix the row's quoting"
    return LogError(f"`{p.name}` row {k + 1}: {what}", path=p, row=k + 1, value=line[:60])


#: a date/clock format written where a unit would be (``hh:mm:ss.sss``, ``dd/mm/yyyy hh:mm:ss``)
_STAMP_FORMAT_RE = re.compile(r"(?=.*[:/])[ymdhsfYMDHSF:/.\- T]+")


def _units_row(cells: list[str], ncol: int) -> list[str | None] | None:
    """The units of a units row under the header (``s, m, [deg], (m/s), -, ...``; a blank or ``-`` cell:
    no unit), or None when ``cells`` is not one: a units row has one cell per column, no number in any
    cell, and at least one cell that is a unit shipid knows."""
    if len(cells) != ncol:
        return None
    out: list[str | None] = []
    known = 0
    for c in cells:
        s = c.strip()
        if _is_number(s) or _DECIMAL_COMMA_RE.match(s):
            return None
        if s[:1] in "[(" and s[-1:] in "])":
            s = s[1:-1].strip()
        if unit_key(s) in UNITS:
            known += 1
            out.append(s)
        elif s.lower() in ("", "-", "--") or _STAMP_FORMAT_RE.fullmatch(s):  # no unit; a clock format (hh:mm:ss)
            out.append(None)
        else:
            out.append(s)
    return out if known else None


def _find_col(theirs: str, hdr: list[str], names: list[str]) -> int | None:
    t = theirs.strip()
    for cands in (hdr, names):
        hits = [j for j, c in enumerate(cands) if c == t]
        if len(hits) == 1:
            return hits[0]
    hits = [j for j, c in enumerate(names) if c.lower() == t.lower()]
    return hits[0] if len(hits) == 1 else None
