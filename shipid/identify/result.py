"""Fit results as files: JSON that records the model, coefficients,
uncertainties, diagnostics, inputs (path + sha256) and software versions, and
loads back into a model."""
from __future__ import annotations

import json
import platform
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from .._io import atomic_write_text

__all__ = ["FitResult", "load_result", "model_from", "software_versions", "diagnostics_to_json", "fitted_ship"]


def fitted_ship(model, inputs, ship: dict | None = None) -> tuple[dict, dict]:
    """``(model_options, ship)`` of a fit of ``model`` to logs described by ``inputs`` (their metadata:
    each log's particulars under ``ship``, its ``lpp``): the particulars and the Lpp the fit belongs to.

    A model with dimensional coefficients (``prime_exponents``: kcs-response, response-nl) fitted to logs
    of one ship belongs to that ship, whatever length its start values had: its ``lpp`` option becomes
    the logs' and its design speed and rudder rate those of the logs' particulars (Froude-scaled from
    the start model where the particulars do not state them).  Other models keep their options (an
    ``mmg`` model's particulars are part of its equations).  ``ship`` overrides the logs' particulars.
    """
    opts = dict(model.options())
    lpps = {float(m["lpp"]) for m in inputs if m.get("lpp")}
    if ship is None:
        ships = [m["ship"] for m in inputs if m.get("ship")]
        ship = dict(ships[0]) if ships and all(s == ships[0] for s in ships) else {}
    ship = dict(ship)
    if len(lpps) != 1 and "lpp" not in ship:
        return opts, ship
    L = float(ship.get("lpp", next(iter(lpps))))
    ship["lpp"] = L
    if getattr(model, "prime_exponents", None):
        lam = L / opts.get("lpp", L)
        if "design_speed" in opts:
            opts["design_speed"] = opts["design_speed"] * lam ** 0.5
        if "rudder_rate" in opts:
            opts["rudder_rate"] = opts["rudder_rate"] / lam ** 0.5
        opts["lpp"] = L
        for k in ("design_speed", "rudder_rate"):
            if ship.get(k):
                opts[k] = float(ship[k])
    return opts, ship


def _inputs(metas) -> list[dict]:
    """The result's ``inputs`` entries (name, path, sha256, lpp; the particulars go to ``ship``)."""
    return [{k: v for k, v in m.items() if k != "ship"} for m in metas]


def diagnostics_to_json(d: dict) -> dict:
    """JSON-friendly copy of a diagnostics dict from :func:`shipid.identify.diagnostics.identifiability`."""
    out = {k: v for k, v in d.items() if k not in ("correlation", "correlated_pairs")}
    out["correlation"] = {"names": list(d["correlation"].index), "matrix": d["correlation"].to_numpy().tolist()}
    out["correlated_pairs"] = [list(p) for p in d["correlated_pairs"]]
    return out


def software_versions() -> dict:
    """Versions of Python and the packages a result depends on."""
    import filterpy
    import matplotlib
    import scipy

    from .. import __version__

    return {"shipid": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "pandas": pd.__version__, "filterpy": filterpy.__version__,
            "matplotlib": matplotlib.__version__}


@dataclass
class FitResult:
    """Serialisable result of an identification.

    Attributes
    ----------
    model : str -- registered model name
    coef : dict -- all parameters (estimated and fixed) name -> value
    coef_std : dict -- standard deviation (0 for fixed parameters)
    cov : DataFrame -- covariance of the estimated parameters
    diagnostics : dict -- JSON-friendly identifiability diagnostics
    inputs : list of dict -- one per log: name, path, sha256, lpp
    model_options : dict -- keyword arguments that rebuild the model (its ship: lpp, particulars, ...)
    ship : dict -- particulars of the logs the fit was made on (``lpp`` [m], ...; see :func:`fitted_ship`)
    method : str, settings : dict, loglik : float, success : bool, message : str
    versions : dict, created : str (UTC ISO time)
    """

    model: str
    coef: dict
    coef_std: dict
    cov: pd.DataFrame
    diagnostics: dict = field(default_factory=dict)
    inputs: list = field(default_factory=list)
    method: str = "ekf"
    settings: dict = field(default_factory=dict)
    loglik: float | None = None
    success: bool = True
    message: str = ""
    versions: dict = field(default_factory=dict)
    created: str = ""
    extra: dict = field(default_factory=dict)
    model_options: dict = field(default_factory=dict)
    ship: dict = field(default_factory=dict)

    @classmethod
    def from_identifier(cls, ident) -> "FitResult":
        diag = diagnostics_to_json(ident.diagnostics_)
        settings = {
            "estimated": ident.estimated_,
            "meas_std": ident.meas_std_.to_dict(),
            "process_std": ident.process_std_.to_dict(),
            "prior_std": ident.prior_std_.to_dict(),
            "scale": ident.scale_.to_dict(),
            "n_passes": int(ident.n_passes),
            "param_walk": float(ident.param_walk),
            "substeps": int(ident.substeps),
            "discretisation": ident.method,
        }
        opts, ship = fitted_ship(ident.model, ident.logs_)
        return cls(
            model=ident.model.name, coef={k: float(v) for k, v in ident.coef_.items()},
            coef_std={k: float(v) for k, v in ident.coef_std_.items()}, cov=ident.cov_.copy(),
            diagnostics=diag, inputs=_inputs(ident.logs_), method="ekf", settings=settings,
            loglik=ident.loglik_, success=ident.success_, message=ident.message_, versions=software_versions(),
            created=datetime.now(timezone.utc).isoformat(timespec="seconds"), model_options=opts, ship=ship,
        )

    # ------------------------------------------------------------------- I/O
    def to_dict(self) -> dict:
        return {
            "model": self.model, "method": self.method, "success": self.success, "message": self.message,
            "coef": self.coef, "coef_std": self.coef_std,
            "cov": {"names": list(self.cov.index), "matrix": self.cov.to_numpy().tolist()},
            "diagnostics": self.diagnostics, "loglik": self.loglik, "settings": self.settings,
            "inputs": self.inputs, "versions": self.versions, "created": self.created, "extra": self.extra,
            "model_options": self.model_options, "ship": self.ship,
        }

    def to_json(self, path, *, force: bool = False) -> Path:
        """Write atomically; an existing file is replaced only with ``force=True``."""
        return atomic_write_text(path, json.dumps(self.to_dict(), indent=2, allow_nan=True) + "\n", force=force)

    @classmethod
    def from_dict(cls, doc: dict, source: str = "result") -> "FitResult":
        for key in ("model", "coef"):
            if key not in doc:
                raise ValueError(f"{source}: not a shipid fit result (no '{key}' entry)")
        cov = doc.get("cov") or {"names": [], "matrix": []}
        names = cov.get("names", [])
        mat = np.array(cov.get("matrix", []), dtype=float).reshape(len(names), len(names))
        return cls(
            model=doc["model"], coef=dict(doc["coef"]), coef_std=dict(doc.get("coef_std", {})),
            cov=pd.DataFrame(mat, index=names, columns=names), diagnostics=doc.get("diagnostics", {}),
            inputs=doc.get("inputs", []), method=doc.get("method", "ekf"), settings=doc.get("settings", {}),
            loglik=doc.get("loglik"), success=doc.get("success", True), message=doc.get("message", ""),
            versions=doc.get("versions", {}), created=doc.get("created", ""), extra=doc.get("extra", {}),
            model_options=dict(doc.get("model_options") or (doc.get("extra") or {}).get("model_options") or {}),
            ship=dict(doc.get("ship") or {}),
        )

    def to_model(self):
        """The registered model with these coefficients (and its options, e.g. MMG particulars)."""
        from ..models import get_model

        if not isinstance(self.coef, dict):
            raise ValueError("fit result: 'coef' must be a mapping name -> value")
        try:
            return get_model(self.model, self.coef, **self.model_options)
        except TypeError as exc:
            raise ValueError(f"fit result: cannot build model '{self.model}' with options {self.model_options}: {exc}") from None

    def summary(self) -> pd.DataFrame:
        est = list(self.cov.index)
        v = pd.Series({k: self.coef[k] for k in est})
        sd = pd.Series({k: self.coef_std.get(k, np.nan) for k in est})
        return pd.DataFrame({"value": v, "std": sd, "rel_std_%": 100 * sd / v.abs().where(v.abs() > 0),
                             "ci95_low": v - 1.96 * sd, "ci95_high": v + 1.96 * sd})


def model_from(spec, *, model: str | None = None):
    """A model (and the fit result, if any) from any of the ways a user names one.

    Parameters
    ----------
    spec : FitResult, dict (result JSON), path to a result JSON, Model, or ``"name[:parameter-set]"``
    model : str, optional
        Registered model the result must be for (ValueError otherwise).

    Returns
    -------
    (Model, FitResult or None)
    """
    import os

    from ..models import Model, available_models, get_model

    res = None
    if isinstance(spec, Model):
        m = spec
    elif isinstance(spec, FitResult):
        res = spec
    elif isinstance(spec, dict):
        res = FitResult.from_dict(spec)
    elif isinstance(spec, (str, os.PathLike)):
        p = Path(spec)
        if p.suffix.lower() == ".json" or p.is_file():
            res = load_result(p)
        else:
            name, _, pset = str(spec).partition(":")
            if name not in available_models():
                raise ValueError(f"'{spec}' is neither a result file nor a registered model; "
                                 f"models: {', '.join(available_models())}")
            m = get_model(name, pset or None)
    else:
        raise ValueError(f"expected a fit result, a result JSON, a model or 'name[:set]', got {type(spec).__name__}")
    if res is not None:
        m = res.to_model()
    if model is not None and m.name != model:
        raise ValueError(f"{spec if isinstance(spec, (str, os.PathLike)) else 'result'}: model is '{m.name}', expected '{model}'")
    return m, res


def load_result(path) -> FitResult:
    """Read a fit result JSON written by :meth:`FitResult.to_json` / ``shipid fit``."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such result file; run `shipid fit` first or check the path")
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{p}: not a JSON fit result ({exc}); pass the file written by `shipid fit -o`") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{p}: not a shipid fit result (top level is not an object)")
    return FitResult.from_dict(doc, source=str(p))
