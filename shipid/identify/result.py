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

__all__ = ["FitResult", "load_result", "model_from", "software_versions", "diagnostics_to_json"]


def diagnostics_to_json(d: dict) -> dict:
    """JSON-friendly copy of a diagnostics dict from :func:`shipid.identify.diagnostics.identifiability`."""
    out = {k: v for k, v in d.items() if k not in ("correlation", "correlated_pairs")}
    out["correlation"] = {"names": list(d["correlation"].index), "matrix": d["correlation"].to_numpy().tolist()}
    out["correlated_pairs"] = [list(p) for p in d["correlated_pairs"]]
    return out


def _strict(obj):
    """A copy of ``obj`` with every non-finite float (NaN, +-inf) replaced by None (JSON null)."""
    if isinstance(obj, dict):
        return {k: _strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_strict(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


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
    inputs : list of dict -- one per log: name, path, sha256
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
        return cls(
            model=ident.model.name, coef={k: float(v) for k, v in ident.coef_.items()},
            coef_std={k: float(v) for k, v in ident.coef_std_.items()}, cov=ident.cov_.copy(),
            diagnostics=diag, inputs=[dict(m) for m in ident.logs_], method="ekf", settings=settings,
            loglik=ident.loglik_, success=ident.success_, message=ident.message_, versions=software_versions(),
            created=datetime.now(timezone.utc).isoformat(timespec="seconds"), model_options=ident.model.options(),
        )

    # ------------------------------------------------------------------- I/O
    def to_dict(self) -> dict:
        return {
            "model": self.model, "method": self.method, "success": self.success, "message": self.message,
            "coef": self.coef, "coef_std": self.coef_std,
            "cov": {"names": list(self.cov.index), "matrix": self.cov.to_numpy().tolist()},
            "diagnostics": self.diagnostics, "loglik": self.loglik, "settings": self.settings,
            "inputs": self.inputs, "versions": self.versions, "created": self.created, "extra": self.extra,
            "model_options": self.model_options,
        }

    def to_json(self, path, *, force: bool = False) -> Path:
        """Write atomically; an existing file is replaced only with ``force=True``.  Strict JSON:
        non-finite numbers (a diverged fit's log-likelihood, an undefined statistic) are written as null."""
        return atomic_write_text(path, json.dumps(_strict(self.to_dict()), indent=2, allow_nan=False) + "\n",
                                 force=force)

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
