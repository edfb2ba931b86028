"""The one check and call of Numba's thread count (every run's ``threads`` argument)."""
from __future__ import annotations

from peclet.core.validation import check_int

__all__ = ["set_threads"]


def set_threads(threads, name="threads"):
    """``numba.set_num_threads(threads)`` after checking 1 <= threads <= NUMBA_NUM_THREADS."""
    import numba

    t = check_int(name, threads, 1, int(numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(t)
    return t
