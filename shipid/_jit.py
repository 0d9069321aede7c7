"""Optional compilation of model equations with numba (the ``fast`` extra).

A model's equations are written once, as plain Python functions of floats
whose elementary functions (``sqrt``, ``sin``, ...) are the globals of their
module (e.g. :mod:`shipid.models._mmg_equations`).  :func:`rebind` runs the
same code objects with other globals -- numpy's functions for batched arrays,
complex-step-safe ones for Jacobians -- and :func:`compiled` hands them to
numba.  There is no second copy of any equation: every path executes, or
compiles, the one source.

numba is a dependency on the platforms it publishes wheels for.  Without it
(a platform without wheels: one notice, :func:`fallback_notice`), with the
environment variable ``SHIPID_JIT=0``, or inside :func:`disabled`,
:func:`compiled` returns ``None`` and the models use their numpy/math paths,
which give the same values (``tests/test_mmg.py`` compares both).
:func:`path` says which path is active (``shipid --version`` prints it).

Compiled code is cached on disk by numba (``__pycache__`` beside the source,
numba's user cache directory, or ``NUMBA_CACHE_DIR``), so only the first run
compiles (up to about a minute for a ship model's filter, said once on stderr by
:func:`compile_notice`; later runs load it in well under a second).  numba invalidates a cached function when *its*
source file changes, not when a helper in another file does: the tests
compare the compiled and pure paths, so a stale cache shows there; delete
the ``*.nbi``/``*.nbc`` files after changing a compiled helper in another file
(e.g. :func:`shipid.models.kinematics.planar_rates_cs`).
"""
from __future__ import annotations

import contextlib
import importlib.util
import os
import types
from importlib.metadata import PackageNotFoundError, version

__all__ = ["available", "enabled", "disabled", "rebind", "compiled", "path", "compile_notice", "fallback_notice",
           "set_notices"]

_numba = None  # the numba module once imported (lazily: importing it takes ~0.6 s)
_HAVE_NUMBA = importlib.util.find_spec("numba") is not None

_off = [False]  # set by disabled() (process-wide; meant for tests and comparisons)
#: ``SHIPID_JIT=0`` in the environment (read once, at import) switches compilation off.
_ENV_OFF = os.environ.get("SHIPID_JIT", "1") == "0"
_compiled: dict = {}


def available() -> bool:
    """numba is installed."""
    return _HAVE_NUMBA


def enabled() -> bool:
    """Compiled paths are in use: numba available, ``SHIPID_JIT`` not ``0``, not inside :func:`disabled`."""
    return _HAVE_NUMBA and not _ENV_OFF and not _off[0]


def path() -> str:
    """Which path runs the equations, in words: ``"compiled path: numba 0.68.1"``, ``"numpy path: SHIPID_JIT=0"``
    or ``"numpy path: numba not installed"`` (what ``shipid --version`` prints)."""
    if not _HAVE_NUMBA:
        return "numpy path: numba not installed"
    if _ENV_OFF:
        return "numpy path: SHIPID_JIT=0"
    if _off[0]:
        return "numpy path: compilation disabled"
    try:
        return f"compiled path: numba {version('numba')}"
    except PackageNotFoundError:  # importable but without metadata (a source checkout)
        return "compiled path: numba"


#: Where notices go (a callable taking one line, or None: silent); :func:`set_notices`.
_notify = [None]
_said: set = set()


def set_notices(fn) -> None:
    """Send this module's one-line notices (compiling, fallback) to ``fn`` (e.g. ``print``), or nowhere with
    ``None`` (the default of the library; the CLI passes a function writing to stderr unless ``--quiet``)."""
    _notify[0] = fn


def _say(key: str, line: str) -> None:
    if key in _said or _notify[0] is None:
        return
    _said.add(key)
    _notify[0](line)


def fallback_notice() -> None:
    """One line, once per process, when numba is not installed: the numpy path runs (same results, slower)."""
    if not _HAVE_NUMBA:
        _say("fallback", "numba is not installed for this Python/platform: running the numpy path (same results, "
                         "about 3-8x slower); pip install numba to compile")


#: Compile time of a ship model's filter with an empty cache, said by the notice: the README's KVLCC2 ``mmg`` fit
#: took 84.5 s of CPU cold and 20.7 s warm (``benchmarks/bench_fit_cold_warm.py``, numba 0.68), so ~64 s compiling.
COMPILE_SECONDS = 60


def compile_notice(dispatcher, what: str, seconds: float = COMPILE_SECONDS) -> bool:
    """Say once per ``what`` "compiling WHAT (first run only, about N s)" when ``dispatcher`` (a numba
    function) is about to compile: not yet compiled in this process and no index of it in numba's disk cache
    (where numba would load it from instead).  Returns whether it said so.  Reading the cache location uses
    numba's internals; when they are not as expected nothing is said."""
    if getattr(dispatcher, "signatures", None):
        return False
    try:
        index = dispatcher._cache._cache_file._index_path
    except AttributeError:
        return False
    if os.path.exists(index):
        return False
    key = "compile:" + what
    if key in _said:
        return False
    _say(key, f"compiling {what} (first run only, about {seconds:.0f} s; cached for later runs)")
    return True


@contextlib.contextmanager
def disabled():
    """Context manager: use the pure numpy/math paths inside (e.g. to compare both in tests).

    Process-wide, not per thread."""
    prev = _off[0]
    _off[0] = True
    try:
        yield
    finally:
        _off[0] = prev


def rebind(functions: dict, namespace: dict, jit: bool = False, tag: str = "", fastmath=False,
           inline=frozenset(), error_model: str = "python", no_refcount=frozenset()) -> dict:
    """The ``functions`` (name -> function, in dependency order) with their globals overridden.

    Each function is rebuilt from its own code object with its module's globals updated by
    ``namespace`` and by the functions rebuilt before it, so that calls among them stay within the
    new set.  Names that ``namespace`` provides are not rebuilt (the namespace's object is used).
    With ``jit`` each rebuilt function is compiled by ``numba.njit(cache=True)`` (lazily, at its
    first call); ``tag`` is appended to the qualified names so that two sets built from the same
    functions with different globals keep separate disk caches.  ``fastmath`` is numba's option (e.g.
    ``{"reassoc", "contract"}``: sums may be reordered and fused, so loops vectorise; never the flags
    that assume finite values, which the divergence checks rely on).  ``inline``: names of functions
    that numba inlines into their callers (``inline="always"``) -- small helpers called once per sample
    with many array arguments, whose call (each array passed as its ~9 fields, reference counts
    adjusted) costs more than their arithmetic; the results are the same, compiling takes longer.
    ``error_model``: numba's (``"numpy"``: a division by zero gives inf/NaN as in numpy instead of
    raising, so a division needs no check; the kernel's divergence checks catch the NaN).
    ``no_refcount``: names compiled without numba's reference counting of arrays (its private ``_nrt=False``
    option): functions that neither allocate nor return a new array (numba refuses to compile one that does,
    a typing error), called many times per sample with array arguments, whose atomic reference counts
    (``NRT_incref``/``NRT_decref``, at entry and at each slice) would cost more than their arithmetic.  The
    results are the same to the bit.
    """
    if jit:
        _import_numba()
    ns = dict(namespace)
    out = {}
    for name, fn in functions.items():
        if name in namespace:
            continue
        g = dict(fn.__globals__)
        g.update(ns)
        new = types.FunctionType(fn.__code__, g, fn.__name__, fn.__defaults__, fn.__closure__)
        new.__qualname__, new.__doc__ = fn.__qualname__ + tag, fn.__doc__
        if jit:
            nrt = {"_nrt": False} if name in no_refcount and _has_nrt_option() else {}
            new = _numba.njit(cache=True, fastmath=fastmath, inline="always" if name in inline else "never",
                              error_model=error_model, **nrt)(new)
        ns[name] = out[name] = new
    return out


def _has_nrt_option() -> bool:
    """Whether this numba knows the private ``_nrt`` target option (0.68 does).  A numba without it would
    reject the option at the first call (a KeyError, not a compile error :func:`compile_errors` names), so
    ``no_refcount`` then compiles with reference counting: slower, same results."""
    try:
        from numba.core.cpu import CPUTargetOptions  # optional (the fast extra), ~0.6 s to import
    except ImportError:
        return False
    return hasattr(CPUTargetOptions, "_nrt")


def compile_errors() -> tuple:
    """The exceptions numba raises when it cannot compile a function (typing or lowering), for a caller that
    has a fallback."""
    return (_import_numba().core.errors.NumbaError,)


def _import_numba():
    global _numba
    if _numba is None:
        if not _HAVE_NUMBA:
            raise RuntimeError("numba is not installed: pip install numba")
        import numba  # ~0.6 s to import: only when compiling

        _numba = numba
    return _numba


def compiled(functions: dict, namespace: dict | None = None, tag: str = "", fastmath=False,
             inline=frozenset(), error_model: str = "python") -> dict | None:
    """numba-compiled ``functions`` with globals overridden by ``namespace`` (see :func:`rebind`; built
    once per ``functions`` dict), or ``None`` when compilation is not :func:`enabled`."""
    if not _HAVE_NUMBA or _ENV_OFF or _off[0]:
        return None
    out = _compiled.get(id(functions))
    if out is None:
        out = _compiled[id(functions)] = (functions, rebind(functions, namespace or {}, jit=True, tag=tag,
                                                                fastmath=fastmath, inline=inline,
                                                                error_model=error_model))
    return out[1]
