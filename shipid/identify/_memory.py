"""Memory the EKF with its smoother needs, checked before it starts.

The stored filter (means, covariances and transitions at every sample) and
the smoothed covariances grow as ``N nz^2``: a long log with many estimated
parameters can need more memory than the machine has.  :func:`check` refuses
such a run up front with the numbers, instead of swapping for minutes and
dying without a message.

What the smoother needs (filtered and predicted covariances, transitions) can
be stored in float32 (``run_ekf(store_dtype="float32")``): 20 instead of 32
bytes per ``nz^2`` and sample (the smoothed covariances stay float64).  The
filter itself runs in float64 either way; only the stored copies are rounded
(the error this puts on the smoothed estimates is stated in
``tests/test_kernel.py``).  The default ``"auto"`` stores float64 and falls
back to float32, with a warning, only when float64 would not fit.
"""
from __future__ import annotations

import os
import warnings

import numpy as np

__all__ = ["MemoryLimitError", "ekf_bytes", "memory_limit", "check", "STORE_DTYPES"]

#: Storage types of the smoother's inputs: ``"auto"`` (float64, float32 when float64 would not fit).
STORE_DTYPES = ("auto", "float64", "float32")

#: Environment variable overriding the limit: bytes, or a number with K, M, G or T (powers of 1024).
ENV = "SHIPID_MEMORY_LIMIT"


class MemoryLimitError(MemoryError, ValueError):
    """The run would need more memory than the limit (a ``ValueError`` too: the CLI reports it, exit 2)."""


def ekf_bytes(B: int, N: int, nz: int, nm: int, store: bool, itemsize: int = 8) -> int:
    """Bytes of the arrays :func:`shipid.identify.ekf.run_ekf` allocates (and, with ``store``, those
    :func:`~shipid.identify.ekf.rts_smooth` adds): per member and sample 3 ``nz x nz`` (filtered and
    predicted covariances, transition) of ``itemsize`` bytes and 2 ``nz`` (means) stored, plus the
    smoothed means and covariances (float64); innovations, their variances and flags in any case."""
    per = 2 * nm * 8 + nm + 2 * 8
    if store:
        per += 3 * nz * nz * int(itemsize) + (nz * nz + 3 * nz) * 8
    return int(B) * int(N) * per


def memory_limit() -> int | None:
    """The limit in bytes: ``SHIPID_MEMORY_LIMIT`` if set, else 90 % of the memory the kernel reports
    available (``MemAvailable`` in ``/proc/meminfo``); None when neither is known."""
    txt = os.environ.get(ENV, "").strip()
    if txt:
        mult = {"K": 1024, "M": 1024**2, "G": 1024**3, "T": 1024**4}
        unit = txt[-1].upper()
        try:
            return int(float(txt[:-1]) * mult[unit]) if unit in mult else int(float(txt))
        except ValueError:
            raise ValueError(f"{ENV}={txt!r}: give bytes or a number with K, M, G or T (e.g. 8G)") from None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(0.9 * int(line.split()[1]) * 1024)
    except OSError:
        pass
    return None


def _gb(n: float) -> str:
    return f"{n / 1024**3:.3g} GB"


def check(B: int, N: int, nz: int, nm: int, store: bool, store_dtype: str = "auto"):
    """The storage type of the smoother's inputs (``np.float64`` or ``np.float32``) for ``store_dtype``
    (one of :data:`STORE_DTYPES`); raise :class:`MemoryLimitError` when :func:`ekf_bytes` exceeds
    :func:`memory_limit` (``"auto"``: float64 if it fits, else float32 with a ``RuntimeWarning``)."""
    if store_dtype not in STORE_DTYPES:
        raise ValueError(f"store_dtype must be one of {STORE_DTYPES}, got {store_dtype!r}")
    limit = memory_limit()
    dtype = np.float32 if store_dtype == "float32" else np.float64
    need = ekf_bytes(B, N, nz, nm, store, np.dtype(dtype).itemsize)
    if limit is None or need <= limit:
        return dtype
    if store and store_dtype == "auto":
        need32 = ekf_bytes(B, N, nz, nm, store, 4)
        if need32 <= limit:
            warnings.warn(f"the EKF's stored covariances in float64 would need ~{_gb(need)}, above the limit of "
                          f"{_gb(limit)}: storing them in float32 (~{_gb(need32)}; the filter still runs in float64)",
                          RuntimeWarning, stacklevel=3)
            return np.float32
        need = need32
    src = f"{ENV}" if os.environ.get(ENV, "").strip() else f"90 % of the available memory; {ENV} sets it"
    per = need / max(B * N, 1) / 1024
    f32 = store and (store_dtype != "float64")
    hint = ""
    if store and store_dtype == "float64":
        need32 = ekf_bytes(B, N, nz, nm, store, 4)
        if need32 <= limit:
            hint = f", or store the covariances in float32 (store_dtype='float32': ~{_gb(need32)})"
    raise MemoryLimitError(
        f"the EKF {'with its smoother ' if store else ''}over {B} x {N} samples of {nz} augmented states needs "
        f"~{_gb(need)} ({per:.0f} KB per sample{' with the covariances stored in float32' if f32 else ''}), "
        f"above the limit of {_gb(limit)} ({src}); fit fewer samples "
        "(shorter or decimated logs) or estimate fewer parameters (the stored covariances grow with their "
        "square)" + ("" if not store else ", or run the filter alone (run_ekf(store=False): no smoother)") + hint)
