"""HTML building blocks of the report: escaping, number cells, tables and embedded figures."""
from __future__ import annotations

import html
import math
from typing import Any, Sequence

from . import figures


def _e(x: Any) -> str:
    return html.escape("" if x is None else str(x), quote=True)


def _f(v, fmt: str = "{:.4g}") -> str:
    if v is None or isinstance(v, bool):
        return "&ndash;" if v is None else _e(v)
    try:
        v = float(v)
    except (TypeError, ValueError):
        return _e(v)
    return "&ndash;" if not math.isfinite(v) else _e(fmt.format(v))


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], left: int = 1, cls: str = "") -> str:
    """Rows are already-escaped HTML cell contents (or (content, css class) tuples)."""
    th = "".join(f'<th class="l">{h}</th>' if i < left else f"<th>{h}</th>" for i, h in enumerate(header))
    body = []
    for r in rows:
        cells = []
        for i, c in enumerate(r):
            css = "l" if i < left else ""
            if isinstance(c, tuple):
                c, extra = c
                css = f"{css} {extra}".strip()
            cells.append(f'<td class="{css}">{c}</td>' if css else f"<td>{c}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f'<table class="{cls}"><thead><tr>{th}</tr></thead><tbody>' + "".join(body) + "</tbody></table>"


def _img(uri: str, alt: str) -> str:
    return f'<img src="{uri}" alt="{_e(alt)}">'


def _fig(fig, alt: str) -> str:
    return _img(figures.to_data_uri(fig), alt)
