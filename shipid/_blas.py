"""One BLAS thread for iterative solvers whose iterates must not depend on the machine's thread count."""
from __future__ import annotations

from threadpoolctl import threadpool_limits

__all__ = ["one_blas_thread"]


def one_blas_thread():
    """Context in which BLAS/LAPACK use one thread (``threadpoolctl``).

    An iterative solver's iterates depend on floating-point summation order, which a multi-threaded BLAS
    changes with the thread count, and on an ill-conditioned problem the difference grows into a different
    answer: SLSQP on control scenario 3 stopped at final time 54.624 s with ``OPENBLAS_NUM_THREADS=1`` and
    54.712 s with 2; the own-damping-constrained ``response-nl`` refinement of the MARIN KVLCC2 runs ended in
    two different minima (cost 0.0470 and 0.0452).  Inside this context the solvers give the same answer
    whatever the thread setting (their matrices are small, so one thread costs little).
    """
    return threadpool_limits(limits=1, user_api="blas")
