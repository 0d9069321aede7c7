"""Write the API reference pages (``docs/reference/*.rst``) from the public packages.

One page per public package, listing the names of its ``__all__`` (or, for a module without
``__all__``, the public functions and classes defined in it); each name gets its own page by
autosummary.  A name re-exported by several packages is documented once, under the first
package below that exports it, and linked from the others.  The pages are generated, so a
module moved inside a package changes nothing here.
"""
from __future__ import annotations

import importlib
import inspect
from pathlib import Path

# Public packages and modules, in the order of the data flow (logs -> identify -> ... -> use).
PACKAGES = [
    ("shipid.logs", "Trial logs: reading, checking, ship particulars"),
    ("shipid.models", "Models: the protocol and the registry"),
    ("shipid.identify", "Identification: the fit recipe, the EKF, results"),
    ("shipid.results", "The result contract every result follows"),
    ("shipid.simulate", "Simulation"),
    ("shipid.manoeuvres", "Standard manoeuvres and their metrics"),
    ("shipid.validation", "Validation: replay, metrics, horizon predictions"),
    ("shipid.report", "HTML report"),
    ("shipid.uncertainty", "Uncertainty propagation"),
    ("shipid.campaign", "Campaigns on Dask"),
    ("shipid.environment", "Wind, current and low speed"),
    ("shipid.scaling", "Froude scaling"),
    ("shipid.control", "Optimal control"),
    ("shipid.routing", "Routing in currents"),
    ("shipid.glider", "Underwater glider"),
    ("shipid.synthetic", "Synthetic trial logs"),
    ("shipid", "Top-level names"),
]


def public_names(mod) -> list[str]:
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [n for n, o in vars(mod).items()
                 if not n.startswith("_") and (inspect.isfunction(o) or inspect.isclass(o))
                 and getattr(o, "__module__", "") == mod.__name__]
    out = []
    for n in names:
        obj = getattr(mod, n, None)
        if obj is None or inspect.ismodule(obj) or n.startswith("_"):
            continue
        out.append(n)
    return sorted(set(out), key=str.lower)


def write(folder: Path) -> None:
    folder.mkdir(exist_ok=True)
    seen: dict = {}
    pages = []
    for pkg, title in PACKAGES:
        try:
            mod = importlib.import_module(pkg)
        except (ImportError, AttributeError):
            continue  # a module that does not exist in this checkout
        own, linked = [], []
        for n in public_names(mod):
            obj = getattr(mod, n)
            key = id(obj)
            if not (inspect.isclass(obj) or callable(obj)):
                key = f"{pkg}.{n}"  # constants: their identity says nothing
            if key in seen:
                linked.append((n, seen[key]))
            else:
                seen[key] = f"{pkg}.{n}"
                own.append(n)
        doc = (inspect.getdoc(mod) or "").strip().split("\n\n")[0]
        lines = [f"``{pkg}``: {title}", "=" * (len(pkg) + 6 + len(title)), "",
                 f".. currentmodule:: {pkg}", ""]
        if own:
            lines += [".. autosummary::", "   :toctree: generated", "   :nosignatures:", ""]
            lines += [f"   {n}" for n in own] + [""]
        if linked:
            lines += ["Also available here (documented where they are defined):", ""]
            lines += [f"* ``{pkg}.{n}``: :py:obj:`{target}`" for n, target in linked] + [""]
        page = folder / f"{pkg}.rst"
        text = "\n".join(lines)
        if not page.exists() or page.read_text() != text:
            page.write_text(text)
        pages.append(pkg)
    for stale in folder.glob("shipid*.rst"):  # a package that no longer exists
        if stale.stem not in pages:
            stale.unlink()
    index = ["API reference", "=============", "",
             "Every public name of the package, generated from its docstrings and grouped by package "
             "in the order data flow through shipid: logs, models, identification, simulation and "
             "validation, then the uses of a model.", "",
             ".. toctree::", "   :maxdepth: 1", ""] + [f"   {p}" for p in pages] + [""]
    text = "\n".join(index)
    idx = folder / "index.rst"
    if not idx.exists() or idx.read_text() != text:
        idx.write_text(text)
