"""Sphinx configuration of the shipid documentation.

Build: ``python -m sphinx -W -b html docs docs/_build/html`` from the repository root
(``pip install -e ".[docs]"`` first).  Every ``shipid`` command shown in a ``{shipid}``
block and every ``{code-cell}`` is executed during the build; a command whose exit status
differs from the one the page states fails the build.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
REPO = DOCS.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(DOCS / "_ext"))
# Executed pages and notebooks import the package of this checkout.
os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p)
os.environ.setdefault("MPLBACKEND", "Agg")

import shipid  # noqa: E402
import reference_pages  # noqa: E402

project = "shipid"
author = "shipid developers"
copyright = "shipid developers"
release = version = shipid.__version__

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "shipid_run",
]

exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**.ipynb_checkpoints", "README.md"]
source_suffix = {".md": "myst-nb", ".rst": "restructuredtext", ".ipynb": "myst-nb"}

# MyST
myst_enable_extensions = ["colon_fence", "dollarmath", "deflist"]
myst_heading_anchors = 3

# Executed code: every {code-cell} runs in a fresh kernel per page; an error fails the build.
nb_execution_mode = "force"
nb_execution_timeout = 600
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True

# API reference: one page per public name, from the public packages' __all__.
autosummary_generate = True
autodoc_default_options = {"members": False}
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks = set()
numpydoc_xref_param_type = False

html_theme = "furo"
html_title = f"shipid {release}"
html_static_path = []
pygments_style = "sphinx"

# Work folders of the {shipid} blocks: the repository's data beside them, ../shared when present.
shipid_run_repo = str(REPO)


def setup(app):
    reference_pages.write(DOCS / "reference")
