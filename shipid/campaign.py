# Why one file: the engine, the campaign file, its members and the resumable run share one journal and one schema.
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

Every file name a campaign file supplies is treated as hostile (as git and rsync never write outside the
destination): a member name is a plain file name (letters, digits, ``_ . -``, not starting with ``.`` or
``-``; not ``campaign.json``, ``campaign.journal`` or a device name), checked before anything runs, and a
member folder that is a link or resolves outside OUTDIR is refused.  A member's files are written as soon as
it finishes and a line is appended to ``OUTDIR/campaign.journal``; ``--resume`` keeps the members it lists
(files unchanged) and runs the others, so a kill at any point loses no finished member.  A member is ``ok``,
``flagged`` (its fit would make ``shipid fit`` exit 3 or 4: not consistent with its noise model, or diverged;
a sweep with failed runs) or ``failed`` (it raised, or its worker died :data:`MEMBER_RETRIES` + 1 times); the
command exits 0, 3 (some flagged, none failed) or 1 (some failed).
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import pickle
import re
import threading
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

from ._io import atomic_write_text, check_output_target, dumps_json, read_structured, sha256_file, short
from .glider import PAPER_SWEEP, sweep
from .identify import EKFIdentifier, model_from
from .identify.batch import OutputErrorRefiner
from .logs import read_log
from .manoeuvres import ship_info, turning_sweep
from .models import get_model, model_class
from .results import ResultMixin
from .uncertainty import parse_manoeuvre, predict_manoeuvres
from .uncertainty.draws import check_draws_memory

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
        cpus = os.cpu_count() or 1
        if workers is not None and not 1 <= int(workers) <= cpus:
            shown = f"{int(workers)}" if abs(int(workers)) < 10**9 else f"{float(workers):.3g}"
            raise ValueError(f"--workers {shown}: give 1 to {cpus} (this machine has {cpus} CPUs; each worker is a "
                             "process that uses one); or --scheduler ADDRESS for a larger cluster")
        self.workers = int(workers) if workers is not None else cpus
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
            self._client = _connect(self.scheduler)
        else:
            # one thread per worker process and one BLAS/OpenMP/numba thread inside it: W workers use W
            # cores, never W x (threads of each library) (Dask's pre-spawn environment sets the BLAS ones
            # already; numba's is added here)
            import dask  # optional (the distributed extra)

            t0 = time.perf_counter()
            with dask.config.set({**(QUIET_CONFIG if self.quiet else {}),
                                  "distributed.scheduler.allowed-failures": MEMBER_RETRIES}):
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
            cost: Sequence[float] | None = None, on_result: Callable | None = None) -> list[Outcome]:
        """``[Outcome(func(item))]`` in the order of ``items``; ``func`` must be importable (top level).

        ``on_result(outcome)`` is called in this process as each member finishes (a campaign writes the
        member's files then, so that a kill loses no finished member).  A member whose worker process dies
        is started again on another worker up to :data:`MEMBER_RETRIES` times (an embedded cluster; an
        existing cluster keeps its own ``allowed-failures``), then reported as that member's failure while
        the others complete.

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
                    if on_result is not None:
                        on_result(out[-1])
                    if bar is not None:
                        bar.update(1)
                return out
            from distributed import as_completed  # optional (the distributed extra)

            self._start()
            cpu0 = self._client.run(_process_cpu)
            rank = np.argsort(-np.asarray(cost, float), kind="stable") if cost is not None else range(len(items))
            rank = [int(i) for i in rank]  # client.map gives its tasks priority in the order submitted
            futs = self._client.map(_call, [func] * len(items), [items[i] for i in rank], rank, pure=False)
            index = {f.key: i for f, i in zip(futs, rank)}
            out = [None] * len(items)
            ends = {}
            for fut in as_completed(futs):
                try:
                    o = fut.result()
                except Exception as exc:  # noqa: BLE001 - KilledWorker and other losses: that member's failure
                    o = Outcome(index[fut.key], False, None, _lost_member_message(exc), None)
                out[o.index] = o
                if on_result is not None:
                    on_result(o)
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


#: Times a member is started again after its worker process died (Dask's ``allowed-failures``), then it is
#: reported as failed: a member that kills its worker twice (memory, a crash in compiled code) will again.
MEMBER_RETRIES = 2
#: Seconds to wait for an existing scheduler to answer (``--scheduler``).
SCHEDULER_TIMEOUT = 20.0


def _lost_member_message(exc) -> str:
    name = type(exc).__name__
    if name == "KilledWorker":
        return (f"its worker process died {MEMBER_RETRIES + 1} times running it (out of memory, or a crash); "
                "run it alone with --workers 1 to see why")
    return f"{name}: {' '.join(str(exc).split())[:200]}"


def _connect(address: str):
    """A Client of the scheduler at ``address``, or a one-line error within :data:`SCHEDULER_TIMEOUT` s
    (also for a port that accepts the connection but never answers: the attempt runs in a daemon thread)."""
    from distributed import Client  # optional (the distributed extra)

    box: dict = {}

    def attempt():
        try:
            box["client"] = Client(address, timeout=f"{SCHEDULER_TIMEOUT:g}s")
        except BaseException as exc:  # noqa: BLE001 - said below
            box["error"] = exc

    th = threading.Thread(target=attempt, daemon=True)
    th.start()
    th.join(SCHEDULER_TIMEOUT + 5.0)
    if "client" in box:
        return box["client"]
    why = (f"no answer within {SCHEDULER_TIMEOUT:g} s" if th.is_alive()
           else " ".join(str(box.get("error") or "").split())[:120] or type(box.get("error")).__name__)
    raise ValueError(f"--scheduler {address}: cannot connect ({why}); check the address and that the scheduler "
                     "is running")


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
#: A member name is a plain file name: letters, digits, '_', '.', '-', not starting with '.' or '-' (so never
#: '.', '..' or a hidden file), at most 100 characters; matched to the end of the text (no trailing newline).
_NAME_RE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,99}")
#: Files of the campaign itself in OUTDIR (no member may be named so, in any letter case).
SUMMARY, JOURNAL = "campaign.json", "campaign.journal"
#: Names Windows reserves for devices (a member folder so named cannot be created or read there).
_RESERVED = {"con", "prn", "aux", "nul", *(f"com{i}" for i in range(1, 10)), *(f"lpt{i}" for i in range(1, 10))}


def check_member_name(name, where: str) -> str:
    """``name`` if it is a plain file name for a member's folder (see :data:`_NAME_RE`), else a one-line ValueError."""
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        raise ValueError(f"{where}: name {short(name, 40)} must be a plain file name: letters, digits, '_', '.', '-', "
                         "not starting with '.' or '-', at most 100 characters")
    if name.lower() in (SUMMARY, JOURNAL) or name.split(".")[0].lower() in _RESERVED:
        raise ValueError(f"{where}: name '{name}' is reserved ({SUMMARY}, {JOURNAL} and device names such as 'nul'); "
                         "choose another")
    return name


def _type_name(types) -> str:
    return " or ".join({"str": "text", "list": "list", "dict": "mapping", "int": "integer", "float": "number",
                        "bool": "true/false"}[t.__name__] for t in types)


def _check_type(src, where, key, value, types):
    ok = isinstance(value, types) and not (isinstance(value, bool) and bool not in types)
    if not ok:
        raise ValueError(f"{src}: {where}'{key}' must be {_type_name(types)}, got {short(value, 40)}")


def load_campaign(path) -> dict:
    """Read and validate a campaign file; returns ``{"seed", "fits": [...], "sweeps": [...], "path"}``
    (resolved member dicts).

    Unknown keys, wrong types, missing names/logs, duplicate names (over fits and sweeps), missing
    log or result files and bad sweep levels are one-line ValueErrors naming the file, the member
    and the key.
    """
    p = Path(path)
    doc = read_structured(p, "campaign", advice="see the campaign format in the shipid.campaign module docstring")
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
        label = f"fits[{i}]" + (f" ({short(f['name'], 40)})" if isinstance(f.get("name"), str) else "")
        for k, v in f.items():
            if k not in FIT_KEYS:
                raise ValueError(f"{p}: {label}: unknown key '{k}'; allowed: {', '.join(FIT_KEYS)}")
            _check_type(p, f"{label}: ", k, v, FIT_KEYS[k])
        spec = {**defaults, **f}
        for req in ("name", "logs"):
            if req not in spec:
                raise ValueError(f"{p}: {label}: '{req}' is required")
        check_member_name(spec["name"], f"{p}: {label}")
        if spec["name"].lower() in names:
            raise ValueError(f"{p}: {label}: name '{spec['name']}' is used twice (names are compared ignoring case); "
                             "give every member its own name")
        names.add(spec["name"].lower())
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
        if spec.get("draws"):
            try:
                check_draws_memory(int(spec["draws"]))
            except ValueError as exc:
                raise ValueError(f"{p}: {label}: {exc}") from None
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
    label = f"sweeps[{i}]" + (f" ({short(w['name'], 40)})" if isinstance(w.get("name"), str) else "")
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
    check_member_name(w["name"], f"{p}: {label}")
    if w["name"].lower() in names:
        raise ValueError(f"{p}: {label}: name '{w['name']}' is used twice (names are compared ignoring case); "
                         "give every member its own name")
    names.add(w["name"].lower())
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
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        logs = [read_log(f, lpp=spec.get("lpp")) for f in spec["logs"]]
    kept = []
    for w in caught:  # the readers' warnings go into the member's result (one line each, no repeats)
        line = " ".join(str(w.message).split())
        if issubclass(w.category, UserWarning) and line not in kept:
            kept.append(line)
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
    if kept:
        result.extra = {**(result.extra or {}), "reader_warnings": kept}
    out = {"result": result.to_dict(), "prediction": None, "warnings": kept}
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


def member_status(value: dict | None, ok: bool) -> tuple[str, list[str]]:
    """``("ok" | "flagged" | "failed", reasons)`` of one finished member: the one rule the campaign's summary and
    exit status use.  A fit member is ``flagged`` when ``shipid fit`` would exit 3 or 4 on its result
    (:func:`fit_exit_status`), a sweep member when some of its runs failed; ``failed`` when it raised."""
    if not ok:
        return "failed", []
    if value is None or "result" not in value:
        return "ok", []
    code, reasons = fit_exit_status(value["result"])
    return ("flagged" if code in (3, 4) else "ok"), reasons


def fit_exit_status(result: dict) -> tuple[int, list[str]]:
    """``shipid fit``'s exit status for a result dict (0 consistent, 1 not converged, 3 not consistent with its
    noise model or a data defect, 4 filter diverged) and the reasons.  A result that carries a graded verdict
    is judged by the verdict's own mapping (``shipid.identify.verdict.exit_status``), so that a campaign
    grades a fit exactly as ``shipid fit`` does; otherwise from the result's consistency diagnostics."""
    if isinstance(result.get("verdict"), dict):
        try:
            from .identify.verdict import exit_status, verdict_of  # optional: the graded verdict, where it exists
        except ImportError:
            pass
        else:
            v = verdict_of(result)
            code = int(exit_status(v))
            return code, ([str(r) for r in v.reasons] if code else [])
    diag = result.get("diagnostics") or {}
    if result.get("method") == "ekf" and not result.get("success", True):  # the filter did not finish
        return 4, [f"the filter diverged: {result.get('message', '')}"]
    verdict = diag.get("consistency") or {}
    if isinstance(verdict, dict) and not verdict.get("consistent", True):
        return 3, [str(r) for r in verdict.get("reasons", [])] or ["not consistent with its noise model"]
    if not result.get("success", True):
        return 1, [str(result.get("message", "not converged"))]
    return 0, []


#: Exit status of ``shipid campaign``: every member ok; some flagged (none failed); some failed.
EXIT_OK, EXIT_FLAGGED, EXIT_FAILED = 0, 3, 1


def campaign_exit_status(summary: dict) -> int:
    """:data:`EXIT_FAILED` when a member failed, else :data:`EXIT_FLAGGED` when one is flagged, else 0."""
    if summary.get("n_failed"):
        return EXIT_FAILED
    return EXIT_FLAGGED if summary.get("n_flagged") else EXIT_OK


#: Files a member may write in its folder (the only names ``--force`` and ``--resume`` remove).
MEMBER_FILES = ("result.json", "predictions.json", "sweep.csv")


def _member_dir(out: Path, name: str, create: bool) -> Path:
    """``OUTDIR/name``, refused when it is a symbolic link or resolves outside OUTDIR."""
    d = out / name
    if d.is_symlink() or (d.exists() and not d.is_dir()):
        raise ValueError(f"{d}: exists and is not a folder of this campaign (a link or a file); remove it or "
                         "choose another output folder")
    if create:
        d.mkdir(exist_ok=True)
    if d.exists() and d.resolve().parent != out.resolve():
        raise ValueError(f"{d}: resolves outside the output folder {out}; choose another output folder")
    return d


def _clear_member(out: Path, name: str) -> None:
    d = out / name
    if not d.exists():
        return
    _member_dir(out, name, create=False)
    for f in MEMBER_FILES:
        try:
            os.unlink(d / f)
        except FileNotFoundError:
            pass


def _fingerprint(specs) -> str:
    text = json.dumps([{k: v for k, v in sp.items()} for sp in specs], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _read_journal(path: Path, fingerprint: str) -> dict:
    """``{name: record}`` of the members a journal says finished (lines cut by a kill are skipped)."""
    done: dict = {}
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        return done
    for i, line in enumerate(lines):
        try:
            rec = json.loads(line)
        except ValueError:
            continue  # the last line of a run killed while appending it
        if i == 0:
            if rec.get("fingerprint") != fingerprint:
                raise ValueError(f"{path}: written for another version of the campaign (its members or settings "
                                 "changed); run it into a new output folder, or pass --force to start again")
            continue
        if isinstance(rec, dict) and "name" in rec:
            files = rec.get("sha256", {})
            if all((path.parent / f).is_file() and sha256_file(path.parent / f) == h for f, h in files.items()):
                done[rec["name"]] = rec
    return done


def run_campaign(campaign, outdir, *, engine: Engine | None = None, force: bool = False, resume: bool = False,
                 on_member: Callable | None = None) -> dict:
    """Run every fit and sweep of a campaign (file path or :func:`load_campaign` dict) and write the outputs.

    Fits and sweeps are members of one map over the engine (fits first, in file order).  Each member's files
    are written as soon as it finishes, then a line is appended to ``OUTDIR/campaign.journal`` (its record and
    the SHA-256 of its files); ``resume=True`` skips the members the journal holds whose files are unchanged,
    so a campaign killed at any point loses no finished member.  Without ``force`` or ``resume`` the output
    folder must be new or empty; ``force`` first removes the members' old files (:data:`MEMBER_FILES`), the
    journal and the summary, and runs every member again.  Every write stays inside OUTDIR (member names are
    plain file names; a member folder that is a link or resolves elsewhere is refused).

    Returns the summary written to ``OUTDIR/campaign.json``: per member ``name``, ``type`` ("fit" or
    "sweep"), ``status`` ("ok", "flagged", "failed"; :func:`member_status`), ``ok`` (it ran), ``error``,
    ``reasons``, ``warnings`` (of reading its logs), ``success``, ``seed``, ``files``; and ``n_ok``,
    ``n_flagged``, ``n_failed``.  ``on_member(record)`` is called as each member's files are written.
    """
    camp = load_campaign(campaign) if not isinstance(campaign, dict) else campaign
    out = Path(outdir)
    check_output_target(out / SUMMARY, "campaign summary")
    check_output_target(out / JOURNAL, "campaign journal")  # (a FIFO there would block --resume's read)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out}: exists and is not a folder; give a new or empty output folder")
    fits, sweeps = camp["fits"], camp.get("sweeps", [])
    seeds = member_seeds(camp["seed"], len(fits) + len(sweeps))  # fits keep the seeds of a fits-only campaign
    specs = [{**f, "seed": int(f.get("seed", s))} for f, s in zip(fits, seeds)]
    specs += [{**w, "seed": s, "_member": "sweep"} for w, s in zip(sweeps, seeds[len(fits):])]
    for sp in specs:
        check_member_name(sp["name"], f"{camp.get('path', 'campaign')}: member")
    fingerprint = _fingerprint(specs)
    journal = out / JOURNAL
    busy = out.exists() and any(out.iterdir())
    if busy and not (force or resume):
        raise ValueError(f"{out}: output folder exists and is not empty; choose a new one, pass --resume to finish "
                         "a campaign run into it, or --force to run every member again")
    done = _read_journal(journal, fingerprint) if (resume and not force) else {}
    if resume and not force and busy and not journal.exists():
        raise ValueError(f"{out}: no {JOURNAL} in this folder, so nothing to resume; choose a new output folder, "
                         "or pass --force to run every member into it again")
    out.mkdir(parents=True, exist_ok=True)
    for sp in specs:
        _member_dir(out, sp["name"], create=False)  # every member folder checked before anything runs
    if force or not done:
        for f in (journal, out / SUMMARY):
            if f.is_symlink() or f.is_file():
                os.unlink(f)
    for sp in specs:
        if sp["name"] not in done:
            _clear_member(out, sp["name"])
    if not journal.exists():
        atomic_write_text(journal, json.dumps({"fingerprint": fingerprint, "campaign": camp.get("path")}) + "\n")
    todo = [sp for sp in specs if sp["name"] not in done]
    records: dict = {name: rec["record"] for name, rec in done.items()}

    def finished(o: Outcome) -> None:
        spec = todo[o.index]
        rec = _write_member(out, spec, o)
        records[spec["name"]] = rec
        sums = {f: sha256_file(out / f) for f in rec["files"]}
        with open(journal, "a", encoding="utf-8") as fh:  # one line per finished member, flushed to disk
            fh.write(json.dumps({"name": spec["name"], "record": rec, "sha256": sums}) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        if on_member is not None:
            on_member(rec)

    eng = engine or Engine(1, progress=False)
    if todo:
        eng.map(run_member, todo, desc="campaign members", warm=partial(warm_fits, warm_specs(todo)),
                cost=[member_cost(sp) for sp in todo], on_result=finished)
    members = [records[sp["name"]] for sp in specs]
    summary = {"campaign": camp.get("path"), "seed": camp["seed"], "engine": eng.describe(),
               "n_members": len(members), "n_ok": sum(m["status"] == "ok" for m in members),
               "n_flagged": sum(m["status"] == "flagged" for m in members),
               "n_failed": sum(m["status"] == "failed" for m in members), "n_resumed": len(done),
               "members": members}
    atomic_write_text(out / SUMMARY, json.dumps(summary, indent=2) + "\n", force=True)
    return CampaignResult(summary)


def _write_member(out: Path, spec: dict, o: Outcome) -> dict:
    """Write one finished member's files (exclusively: its old ones were removed before it ran); its record."""
    kind = spec.get("_member", "fit")
    value = o.value if o.ok else None
    status, reasons = member_status(value if kind == "fit" else None, o.ok)
    rec = {"name": spec["name"], "type": kind, "ok": o.ok, "status": status, "error": o.error, "reasons": reasons,
           "warnings": (value or {}).get("warnings", []) if kind == "fit" else [], "seed": spec["seed"],
           "seconds": round(o.seconds, 3), "files": []}
    if not o.ok:
        return rec
    d = _member_dir(out, spec["name"], create=True)
    if kind == "sweep":
        atomic_write_text(d / "sweep.csv", o.value.to_csv(index=False))
        rec["files"].append(f"{spec['name']}/sweep.csv")
        ok_col = "success" if "success" in o.value else "surfaced"  # turning rows / glider launches
        rec["success"] = bool(o.value[ok_col].all())
        if not rec["success"]:
            rec["status"], rec["reasons"] = "flagged", ["some runs of the sweep failed"]
        return rec
    atomic_write_text(d / "result.json", json.dumps(o.value["result"], indent=2, allow_nan=True) + "\n")
    rec["files"].append(f"{spec['name']}/result.json")
    rec["success"] = bool(o.value["result"]["success"])
    if o.value["prediction"] is not None:
        atomic_write_text(d / "predictions.json", dumps_json(o.value["prediction"]))
        rec["files"].append(f"{spec['name']}/predictions.json")
    return rec


class CampaignResult(dict, ResultMixin):
    """What :func:`run_campaign` wrote to ``campaign.json``: the same dict (``members``, ``n_failed``, ...),
    with the result contract on top (one row per member in :meth:`summary`)."""

    @property
    def success(self) -> bool:
        """Every member ran and is ``ok`` (none flagged, none failed; :func:`member_status`), and every fit and
        sweep reports success."""
        return all(m.get("ok") and m.get("status", "ok") == "ok" and m.get("success", True)
                   for m in self.get("members", []))

    @property
    def message(self) -> str:
        n = int(self.get("n_members", 0))
        unsuccessful = sum(1 for m in self.get("members", []) if m.get("ok") and not m.get("success", True))
        return (f"{n} member(s): {self.get('n_ok', 0)} ok, {self.get('n_flagged', 0)} flagged, "
                f"{self.get('n_failed', 0)} failed ({self.get('engine', '')})"
                + (f"; {unsuccessful} completed without success" if unsuccessful else ""))

    def summary(self) -> pd.DataFrame:
        """One row per member: name, type, status, ok, success, seconds, error, files written."""
        cols = ["name", "type", "status", "ok", "success", "seconds", "error", "files"]
        rows = [{"name": m.get("name"), "type": m.get("type"), "status": m.get("status"), "ok": m.get("ok"),
                 "success": m.get("success"), "seconds": m.get("seconds"), "error": m.get("error"),
                 "files": ", ".join(m.get("files", []))} for m in self.get("members", [])]
        return pd.DataFrame(rows, columns=cols)

    def to_pandas(self) -> pd.DataFrame:
        """Every member's record as written (seed included), one row each."""
        return pd.DataFrame(self.get("members", []))

    def _html_title(self) -> str:
        return f"Campaign ({self.get('n_members', 0)} members)"

    def plot(self, ax=None):
        """Seconds each member took, coloured by outcome (green ok, orange flagged or no success, red failed);
        returns the axes."""
        import matplotlib.pyplot as plt  # only when plotting: pyplot takes ~1 s to import

        df = self.summary()
        if ax is None:
            _, ax = plt.subplots(figsize=(6, 0.3 * len(df) + 1.2))
        colour = ["C3" if not ok else ("C2" if s in (True, None) and st in ("ok", None) else "C1")
                  for ok, s, st in zip(df["ok"], df["success"], df["status"])]
        ax.barh(df["name"].astype(str), df["seconds"].astype(float), color=colour)
        ax.invert_yaxis()
        ax.set_xlabel("seconds")
        return ax
