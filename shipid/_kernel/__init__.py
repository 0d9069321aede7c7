"""Compiled numerics (numba): the RK4 map with its tangent, the EKF filter step, the
RTS smoother's recursion and the open-loop RK4 replay, compiled together with a model's equations.

It sits below both users, :mod:`shipid.identify.ekf` (the filter and smoother drivers
``_run_compiled``/``_smooth_compiled``) and :mod:`shipid.simulate` (open-loop replay with sampled
inputs), and imports neither.  The same algorithm as :func:`shipid.identify.ekf.run_ekf` and
:func:`~shipid.identify.ekf.rts_smooth` (which dispatch here), written per
batch member as loops over samples so that numba compiles it together with
the model's equations.  The model's equations are not copied: a model
declares them (``Model._equations``, the kernel protocol ``k_consts``,
``k_rhs``, ``k_jac`` of e.g. :mod:`shipid.models._response_equations`), and
:func:`shipid._jit.rebind` builds this package's functions with those as
globals, compiled once per model (numba's disk cache keeps them; the cache
tag carries a hash of the equations' source files, so an edited equation is
recompiled).  Parameter-derived constants (``k_consts``) are computed once
per step and member.

Semantics (kept equal to the numpy path, to rounding; ``tests/test_kernel.py``):
measurement update with the finite, not-diverged channels (Joseph form,
``A - (A H^T - K R) K^T`` with ``A = P - K H P``), divergence check (NIS
above ``nis_limit``, non-finite or non-positive trace) freezing the member at
its last good values, RK4 map with the tangent of ``method`` over ``substeps``
steps per interval (input held from sample k), resets, process noise
``q dt`` per interval.  Without numba, or with ``SHIPID_JIT=0``, nothing here
is used.

One job per module: :mod:`.linalg` (Cholesky, solves, products), :mod:`.tangent` (the RK4 step, its
tangent and the input hold), :mod:`.filter` (the EKF pass per member), :mod:`.smoothers` (RTS and
Bryson-Frazier), :mod:`.replay` (open-loop RK4 of a batch); this module builds them per model (source
hash, compilation, the fallback when an equation needs reference counting) and drives the replay.
"""
from __future__ import annotations

import hashlib
import inspect
import re
import types
import warnings
from pathlib import Path

import numpy as np

from .. import _jit
from .filter import _work, ekf_batch, ekf_member
from .linalg import chol_solve, cholesky, mat_mul
from .replay import rk4_replay
from .smoothers import bf_batch, bf_member, rows_times, rts_batch, rts_member, ship_variances
from .tangent import hold_inputs, rk4_rest, tangent

__all__ = ["filter_functions", "replay_compiled", "METHODS", "SMOOTHER", "FASTMATH", "INLINE"]

#: Transition methods of the kernel (codes of ``EKFProblem.method``).
METHODS = {"rk4": 0, "rk4-exact": 1, "euler": 2}

FILTER = {"cholesky": cholesky, "chol_solve": chol_solve, "mat_mul": mat_mul, "rk4_rest": rk4_rest,
          "hold_inputs": hold_inputs, "tangent": tangent, "_work": _work,
          "ekf_member": ekf_member, "ekf_batch": ekf_batch, "rk4_replay": rk4_replay}

SMOOTHER = {"cholesky": cholesky, "chol_solve": chol_solve, "rows_times": rows_times, "ship_variances": ship_variances, "rts_member": rts_member, "rts_batch": rts_batch, "bf_member": bf_member,
            "bf_batch": bf_batch}


# ------------------------------------------------------------------ Python side
_noticed: set = set()


def _source_hash(functions: dict) -> str:
    """Hash of the source files of ``functions`` (and of this package's modules): the compiled kernel inlines them.
    Read once per process and set of functions (every fit asks; reading and hashing the files cost ~0.7 ms)."""
    key = tuple(sorted((name, id(f)) for name, f in functions.items()))
    out = _hashes.get(key)
    if out is None:
        files = {inspect.getsourcefile(getattr(f, "py_func", f)) for f in functions.values()} | _KERNEL_FILES
        h = hashlib.sha1()
        for name in sorted(files):
            with open(name, "rb") as fh:
                h.update(fh.read())
        out = _hashes[key] = h.hexdigest()[:10]
    return out


_hashes: dict = {}
#: The kernel's own source files (numba's cache of a function follows its own file, not the helpers it inlines).
_KERNEL_FILES = {str(p) for p in Path(__file__).resolve().parent.glob("*.py")}


def filter_functions(model, notice: bool = True, refcount: bool = False):
    """The compiled filter for ``model`` (a dict of numba functions), or ``None`` when compilation is
    off (:func:`shipid._jit.enabled`) or the model declares no equations (then, with ``notice``, a
    one-line notice, once per model class).  The model's equations that allocate no array are compiled
    without reference counting (:func:`_refcount_free`); with ``refcount`` (or once that build failed to
    compile, :func:`call`) all of them are reference counted (a separate build and disk cache)."""
    if not _jit.enabled():
        _jit.fallback_notice()
        return None
    eq = getattr(model, "_equations", None)
    if eq is None:
        key = type(model).__name__
        if notice and key not in _noticed:
            _noticed.add(key)
            warnings.warn(f"shipid: model '{model.name}' declares no compiled equations (Model._equations); "
                          "the EKF runs on the numpy path", RuntimeWarning, stacklevel=3)
        return None
    ns = model._equations_namespace()
    tag = "__" + re.sub(r"\W", "_", model.name) + "_" + _source_hash({**eq, **ns})
    base = ("filter", id(eq), tag)
    refcount = refcount or base in _refcounted
    key = base + (refcount,)
    out = _cache.get(key)
    if out is None:
        tag += "_rc" if refcount else ""
        funcs = _jit.rebind(eq, ns, jit=True, tag=tag,
                            no_refcount=frozenset() if refcount else _refcount_free(eq, ns))
        out = _cache[key] = _jit.rebind(FILTER, {**ns, **funcs}, jit=True, tag=tag, fastmath=FASTMATH, inline=INLINE,
                                        error_model="numpy")
        _base_of[id(out)] = base
    return out


def call(model, fns, name, *args):
    """``fns[name](*args)`` for ``fns = filter_functions(model)``.  Should that build not compile (an
    equation compiled without reference counting allocates after all: numba refuses it), the model's
    reference-counted build runs instead, now and from then on (same results, slower)."""
    base = getattr(model, "base", None)  # a ship model with wind/current parts: named after its ship model
    what = {"ekf_batch": "filter", "rk4_replay": "replay"}.get(name, name)
    _jit.compile_notice(fns[name], f"the {base.name + ' (wind/current)' if base is not None else model.name} {what}")
    try:
        return fns[name](*args)
    except _jit.compile_errors():
        base = _base_of.get(id(fns))
        if base is None or base in _refcounted:
            raise
        _refcounted.add(base)
        return filter_functions(model, refcount=True)[name](*args)


#: Names whose use allocates an array (an equation that uses one is compiled with reference counting).
_ALLOCATING = frozenset({
    "empty", "zeros", "ones", "full", "array", "asarray", "ascontiguousarray", "copy", "empty_like", "zeros_like",
    "ones_like", "full_like", "concatenate", "stack", "vstack", "hstack", "column_stack", "arange", "linspace", "eye",
    "identity", "diag", "outer", "dot", "tile", "repeat", "append", "astype", "flatten", "ravel", "reshape", "sort",
    "argsort", "unique", "where", "cumsum", "cumprod", "transpose", "broadcast_to"})


def _refcount_free(eq: dict, ns: dict) -> frozenset:
    """Names of the model's equations (``Model._equations``, in dependency order) compiled without numba's
    reference counting (:func:`shipid._jit.rebind`'s ``no_refcount``): not ``k_consts`` (it returns a new
    array), no allocating name (:data:`_ALLOCATING`) among the names their code uses, and calling only
    equations of the set that qualify themselves (none that the model's namespace provides, compiled
    elsewhere).  Array arithmetic allocates without a name; numba refuses to compile it without reference
    counting, and :func:`call` then falls back.  Why: ``k_rhs``/``k_jac`` run ~5 times per filter step and
    4 times per replay step with array arguments; their atomic reference counts cost ~7 % of a compiled
    fit (kcs-response)."""
    free: set = set()
    for name, fn in eq.items():
        if name == "k_consts" or name in ns or not isinstance(fn, types.FunctionType):
            continue
        names, codes = set(), [fn.__code__]
        while codes:
            code = codes.pop()
            names.update(code.co_names)
            codes.extend(c for c in code.co_consts if isinstance(c, types.CodeType))
        if names & _ALLOCATING or any(n != name and (n in ns or (n in eq and n not in free)) for n in names):
            continue
        free.add(name)
    return frozenset(free)


_refcounted: set = set()  # base keys of filter builds whose reference-count-free equations did not compile
_base_of: dict = {}
_cache: dict = {}
#: The kernel's helpers that numba inlines into their callers (``_jit.rebind``'s ``inline``): called once
#: or more per sample with up to ~25 array arguments, their calls cost ~0.6 us of a ~4 us filter step
#: (kcs-response, 22 states; same results to the bit), for ~2.5 s more compile time (17.8 -> 20.2 s with
#: an empty cache).  The model's equations and wrappers are not inlined: no measurable gain, and
#: inlining the equations themselves would let the filter's fastmath flags change their rounding.
INLINE = frozenset({"cholesky", "chol_solve", "mat_mul", "rk4_rest", "hold_inputs", "tangent", "ship_variances", "rows_times"})
#: The filter and smoother compile with numba's ``error_model="numpy"`` (a division by zero gives inf/NaN, as
#: on the numpy path, instead of raising: no check per division; smoother ~0.1 us per sample faster, results
#: identical to the bit on the bench log).
#: numba's fastmath flags of the filter and smoother: sums may be reassociated and fused (so that the
#: loops vectorise); not "nnan"/"ninf", which would break the NaN-based divergence checks.
FASTMATH = {"reassoc", "contract"}


def replay_compiled(model, x0, t, U, p, nsteps, foh: bool):
    """Open-loop RK4 of ``model`` on its kernel equations (what :func:`shipid.simulate.simulate` does
    with sampled inputs and ``method="rk4"``): compiled, or -- without compilation, for one
    trajectory -- the same :func:`rk4_replay` run by the Python interpreter on floats (one trajectory
    is a chain of scalar operations, ~3.5x cheaper on floats than on numpy arrays of six entries; a
    batch stays on the caller's numpy path).  ``None`` when neither applies (a batch without
    compilation, a model without kernel equations) or a state became non-finite (the caller's numpy
    path then reports it with its own failure semantics).

    ``x0 (B, nx)``, ``t (nt,)``, ``U (B, nt, nu)``, ``p (np,)`` or ``(B, np)``, ``nsteps (nt-1,)`` int,
    ``foh``: first-order hold.  Returns ``X (B, nt, nx)``.
    """
    fns = filter_functions(model, notice=False)  # the simulator's numpy path is not slower than expected
    if fns is None:
        if len(x0) != 1 or _jit.enabled() or not getattr(model, "_python_replay", False):
            return None
        fns = python_functions(model)
        if fns is None:
            return None
    f64 = lambda a: np.ascontiguousarray(a, dtype=float)  # noqa: E731
    x0 = f64(x0)
    X = np.empty((x0.shape[0], len(t), x0.shape[1]))
    try:
        args = (f64(t), f64(U), x0, f64(np.atleast_2d(p)), f64(model._kernel_constants()),
                np.ascontiguousarray(nsteps, dtype=np.int64), bool(foh), X)
        bad = call(model, fns, "rk4_replay", *args) if _jit.enabled() else fns["rk4_replay"](*args)
    except (ArithmeticError, ValueError):  # the interpreter's float maths raises where numpy gives inf/NaN
        return None
    return None if bad else X


def python_functions(model):
    """:data:`FILTER` with ``model``'s kernel equations as globals, not compiled (run by the interpreter:
    the same source as the compiled kernel), or ``None`` when the model declares no equations."""
    eq = getattr(model, "_equations", None)
    if eq is None:
        return None
    key = ("python", id(eq), type(model))
    hit = _cache.get(key)
    if hit is None or hit[0] is not eq:
        ns = model._equations_namespace()
        hit = _cache[key] = (eq, _jit.rebind(FILTER, {**ns, **_jit.rebind(eq, ns)}))  # eq kept: ids stay unique
    return hit[1]
