"""Fit results as files: JSON that records the model, coefficients,
uncertainties, diagnostics, inputs (path + sha256) and software versions, and
loads back into a model."""
from __future__ import annotations

import os
import platform
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from .._io import (as_bool, as_mapping, as_number, as_string, atomic_write_text, dumps_json, read_json, short)
from .._version import __version__
from ..models import available_models, get_model, Model
from ..results import ResultMixin, coefficient_table, plot_coefficients, verdict_grade
from .verdict import Verdict

__all__ = ["FitResult", "load_result", "as_result", "model_from", "software_versions", "diagnostics_to_json", "fitted_ship"]


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
    # imported here only to read their versions: filterpy and matplotlib are not loaded otherwise
    import filterpy
    import matplotlib
    import scipy

    return {"shipid": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "pandas": pd.__version__, "filterpy": filterpy.__version__,
            "matplotlib": matplotlib.__version__}


@dataclass
class FitResult(ResultMixin):
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
    verdict : :class:`~shipid.identify.verdict.Verdict` -- the graded verdict (``grade`` consistent,
        model_error, defect or diverged; ``reasons``); ``shipid fit`` exits on it
        (:func:`~shipid.identify.verdict.exit_status`)
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
    verdict: object = None

    @classmethod
    def from_identifier(cls, ident) -> "FitResult":
        diag = diagnostics_to_json(ident.diagnostics_)
        settings = {
            "estimated": ident.estimated_,
            "meas_std": ident.meas_std_.to_dict(),
            "process_std": ident.process_std_.to_dict(),
            "prior_std": ident.prior_std_.to_dict(),
            "prior_mean": ident.prior_mean_.to_dict(),  # the EKF's start (the prior's centre, pass 1)
            "scale": ident.scale_.to_dict(),
            "n_passes": int(ident.n_passes),
            "param_walk": float(ident.param_walk),
            "substeps": int(ident.substeps),
            "discretisation": ident.method,
        }
        opts, ship = fitted_ship(ident.model, ident.logs_)
        return cls(verdict=ident.verdict_,
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
            **({"verdict": self.verdict.to_dict()} if self.verdict is not None else {}),
        }

    def to_json(self, path, *, force: bool = False) -> Path:
        """Write atomically; an existing file is replaced only with ``force=True``."""
        return atomic_write_text(path, dumps_json(self.to_dict()), force=force)

    @classmethod
    def from_dict(cls, doc: dict, source: str = "result") -> "FitResult":
        """Build from the JSON structure of :meth:`to_dict`, checking every entry's type
        (ValueError naming ``source`` and the key; see :func:`check_result_dict`)."""
        d = check_result_dict(doc, source)
        names = d["cov"]["names"]
        mat = np.array(d["cov"]["matrix"], dtype=float).reshape(len(names), len(names))
        return cls(
            model=d["model"], coef=d["coef"], coef_std=d["coef_std"],
            cov=pd.DataFrame(mat, index=names, columns=names), diagnostics=d["diagnostics"],
            inputs=d["inputs"], method=d["method"], settings=d["settings"],
            loglik=d["loglik"], success=d["success"], message=d["message"],
            versions=d["versions"], created=d["created"], extra=d["extra"],
            model_options=dict(d["model_options"] or d["extra"].get("model_options") or {}),
            ship=dict(as_mapping(doc.get("ship") or {}, f"{source}: ship", '{"lpp": 320}')),
            verdict=_verdict(doc, source),
        )

    def to_model(self):
        """The registered model with these coefficients (and its options, e.g. MMG particulars)."""
        if not isinstance(self.coef, dict):
            raise ValueError("fit result: 'coef' must be a mapping name -> value")
        try:
            return get_model(self.model, self.coef, **self.model_options)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"fit result: cannot build model '{self.model}' with options "
                             f"{short(self.model_options, 80)}: {exc}") from None

    def summary(self) -> pd.DataFrame:
        """Estimated coefficients: value, std, relative std [%], 95 % interval.  ``attrs["verdict"]`` holds the
        fit's verdict grade when it has one."""
        est = list(self.cov.index)
        tab = coefficient_table(pd.Series({k: self.coef[k] for k in est}, dtype=float),
                                pd.Series({k: self.coef_std.get(k, np.nan) for k in est}, dtype=float))
        grade = verdict_grade(self)
        if grade is not None:  # the grade travels with the table (DataFrame.attrs survive copies)
            tab.attrs["verdict"] = grade
            tab.attrs["verdict_reasons"] = list(getattr(self.verdict, "reasons", []) or [])
        return tab

    def to_pandas(self) -> pd.DataFrame:
        """Every parameter of the model (estimated and fixed): ``value``, ``std`` and ``estimated``."""
        est = set(self.cov.index)
        return pd.DataFrame({"value": pd.Series(self.coef, dtype=float),
                             "std": pd.Series({k: self.coef_std.get(k, 0.0) for k in self.coef}, dtype=float),
                             "estimated": pd.Series({k: k in est for k in self.coef}, dtype=bool)})

    def plot(self, ax=None):
        """Each estimated coefficient's 95 % interval relative to its value; returns the axes."""
        return plot_coefficients(self.summary(), ax, title=f"{self.model} ({self.method})")

    def _html_title(self) -> str:
        return f"Fit of '{self.model}' ({self.method})"

    def _key_numbers(self) -> dict:
        k = {"logs": ", ".join(str(i.get("name", "?")) for i in self.inputs[:6]) + (" ..." if len(self.inputs) > 6 else ""),
             "estimated": len(self.cov.index)}
        if self.ship.get("lpp"):
            k["Lpp [m]"] = float(self.ship["lpp"])
        cons = self.diagnostics.get("consistency") if isinstance(self.diagnostics, dict) else None
        if verdict_grade(self) is None and isinstance(cons, dict) and "consistent" in cons:
            k["consistent with the noise model"] = bool(cons["consistent"])
        warn = self.diagnostics.get("warnings") if isinstance(self.diagnostics, dict) else None
        if warn:
            k["warnings"] = len(warn)
        return k


def _verdict(doc: dict, source: str):
    """The result document's verdict (None when it has none: written before verdicts existed)."""
    v = doc.get("verdict")
    if v is None:
        return None
    return Verdict.from_dict(as_mapping(v, f"{source}: verdict", '{"grade": "consistent", "reasons": []}'), source)


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
        try:
            m = res.to_model()
        except ValueError as exc:
            if isinstance(spec, (str, os.PathLike)):
                raise ValueError(f"{spec}: {str(exc).removeprefix('fit result: ')}") from None
            raise
    if model is not None and m.name != model:
        raise ValueError(f"{spec if isinstance(spec, (str, os.PathLike)) else 'result'}: model is '{m.name}', expected '{model}'")
    return m, res


def load_result(path) -> FitResult:
    """Read a fit result JSON written by :meth:`FitResult.to_json` / ``shipid fit``."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such result file; run `shipid fit` first or check the path")
    doc = read_json(p, "JSON fit result", advice="pass the file written by `shipid fit -o`")
    return FitResult.from_dict(doc, source=str(p))


def _number_map(value, where: str, *, allow_null: bool = False) -> dict:
    out = {}
    for k, v in as_mapping(value, where, '{"a1": 0.1}').items():
        out[k] = np.nan if (v is None and allow_null) else as_number(v, f"{where}.{short(k, 30)}", finite=False)
    return out


def _list_of(value, where: str, kind, label: str) -> list:
    if not isinstance(value, list) or not all(isinstance(v, kind) for v in value):
        raise ValueError(f"{where}: expected a list of {label}, got {short(value, 40)}")
    return value


def check_result_dict(doc, source: str = "result") -> dict:
    """Check the types of a fit-result document (the JSON of :meth:`FitResult.to_dict`).

    Hand-written checks (no schema library): each message names ``source``,
    the key and the offending type or value, in one short line.  Unknown
    top-level keys are kept in the file but ignored.  Returns a normalised copy
    (defaults filled in, ``null`` numbers -> NaN).
    """
    if not isinstance(doc, dict):
        raise ValueError(f"{source}: not a shipid fit result (top level is not an object)")
    for key in ("model", "coef"):
        if key not in doc:
            raise ValueError(f"{source}: not a shipid fit result (no '{key}' entry)")
    w = f"{source}: "
    out = {"model": as_string(doc["model"], w + "model"), "coef": _number_map(doc["coef"], w + "coef")}
    out["coef_std"] = _number_map(doc.get("coef_std") or {}, w + "coef_std", allow_null=True)
    cov = as_mapping(doc.get("cov") or {"names": [], "matrix": []}, w + "cov", '{"names": [...], "matrix": [[...]]}')
    names = _list_of(cov.get("names", []), w + "cov.names", str, "coefficient names")
    mat = cov.get("matrix", [])
    if not isinstance(mat, list) or len(mat) != len(names) or not all(
            isinstance(row, list) and len(row) == len(names) for row in mat):
        raise ValueError(f"{w}cov.matrix: expected a {len(names)}x{len(names)} list of lists (one row per name)")
    out["cov"] = {"names": names, "matrix": [[np.nan if v is None else as_number(v, f"{w}cov.matrix[{i}][{j}]", finite=False)
                                              for j, v in enumerate(row)] for i, row in enumerate(mat)]}
    missing = [n for n in names if n not in out["coef"]]
    if missing:
        raise ValueError(f"{w}cov.names {short(missing, 60)} have no value in 'coef'")
    diag = as_mapping(doc.get("diagnostics") or {}, w + "diagnostics", '{"warnings": [...]}')
    if "warnings" in diag:
        _list_of(diag["warnings"], w + "diagnostics.warnings", str, "strings")
    for key in ("poorly_determined", "correlated_pairs", "unidentified_combinations"):
        if key in diag and not isinstance(diag[key], list):
            raise ValueError(f"{w}diagnostics.{key}: expected a list, got {short(diag[key], 40)}")
    for key in ("condition_number", "nis_mean", "nis_expected"):
        if diag.get(key) is not None:
            as_number(diag[key], f"{w}diagnostics.{key}", finite=False)
    if "correlation" in diag:
        c = as_mapping(diag["correlation"], w + "diagnostics.correlation", '{"names": [...], "matrix": [[...]]}')
        cn = _list_of(c.get("names", []), w + "diagnostics.correlation.names", str, "names")
        cm = c.get("matrix", [])
        if not isinstance(cm, list) or len(cm) != len(cn) or not all(
                isinstance(r, list) and len(r) == len(cn) and all(v is None or (isinstance(v, (int, float))
                                                                  and not isinstance(v, bool)) for v in r)
                for r in cm):
            raise ValueError(f"{w}diagnostics.correlation.matrix: expected a {len(cn)}x{len(cn)} list of numbers")
    out["diagnostics"] = diag
    inputs = doc.get("inputs") or []
    if not isinstance(inputs, list) or not all(isinstance(i, dict) for i in inputs):
        raise ValueError(f"{w}inputs: expected a list of objects (name, path, sha256), got {short(inputs, 40)}")
    out["inputs"] = inputs
    for key, default in (("method", "ekf"), ("message", ""), ("created", "")):
        out[key] = as_string(doc.get(key, default) if doc.get(key) is not None else default, w + key)
    for key in ("settings", "versions", "extra", "model_options", "ship"):
        out[key] = as_mapping(doc.get(key) or {}, w + key)
    out["success"] = as_bool(doc.get("success", True), w + "success")
    out["loglik"] = as_number(doc["loglik"], w + "loglik", finite=False) if doc.get("loglik") is not None else None
    return out


def as_result(result) -> FitResult:
    """``result`` as a :class:`FitResult`: the object itself, its dict (:meth:`FitResult.to_dict`) or the path of
    its JSON file."""
    if isinstance(result, FitResult):
        return result
    if isinstance(result, dict):
        return FitResult.from_dict(result)
    if isinstance(result, (str, os.PathLike)):
        return load_result(result)
    raise ValueError(f"result: expected a FitResult, its dict or a result JSON path, got {type(result).__name__}")
