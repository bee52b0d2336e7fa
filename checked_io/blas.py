"""One BLAS thread for code that solves many small dense problems, its thread pools found once.

``threadpoolctl.threadpool_limits`` looks for the loaded BLAS libraries afresh at every call (it walks
every shared object of the process: 7 ms of CPU a call here, 45 % of a tracked map's CPU when SSI ran it
once per window); :func:`one_blas_thread` finds them once per process and sets the same limit.
"""

from __future__ import annotations

from functools import cache


@cache
def _blas_pools():
    """The process's BLAS thread pools (NumPy's and SciPy's libraries loaded first, so both are found)."""
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def one_blas_thread():
    """Context in which BLAS uses one thread (restored after): the matrices of pLSCF, LSFD, SSI, FDD's
    bootstrap, order removal and the truth model's eigenproblems are at most a few hundred wide, and
    threads spinning on a shared machine cost more than they give (LSFD 10x slower on a busy host).
    Hold it over a whole computation: each switch costs more CPU than the small products it brackets.

    Examples
    --------
    >>> import numpy as np
    >>> with one_blas_thread():
    ...     float(np.linalg.eigvalsh(np.diag([2.0, 1.0]))[0])
    1.0
    """
    return _blas_pools().limit(limits=1, user_api="blas")
