"""Distributed work on Dask: an engine that maps independent members over workers, and campaigns.

:class:`Engine` runs a list of independent tasks (fits of a campaign, replicates of
the replicate coverage study in ``studies/``, chunks of posterior draws) either

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

A campaign file (JSON or YAML) lists fits, each with its own logs and settings,
and sweeps (the batched studies of ``shipid sweep`` and the glider launch sweep)::

    seed: 1                      # optional, default 0
    defaults: {model: kcs-response, passes: 2}   # optional, any fit key
    fits:
      - name: kcs_all            # required, unique; the member's output folder
        logs: [../data/kcs_tc_p35.csv, ../data/kcs_zz_m10.csv]   # relative to the campaign file
        estimate: [b1, b2, b3, b4, c1, c2, c3]
        draws: 200               # optional: predicted manoeuvres with 95 % intervals
        manoeuvres: ["turning:35", "zigzag:10/10"]
    sweeps:
      - name: td_grid            # turning diameters over rudder x speed (shipid sweep)
        model: kcs-response:synthetic-truth      # or a result JSON (relative to the file)
        rudder: [10, 15, 25]
        speeds: [1.7, 2.0]
      - name: launches           # glider launch sweep (shipid.glider.sweep)
        kind: glider
        speed: [1, 2]
        angle_deg: [30, 45]

:func:`run_campaign` writes ``OUTDIR/<name>/result.json`` (and
``predictions.json`` when ``draws`` > 0) per fit, ``OUTDIR/<name>/sweep.csv`` per
sweep and ``OUTDIR/campaign.json`` with every member's status and error.
"""
from __future__ import annotations

import json
import logging
import math
import os
import pickle
import re
import time
import traceback
import warnings
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from ._io import atomic_write_text
from .glider import PAPER_SWEEP, sweep
from .identify import EKFIdentifier, model_from
from .identify.batch import OutputErrorRefiner
from .logs import read_log
from .manoeuvres import ship_info, turning_sweep
from .models import get_model, model_class
from .results import ResultMixin
from .uncertainty import parse_manoeuvre, predict_manoeuvres

__all__ = ["Engine", "Outcome", "CampaignResult", "member_seeds", "load_campaign", "run_campaign", "run_fit_member", "run_sweep_member",
           "run_member", "member_cost", "warm_fits", "warm_specs", "FIT_KEYS", "SWEEP_KEYS", "dask_available"]


#: Environment of the embedded LocalCluster's worker processes (set before they import numpy/numba).
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}


def dask_available() -> bool:
    try:
        import distributed  # noqa: F401  # optional (the distributed extra)
    except ImportError:
        return False
    return True


def member_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent integer seeds from one seed (:class:`numpy.random.SeedSequence` spawning)."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(int(seed)).spawn(int(n))]


@dataclass
class Outcome:
    """One member's outcome: ``ok``, its ``value`` (None on error), ``error`` (one line) and ``trace``;
    ``seconds`` and ``cpu_seconds`` it took and the ``worker`` (process id) that ran it."""

    index: int
    ok: bool
    value: Any = None
    error: str | None = None
    trace: str | None = None
    seconds: float = float("nan")
    cpu_seconds: float = float("nan")
    worker: int = 0


def _call(func, item, index):
    """Run one member, turning an exception into a reported error (runs on a worker).  The outcome records
    the member's wall and CPU seconds (CPU of this thread: a Dask worker's own threads are not counted)."""
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out = Outcome(index, True, func(item))
    except Exception as exc:  # noqa: BLE001 - every member error is reported, the others continue
        out = Outcome(index, False, None, f"{type(exc).__name__}: {' '.join(str(exc).split())}",
                      traceback.format_exc(limit=6))
    out.seconds, out.cpu_seconds, out.worker = time.perf_counter() - t0, time.thread_time() - c0, os.getpid()
    return out


def _warm_call(warm):
    """Run ``warm()`` in this worker process; returns its wall seconds (errors are the members' to report)."""
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            warm()
    except Exception:  # noqa: BLE001 - a warm-up is an optimisation: a member that fails reports its own error
        pass
    return time.perf_counter() - t0


def _process_cpu():
    return time.process_time()


#: Dask settings of the embedded LocalCluster: its workers have no dashboard, so the statistical profiler
#: (a stack sample every 10 ms), the 20 ms event-loop tick, the 100 ms memory monitor and the 500 ms system
#: monitor only cost CPU.  Measured on 2 busy workers (benchmarks/bench_uncertainty.py, docs/uncertainty.md):
#: the workers' own threads used 9-13 % of the members' CPU and the main process (scheduler, nannies) 3-7 %;
#: with these 1.0-1.4 % and 1.1-1.8 %.  An existing cluster (``scheduler=``) keeps its own configuration.
QUIET_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "1s",
                "distributed.worker.memory.monitor-interval": "1s",
                "distributed.admin.system-monitor.interval": "2s", "distributed.admin.system-monitor.disk": False}


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
    quiet : bool
        Start the embedded LocalCluster with :data:`QUIET_CONFIG` (default); False keeps Dask's
        configuration (its profiler and monitors, e.g. for a dashboard).
    """

    def __init__(self, workers: int | None = None, *, scheduler: str | None = None, progress: bool = True,
                 quiet: bool = True):
        if workers is not None and int(workers) < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = int(workers) if workers is not None else (os.cpu_count() or 1)
        self.scheduler = scheduler
        self.progress = progress
        self.quiet = bool(quiet)
        self._client = None
        self._cluster = None
        self.mode = "serial"
        self.note = ""
        #: timings of the engine: ``start`` (cluster start and connection, s), ``warm`` ({worker: s} of the
        #: last warm-up), and of the last :meth:`map`: ``wall``, ``main_cpu`` (this process's CPU seconds: client,
        #: and for the embedded cluster its scheduler and nannies), ``worker_cpu`` ({worker: process CPU s}),
        #: ``worker_end`` ({worker: s to its last member}), ``member_seconds`` and ``member_cpu`` (per member)
        self.stats: dict = {}
        self._warmed: set = set()
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
        from distributed import Client, LocalCluster  # optional (the distributed extra)

        if self.scheduler is not None:
            try:
                self._client = Client(self.scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise ValueError(f"--scheduler {self.scheduler}: cannot connect ({exc}); check the address") from None
        else:
            # one thread per worker process and one BLAS/OpenMP/numba thread inside it: W workers use W
            # cores, never W x (threads of each library) (Dask's pre-spawn environment sets the BLAS ones
            # already; numba's is added here)
            import dask  # optional (the distributed extra)

            t0 = time.perf_counter()
            with dask.config.set(QUIET_CONFIG if self.quiet else {}):  # the nannies hand it to their workers
                self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                             host="127.0.0.1", dashboard_address=None, silence_logs=logging.ERROR,
                                             env=dict(WORKER_ENV))
                self._client = Client(self._cluster)
            self.stats["start"] = time.perf_counter() - t0

    def warm(self, warm: Callable | None) -> dict:
        """Run ``warm()`` (importable, no arguments) once in every worker process now, so that imports,
        compiled-kernel loading and first-call costs are paid at start-up rather than inside the first
        members (a serial engine does nothing: its members pay them once, in order).  Returns
        ``{worker: seconds}``; a warm-up already run on this engine is not repeated."""
        if warm is None or self.mode != "dask":
            return {}
        key = pickle.dumps(warm)
        if key in self._warmed:
            return {}
        self._start()
        self.stats["warm"] = {str(k): float(v) for k, v in self._client.run(_warm_call, warm).items()}
        self._warmed.add(key)
        return self.stats["warm"]

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
    def map(self, func: Callable, items: Sequence, *, desc: str = "members", warm: Callable | None = None,
            cost: Sequence[float] | None = None) -> list[Outcome]:
        """``[Outcome(func(item))]`` in the order of ``items``; ``func`` must be importable (top level).

        ``warm``: see :meth:`warm` (run on every worker before the members).  ``cost``: an estimate of
        each member's run time (any unit); on Dask the members start in order of decreasing cost (longest
        first, so that no long member starts last while the other workers idle).  Neither changes any result.
        """
        items = list(items)
        bar = None
        if self.mode == "dask":
            self.warm(warm)
        if self.progress:
            bar = tqdm(total=len(items), desc=desc, unit="member")
        t0, c0 = time.perf_counter(), time.process_time()
        out: list = []
        try:
            if self.mode == "serial":
                for i, it in enumerate(items):
                    out.append(_call(func, it, i))
                    if bar is not None:
                        bar.update(1)
                return out
            from distributed import as_completed  # optional (the distributed extra)

            self._start()
            cpu0 = self._client.run(_process_cpu)
            rank = np.argsort(-np.asarray(cost, float), kind="stable") if cost is not None else range(len(items))
            rank = [int(i) for i in rank]  # client.map gives its tasks priority in the order submitted
            futs = self._client.map(_call, [func] * len(items), [items[i] for i in rank], rank, pure=False)
            out = [None] * len(items)
            ends = {}
            for fut in as_completed(futs):
                o = fut.result()
                out[o.index] = o
                ends[o.worker] = time.perf_counter() - t0
                if bar is not None:
                    bar.update(1)
            cpu1 = self._client.run(_process_cpu)
            self.stats["worker_cpu"] = {str(k): float(cpu1[k] - cpu0.get(k, 0.0)) for k in cpu1}
            self.stats["worker_end"] = ends  # {worker process id: seconds from the start of the map to its last member}
            return out
        finally:
            self.stats["wall"], self.stats["main_cpu"] = time.perf_counter() - t0, time.process_time() - c0
            done = [o for o in out if o is not None]
            self.stats["member_seconds"] = [o.seconds for o in done]
            self.stats["member_cpu"] = [o.cpu_seconds for o in done]
            if bar is not None:
                bar.close()


# ----------------------------------------------------------------------------- campaign files
#: Keys of one fit in a campaign file and their types.
FIT_KEYS: dict[str, tuple] = {
    "name": (str,), "logs": (list,), "model": (str,), "params": (str,), "estimate": (list,),
    "fixed": (list, dict), "passes": (int,), "tune_noise": (bool,), "refine": (bool,), "lpp": (int, float),
    "draws": (int,), "manoeuvres": (list,), "inflation": (int, float), "speed": (int, float), "seed": (int,),
}
#: Keys of one sweep member and their types: ``kind`` "turning" (:func:`shipid.manoeuvres.turning_sweep`, the
#: ``shipid sweep`` command) or "glider" (:func:`shipid.glider.sweep`, the launch factorial).
SWEEP_KEYS: dict[str, dict[str, tuple]] = {
    "turning": {"name": (str,), "kind": (str,), "model": (str,), "rudder": (list,), "speeds": (list,), "side": (str,),
                "lpp": (int, float), "rudder_rate": (int, float), "method": (str,)},
    "glider": {"name": (str,), "kind": (str,), "speed": (list,), "angle_deg": (list,), "fin_deg": (list,),
               "cg_m": (list,), "t_max": (int, float), "dt": (int, float)},
}
_TOP_KEYS = {"seed": (int,), "defaults": (dict,), "fits": (list,), "sweeps": (list,), "description": (str,)}
_NAME_RE = re.compile(r"^[A-Za-z0-9_.-]+$")


def _type_name(types) -> str:
    return " or ".join({"str": "text", "list": "list", "dict": "mapping", "int": "integer", "float": "number",
                        "bool": "true/false"}[t.__name__] for t in types)


def _check_type(src, where, key, value, types):
    ok = isinstance(value, types) and not (isinstance(value, bool) and bool not in types)
    if not ok:
        raise ValueError(f"{src}: {where}'{key}' must be {_type_name(types)}, got {value!r}")


def load_campaign(path) -> dict:
    """Read and validate a campaign file; returns ``{"seed", "fits": [...], "sweeps": [...], "path"}``
    (resolved member dicts).

    Unknown keys, wrong types, missing names/logs, duplicate names (over fits and sweeps), missing
    log or result files and bad sweep levels are one-line ValueErrors naming the file, the member
    and the key.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such campaign file")
    text = p.read_text(encoding="utf-8")
    if p.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml  # optional (the yaml extra): only for YAML campaign files
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
        raise ValueError(f"{p}: the campaign must be a mapping with a 'fits' and/or a 'sweeps' list")
    for k, v in doc.items():
        if k not in _TOP_KEYS:
            raise ValueError(f"{p}: unknown top-level key '{k}'; allowed: {', '.join(_TOP_KEYS)}")
        _check_type(p, "", k, v, _TOP_KEYS[k])
    if not doc.get("fits") and not doc.get("sweeps"):
        raise ValueError(f"{p}: no members; give a 'fits' or a 'sweeps' list with at least one entry")
    defaults = doc.get("defaults") or {}
    for k, v in defaults.items():
        if k not in FIT_KEYS or k == "name":
            raise ValueError(f"{p}: defaults: unknown key '{k}'; allowed: {', '.join(x for x in FIT_KEYS if x != 'name')}")
        _check_type(p, "defaults: ", k, v, FIT_KEYS[k])
    fits, names = [], set()
    for i, f in enumerate(doc.get("fits") or []):
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
            for m in spec["manoeuvres"]:
                try:
                    parse_manoeuvre(m)
                except ValueError as exc:
                    raise ValueError(f"{p}: {label}: {exc}") from None
        fits.append(spec)
    sweeps = [_sweep_spec(p, i, w, names) for i, w in enumerate(doc.get("sweeps") or [])]
    return {"seed": int(doc.get("seed", 0)), "fits": fits, "sweeps": sweeps, "path": str(p)}


def _sweep_spec(p: Path, i: int, w, names: set) -> dict:
    """One validated sweep member of campaign file ``p`` (``names``: member names so far, updated)."""
    if not isinstance(w, dict):
        raise ValueError(f"{p}: sweeps[{i}] must be a mapping (name, kind, levels ...), got {w!r}")
    label = f"sweeps[{i}]" + (f" ('{w['name']}')" if isinstance(w.get("name"), str) else "")
    kind = w.get("kind", "turning")
    if kind not in SWEEP_KEYS:
        raise ValueError(f"{p}: {label}: 'kind' must be one of {', '.join(SWEEP_KEYS)}, got {kind!r}")
    keys = SWEEP_KEYS[kind]
    for k, v in w.items():
        if k not in keys:
            raise ValueError(f"{p}: {label}: unknown key '{k}' for a {kind} sweep; allowed: {', '.join(keys)}")
        _check_type(p, f"{label}: ", k, v, keys[k])
    if "name" not in w:
        raise ValueError(f"{p}: {label}: 'name' is required")
    if not _NAME_RE.match(w["name"]) or w["name"] in names:
        raise ValueError(f"{p}: {label}: name '{w['name']}' must be unique and use only letters, digits, '_', '.', '-'")
    names.add(w["name"])
    spec = {**w, "kind": kind}
    for k, v in w.items():
        if keys[k] == (list,):
            if not v or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in v):
                raise ValueError(f"{p}: {label}: '{k}' must be a non-empty list of finite numbers, got {v!r}")
            if k in ("rudder", "speeds") and min(v) <= 0:
                raise ValueError(f"{p}: {label}: '{k}' values must be positive (use 'side' for port), got {v!r}")
    if kind == "turning":
        if "model" not in w:
            raise ValueError(f"{p}: {label}: 'model' is required (a result JSON or name[:parameter-set])")
        if w["model"].lower().endswith(".json"):
            mp = (p.parent / w["model"]) if not Path(w["model"]).is_absolute() else Path(w["model"])
            if not mp.is_file():
                raise ValueError(f"{p}: {label}: model '{w['model']}' not found (paths are relative to the campaign file)")
            spec["model"] = str(mp.resolve())
        if spec.get("side", "starboard") not in ("starboard", "port", "both"):
            raise ValueError(f"{p}: {label}: 'side' must be starboard, port or both, got {spec['side']!r}")
    return spec


def run_fit_member(spec: dict) -> dict:
    """One campaign member: read its logs, fit (EKF, optional output-error refinement) and, with
    ``draws`` > 0, predict its manoeuvres with intervals.  Returns JSON-able dicts (runs on a worker)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        logs = [read_log(f, lpp=spec.get("lpp")) for f in spec["logs"]]
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
    fixed = spec.get("fixed")
    ident = EKFIdentifier(model, estimate=spec.get("estimate"), fixed=fixed, n_passes=int(spec.get("passes", 2)),
                          tune_noise=bool(spec.get("tune_noise", False))).fit(logs)
    result = ident.result()
    if spec.get("refine"):
        result = OutputErrorRefiner(ident.to_model(), estimate=ident.estimated_).fit(logs, start=ident).result()
    result.created = ""  # the member's output must not depend on when or where it ran
    out = {"result": result.to_dict(), "prediction": None}
    if int(spec.get("draws", 0)) > 0:
        pred = predict_manoeuvres(result, spec.get("manoeuvres", ["turning:35", "zigzag:10/10"]),
                                  draws=int(spec["draws"]), seed=int(spec["seed"]),
                                  inflation=float(spec.get("inflation", 1.0)), speed=spec.get("speed"))
        out["prediction"] = pred.to_dict()
    return out


def run_sweep_member(spec: dict):
    """One sweep member (runs on a worker): the whole sweep as one batch, as the serial commands run it.

    ``kind`` "turning": :func:`shipid.manoeuvres.turning_sweep` of ``model`` (result JSON or
    ``name[:set]``, Froude-scaled to ``lpp`` when given) over ``rudder`` [deg] x ``speeds`` [m/s]
    (default: the design speed); "glider": :func:`shipid.glider.sweep` over the given factor levels
    (the paper's where omitted).  Returns the sweep's table (DataFrame).
    """
    if spec["kind"] == "glider":
        levels = {k: spec.get(k, PAPER_SWEEP[k]) for k in PAPER_SWEEP}
        res = sweep(**levels, dt=spec.get("dt"), t_max=float(spec.get("t_max", 60.0)), keep_trajectories=False)
        return res.launches.reset_index(drop=True)
    model = model_from(spec["model"])[0]
    lpp = spec.get("lpp")
    if lpp is not None and getattr(model, "lpp", None) not in (None, lpp) and hasattr(model, "scaled"):
        model = model.scaled(float(lpp))
    speeds = spec.get("speeds")
    if speeds is None:
        u0 = ship_info(model).get("design_speed")
        if u0 is None:
            raise ValueError(f"sweep '{spec['name']}': model '{model.name}' has no design speed; give 'speeds'")
        speeds = [u0]
    rate = math.radians(spec["rudder_rate"]) if spec.get("rudder_rate") is not None else None
    return turning_sweep(model, spec.get("rudder", [10.0, 15.0, 25.0]), speeds, side=spec.get("side", "starboard"),
                         rudder_rate=rate, lpp=lpp, method=spec.get("method", "rk4"))


def run_member(spec: dict):
    """A campaign member of either type (the function the engine maps)."""
    return run_sweep_member(spec) if spec.get("_member") == "sweep" else run_fit_member(spec)


#: Run-time estimate of a member [s], for longest-first scheduling only (results never depend on it):
#: per log byte and EKF pass (x 2 with ``refine``), and per parameter draw of each manoeuvre kind;
#: measured on the bundled KCS logs (EKF + refinement ~0.15 s for two 1100-sample logs, 200 draws of a
#: 35 deg turn ~0.1 s, of a 10/10 zigzag ~3.3 s) and ~0.05 s per case of a sweep.
_COST_PER_BYTE_PASS, _COST_PER_DRAW, _COST_PER_CASE = 1e-7, {"turning": 5e-4, "zigzag": 1.6e-2}, 0.05


def member_cost(spec: dict) -> float:
    """Estimated run time of a campaign member (:data:`_COST_PER_BYTE_PASS` ...), for scheduling."""
    if spec.get("_member") == "sweep":
        if spec["kind"] == "glider":
            return _COST_PER_CASE * float(np.prod([len(spec.get(k, PAPER_SWEEP[k])) for k in PAPER_SWEEP]))
        n = len(spec.get("rudder", [10.0, 15.0, 25.0])) * len(spec.get("speeds", [0]))
        return _COST_PER_CASE * n * (2 if spec.get("side") == "both" else 1)
    size = sum(os.path.getsize(f) for f in spec["logs"] if os.path.isfile(f))
    cost = _COST_PER_BYTE_PASS * size * int(spec.get("passes", 2)) * (2 if spec.get("refine") else 1)
    if int(spec.get("draws", 0)) > 0:
        kinds = [str(m).split(":")[0] for m in spec.get("manoeuvres", ["turning:35", "zigzag:10/10"])]
        cost += int(spec["draws"]) * sum(_COST_PER_DRAW.get(k, _COST_PER_DRAW["zigzag"]) for k in kinds)
    return cost


#: Draws of a warm-up fit.
_WARM_DRAWS = 4
#: Settings that select the code (and compiled kernels) a fit member runs.
_WARM_KEYS = ("model", "params", "estimate", "fixed", "refine", "manoeuvres", "lpp", "tune_noise", "inflation", "speed")


def warm_fits(specs: Sequence[dict]) -> None:
    """Warm-up of a worker for the fit members ``specs``: one fit per distinct set of settings
    (:data:`_WARM_KEYS`; at most 3): the first such member with :data:`_WARM_DRAWS` draws.  That imports what
    the members import and loads their compiled kernels, so that the first member runs as fast as the others
    (the engine runs it on every worker at start-up)."""
    for spec in warm_specs(specs):
        try:
            run_fit_member({**spec, "draws": min(int(spec.get("draws", 0)), _WARM_DRAWS), "seed": 0})
        except Exception:  # noqa: BLE001 - the member itself will report its error
            pass


def warm_specs(specs: Sequence[dict]) -> tuple:
    """The fit members :func:`warm_fits` runs for ``specs``: the first of each distinct set of settings
    (:data:`_WARM_KEYS`, at most 3), reduced to those settings, its logs and passes."""
    out = {}
    for spec in specs:
        if spec.get("_member") == "sweep":
            continue
        key = json.dumps({k: spec.get(k) for k in _WARM_KEYS}, sort_keys=True, default=str)
        if key not in out and len(out) < 3:
            out[key] = {**{k: spec[k] for k in _WARM_KEYS if k in spec}, "logs": spec["logs"],
                        "passes": int(spec.get("passes", 2)), "draws": int(spec.get("draws", 0))}
    return tuple(out.values())


def run_campaign(campaign, outdir, *, engine: Engine | None = None, force: bool = False) -> dict:
    """Run every fit and sweep of a campaign (file path or :func:`load_campaign` dict) and write the outputs.

    Fits and sweeps are members of one map over the engine (fits first, in file order).  Returns the
    summary written to ``OUTDIR/campaign.json``: per member ``name``, ``type`` ("fit" or "sweep"),
    ``ok``, ``error``, ``success`` (of the fit; of every row of a sweep), ``seed`` and the files written.
    """
    camp = load_campaign(campaign) if not isinstance(campaign, dict) else campaign
    out = Path(outdir)
    if out.exists() and any(out.iterdir()) and not force:
        raise ValueError(f"{out}: output folder exists and is not empty; choose a new one or pass --force")
    out.mkdir(parents=True, exist_ok=True)
    fits, sweeps = camp["fits"], camp.get("sweeps", [])
    seeds = member_seeds(camp["seed"], len(fits) + len(sweeps))  # fits keep the seeds of a fits-only campaign
    specs = [{**f, "seed": int(f.get("seed", s))} for f, s in zip(fits, seeds)]
    specs += [{**w, "seed": s, "_member": "sweep"} for w, s in zip(sweeps, seeds[len(fits):])]
    eng = engine or Engine(1, progress=False)
    outcomes = eng.map(run_member, specs, desc="campaign members", warm=partial(warm_fits, warm_specs(specs)),
                       cost=[member_cost(sp) for sp in specs])
    members = []
    for spec, o in zip(specs, outcomes):
        kind = spec.get("_member", "fit")
        rec = {"name": spec["name"], "type": kind, "ok": o.ok, "error": o.error, "seed": spec["seed"],
               "seconds": round(o.seconds, 3), "files": []}
        if o.ok and kind == "sweep":
            d = out / spec["name"]
            d.mkdir(exist_ok=True)
            atomic_write_text(d / "sweep.csv", o.value.to_csv(index=False), force=True)
            rec["files"].append(f"{spec['name']}/sweep.csv")
            ok_col = "success" if "success" in o.value else "surfaced"  # turning rows / glider launches
            rec["success"] = bool(o.value[ok_col].all())
        elif o.ok:
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
    return CampaignResult(summary)


class CampaignResult(dict, ResultMixin):
    """What :func:`run_campaign` wrote to ``campaign.json``: the same dict (``members``, ``n_failed``, ...),
    with the result contract on top (one row per member in :meth:`summary`)."""

    @property
    def success(self) -> bool:
        """Every member ran, and every fit and sweep reports success."""
        return all(m.get("ok") and m.get("success", True) for m in self.get("members", []))

    @property
    def message(self) -> str:
        n, bad = int(self.get("n_members", 0)), int(self.get("n_failed", 0))
        unsuccessful = sum(1 for m in self.get("members", []) if m.get("ok") and not m.get("success", True))
        return (f"{n - bad} of {n} member(s) completed ({self.get('engine', '')})"
                + (f"; {unsuccessful} completed without success" if unsuccessful else ""))

    def summary(self) -> pd.DataFrame:
        """One row per member: name, type, ok, success, seconds, error, files written."""
        rows = [{"name": m.get("name"), "type": m.get("type"), "ok": m.get("ok"), "success": m.get("success"),
                 "seconds": m.get("seconds"), "error": m.get("error"), "files": ", ".join(m.get("files", []))}
                for m in self.get("members", [])]
        return pd.DataFrame(rows, columns=["name", "type", "ok", "success", "seconds", "error", "files"])

    def to_pandas(self) -> pd.DataFrame:
        """Every member's record as written (seed included), one row each."""
        return pd.DataFrame(self.get("members", []))

    def _html_title(self) -> str:
        return f"Campaign ({self.get('n_members', 0)} members)"

    def plot(self, ax=None):
        """Seconds each member took, coloured by outcome (green success, orange no success, red failed); returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        df = self.summary()
        if ax is None:
            _, ax = plt.subplots(figsize=(6, 0.3 * len(df) + 1.2))
        colour = ["C3" if not ok else ("C2" if s in (True, None) else "C1") for ok, s in zip(df["ok"], df["success"])]
        ax.barh(df["name"].astype(str), df["seconds"].astype(float), color=colour)
        ax.invert_yaxis()
        ax.set_xlabel("seconds")
        return ax
