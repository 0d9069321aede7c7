"""Self-contained HTML validation report of an identified model (:func:`write_report`)."""
from .html import render_report, write_report

__all__ = ["write_report", "render_report"]
