"""Distributed work on Dask: an engine that maps independent members over workers, and campaigns.

:class:`Engine` runs a list of independent tasks (fits of a campaign, replicates of
:func:`shipid.identify.coverage_study`, chunks of posterior draws) either

* on an embedded :class:`distributed.LocalCluster` of ``workers`` processes
  (one thread each, loopback address only, no dashboard) -- the default when
  the optional ``distributed`` extra is installed;
* on an existing cluster (``scheduler="tcp://host:8786"``);
* serially in this process (``workers=1``, or when Dask is not installed).

Every member carries its own seed (derived from the campaign seed with
:class:`numpy.random.SeedSequence`), so the results do not depend on where or
in which order the members run: a distributed run returns exactly the serial
run's numbers.  A member that raises is reported with its error
(:class:`Outcome`, ``ok=False``) and the others complete.  Progress is shown
with tqdm over completed members.

A campaign file (JSON or YAML) lists fits, each with its own logs and settings::

    seed: 1                      # optional, default 0
    defaults: {model: kcs-response, passes: 2}   # optional, any fit key
    fits:
      - name: kcs_all            # required, unique; the member's output folder
        logs: [../data/kcs_tc_p35.csv, ../data/kcs_zz_m10.csv]   # relative to the campaign file
        estimate: [b1, b2, b3, b4, c1, c2, c3]
        draws: 200               # optional: predicted manoeuvres with 95 % intervals
        manoeuvres: ["turning:35", "zigzag:10/10"]

:func:`run_campaign` writes ``OUTDIR/<name>/result.json`` (and
``predictions.json`` when ``draws`` > 0) per member and ``OUTDIR/campaign.json``
with every member's status and error.
"""
from __future__ import annotations

import json
import logging
import os
import re
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

__all__ = ["Engine", "Outcome", "member_seeds", "load_campaign", "run_campaign", "run_fit_member", "FIT_KEYS",
           "dask_available"]


def dask_available() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def member_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent integer seeds from one seed (:class:`numpy.random.SeedSequence` spawning)."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(int(seed)).spawn(int(n))]


@dataclass
class Outcome:
    """One member's outcome: ``ok``, its ``value`` (None on error), ``error`` (one line) and ``trace``."""

    index: int
    ok: bool
    value: Any = None
    error: str | None = None
    trace: str | None = None


def _call(func, item, index):
    """Run one member, turning an exception into a reported error (runs on a worker)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return Outcome(index, True, func(item))
    except Exception as exc:  # noqa: BLE001 - every member error is reported, the others continue
        return Outcome(index, False, None, f"{type(exc).__name__}: {' '.join(str(exc).split())}",
                       traceback.format_exc(limit=6))


class Engine:
    """Map independent members over Dask workers (or serially).

    Parameters
    ----------
    workers : int, optional
        Worker processes of the embedded LocalCluster (default: the number of CPUs); 1 = serial.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:port``); ``workers`` is then ignored.
    progress : bool
        tqdm bar over completed members.
    """

    def __init__(self, workers: int | None = None, *, scheduler: str | None = None, progress: bool = True):
        if workers is not None and int(workers) < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = int(workers) if workers is not None else (os.cpu_count() or 1)
        self.scheduler = scheduler
        self.progress = progress
        self._client = None
        self._cluster = None
        self.mode = "serial"
        self.note = ""
        if scheduler is None and self.workers == 1:
            return
        if not dask_available():
            if scheduler is not None:
                raise ValueError(f"--scheduler {scheduler}: Dask is not installed; pip install 'shipid[distributed]'")
            self.note = "Dask not installed (pip install 'shipid[distributed]'): running serially"
            warnings.warn(self.note, RuntimeWarning, stacklevel=2)
            return
        self.mode = "dask"

    # -- lifecycle
    def _start(self):
        if self._client is not None or self.mode != "dask":
            return
        from distributed import Client, LocalCluster

        if self.scheduler is not None:
            try:
                self._client = Client(self.scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise ValueError(f"--scheduler {self.scheduler}: cannot connect ({exc}); check the address") from None
        else:
            self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                         host="127.0.0.1", dashboard_address=None, silence_logs=logging.ERROR)
            self._client = Client(self._cluster)

    def close(self):
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._client = self._cluster = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def describe(self) -> str:
        if self.mode == "serial":
            return "serial" + (f" ({self.note})" if self.note else "")
        return f"dask scheduler {self.scheduler}" if self.scheduler else f"dask LocalCluster, {self.workers} processes"

    # -- work
    def map(self, func: Callable, items: Sequence, *, desc: str = "members") -> list[Outcome]:
        """``[Outcome(func(item))]`` in the order of ``items``; ``func`` must be importable (top level)."""
        items = list(items)
        bar = None
        if self.progress:
            from tqdm.auto import tqdm

            bar = tqdm(total=len(items), desc=desc, unit="member")
        try:
            if self.mode == "serial":
                out = []
                for i, it in enumerate(items):
                    out.append(_call(func, it, i))
                    if bar is not None:
                        bar.update(1)
                return out
            from distributed import as_completed

            self._start()
            futs = self._client.map(_call, [func] * len(items), items, range(len(items)), pure=False)
            out: list = [None] * len(items)
            for fut in as_completed(futs):
                o = fut.result()
                out[o.index] = o
                if bar is not None:
                    bar.update(1)
            return out
        finally:
            if bar is not None:
                bar.close()


# ----------------------------------------------------------------------------- campaign files
#: Keys of one fit in a campaign file and their types.
FIT_KEYS: dict[str, tuple] = {
    "name": (str,), "logs": (list,), "model": (str,), "params": (str,), "estimate": (list,),
    "fixed": (list, dict), "passes": (int,), "tune_noise": (bool,), "refine": (bool,), "lpp": (int, float),
    "draws": (int,), "manoeuvres": (list,), "inflation": (int, float), "speed": (int, float), "seed": (int,),
}
_TOP_KEYS = {"seed": (int,), "defaults": (dict,), "fits": (list,), "description": (str,)}
_NAME_RE = re.compile(r"^[A-Za-z0-9_.-]+$")


def _type_name(types) -> str:
    return " or ".join({"str": "text", "list": "list", "dict": "mapping", "int": "integer", "float": "number",
                        "bool": "true/false"}[t.__name__] for t in types)


def _check_type(src, where, key, value, types):
    ok = isinstance(value, types) and not (isinstance(value, bool) and bool not in types)
    if not ok:
        raise ValueError(f"{src}: {where}'{key}' must be {_type_name(types)}, got {value!r}")


def load_campaign(path) -> dict:
    """Read and validate a campaign file; returns ``{"seed", "fits": [resolved fit dicts], "path"}``.

    Unknown keys, wrong types, missing names/logs, duplicate names and missing log files are
    one-line ValueErrors naming the file, the fit and the key.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such campaign file")
    text = p.read_text(encoding="utf-8")
    if p.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:
            raise ValueError(f"{p}: YAML campaign files need PyYAML (pip install 'shipid[yaml]'); or write JSON") from None
        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f"{p}: not valid YAML ({' '.join(str(exc).split())})") from None
    else:
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{p}: not valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{p}: the campaign must be a mapping with a 'fits' list")
    for k, v in doc.items():
        if k not in _TOP_KEYS:
            raise ValueError(f"{p}: unknown top-level key '{k}'; allowed: {', '.join(_TOP_KEYS)}")
        _check_type(p, "", k, v, _TOP_KEYS[k])
    if not doc.get("fits"):
        raise ValueError(f"{p}: no fits; give a 'fits' list with at least one entry")
    defaults = doc.get("defaults") or {}
    for k, v in defaults.items():
        if k not in FIT_KEYS or k == "name":
            raise ValueError(f"{p}: defaults: unknown key '{k}'; allowed: {', '.join(x for x in FIT_KEYS if x != 'name')}")
        _check_type(p, "defaults: ", k, v, FIT_KEYS[k])
    fits, names = [], set()
    for i, f in enumerate(doc["fits"]):
        if not isinstance(f, dict):
            raise ValueError(f"{p}: fits[{i}] must be a mapping (name, logs, ...), got {f!r}")
        label = f"fits[{i}]" + (f" ('{f['name']}')" if isinstance(f.get("name"), str) else "")
        for k, v in f.items():
            if k not in FIT_KEYS:
                raise ValueError(f"{p}: {label}: unknown key '{k}'; allowed: {', '.join(FIT_KEYS)}")
            _check_type(p, f"{label}: ", k, v, FIT_KEYS[k])
        spec = {**defaults, **f}
        for req in ("name", "logs"):
            if req not in spec:
                raise ValueError(f"{p}: {label}: '{req}' is required")
        if not _NAME_RE.match(spec["name"]) or spec["name"] in names:
            raise ValueError(f"{p}: {label}: name '{spec['name']}' must be unique and use only letters, digits, '_', '.', '-'")
        names.add(spec["name"])
        logs = []
        for j, lg in enumerate(spec["logs"]):
            if not isinstance(lg, str):
                raise ValueError(f"{p}: {label}: logs[{j}] must be a file path, got {lg!r}")
            lp = (p.parent / lg) if not Path(lg).is_absolute() else Path(lg)
            if not lp.is_file():
                raise ValueError(f"{p}: {label}: logs[{j}] '{lg}' not found (paths are relative to the campaign file)")
            logs.append(str(lp.resolve()))
        if not logs:
            raise ValueError(f"{p}: {label}: 'logs' is empty; list at least one log file")
        spec["logs"] = logs
        if isinstance(spec.get("params"), str) and spec["params"].endswith(".json"):
            spec["params"] = str((p.parent / spec["params"]).resolve())
        for k in ("passes", "draws"):
            if k in spec and spec[k] < (1 if k == "passes" else 0):
                raise ValueError(f"{p}: {label}: '{k}' must be >= {1 if k == 'passes' else 0}, got {spec[k]}")
        if "manoeuvres" in spec:
            from .uncertainty import parse_manoeuvre

            for m in spec["manoeuvres"]:
                try:
                    parse_manoeuvre(m)
                except ValueError as exc:
                    raise ValueError(f"{p}: {label}: {exc}") from None
        fits.append(spec)
    return {"seed": int(doc.get("seed", 0)), "fits": fits, "path": str(p)}


def run_fit_member(spec: dict) -> dict:
    """One campaign member: read its logs, fit (EKF, optional output-error refinement) and, with
    ``draws`` > 0, predict its manoeuvres with intervals.  Returns JSON-able dicts (runs on a worker)."""
    from .identify import EKFIdentifier, model_from
    from .logs import read_log
    from .models import get_model, model_class

    model_name = spec.get("model", "kcs-response")
    cls = model_class(model_name)
    opts = {"lpp": spec["lpp"]} if ("lpp" in spec and "lpp" in cls.__init__.__code__.co_varnames) else {}
    params = spec.get("params")
    if params is None:
        model = cls(**opts)
    elif params.endswith(".json"):
        model = model_from(params, model=model_name)[0]
    else:
        model = get_model(model_name, params, **opts)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        logs = [read_log(f, lpp=spec.get("lpp")) for f in spec["logs"]]
    fixed = spec.get("fixed")
    ident = EKFIdentifier(model, estimate=spec.get("estimate"), fixed=fixed, n_passes=int(spec.get("passes", 2)),
                          tune_noise=bool(spec.get("tune_noise", False))).fit(logs)
    result = ident.result()
    if spec.get("refine"):
        from .identify.batch import OutputErrorRefiner

        result = OutputErrorRefiner(ident.to_model(), estimate=ident.estimated_).fit(logs, start=ident).result()
    result.created = ""  # the member's output must not depend on when or where it ran
    out = {"result": result.to_dict(), "prediction": None}
    if int(spec.get("draws", 0)) > 0:
        from .uncertainty import predict_manoeuvres

        pred = predict_manoeuvres(result, spec.get("manoeuvres", ["turning:35", "zigzag:10/10"]),
                                  draws=int(spec["draws"]), seed=int(spec["seed"]),
                                  inflation=float(spec.get("inflation", 1.0)), speed=spec.get("speed"))
        out["prediction"] = pred.to_dict()
    return out


def run_campaign(campaign, outdir, *, engine: Engine | None = None, force: bool = False) -> dict:
    """Run every fit of a campaign (file path or :func:`load_campaign` dict) and write the outputs.

    Returns the summary written to ``OUTDIR/campaign.json``: per member ``name``, ``ok``, ``error``,
    ``success`` (of the fit), ``seed`` and the files written.
    """
    from ._io import atomic_write_text

    camp = load_campaign(campaign) if not isinstance(campaign, dict) else campaign
    out = Path(outdir)
    if out.exists() and any(out.iterdir()) and not force:
        raise ValueError(f"{out}: output folder exists and is not empty; choose a new one or pass --force")
    out.mkdir(parents=True, exist_ok=True)
    seeds = member_seeds(camp["seed"], len(camp["fits"]))
    specs = [{**f, "seed": int(f.get("seed", s))} for f, s in zip(camp["fits"], seeds)]
    eng = engine or Engine(1, progress=False)
    outcomes = eng.map(run_fit_member, specs, desc="campaign fits")
    members = []
    for spec, o in zip(specs, outcomes):
        rec = {"name": spec["name"], "ok": o.ok, "error": o.error, "seed": spec["seed"], "files": []}
        if o.ok:
            d = out / spec["name"]
            d.mkdir(exist_ok=True)
            atomic_write_text(d / "result.json", json.dumps(o.value["result"], indent=2, allow_nan=True) + "\n", force=True)
            rec["files"].append(f"{spec['name']}/result.json")
            rec["success"] = bool(o.value["result"]["success"])
            if o.value["prediction"] is not None:
                atomic_write_text(d / "predictions.json", json.dumps(o.value["prediction"], indent=2) + "\n", force=True)
                rec["files"].append(f"{spec['name']}/predictions.json")
        members.append(rec)
    summary = {"campaign": camp.get("path"), "seed": camp["seed"], "engine": eng.describe(),
               "n_members": len(members), "n_failed": sum(not m["ok"] for m in members), "members": members}
    atomic_write_text(out / "campaign.json", json.dumps(summary, indent=2) + "\n", force=True)
    return summary
