"""Whether a Numba kernel's on-disk cache already holds a compiled version (first-run honesty).

A cold cache costs minutes of compilation on the first step of a run; the progress bar says so
up front instead of showing an ETA of hours. Numba keeps a kernel's cache as an index file
(``<module>.<function>-<line>.pyXY.nbi``, next to the module in ``__pycache__`` or under
``NUMBA_CACHE_DIR``) whose entries are dropped when the source file's stamp changes; a kernel
counts as cached when its index loads with at least one compiled signature. Reading the index
uses Numba's cache object, an internal interface: if it moves, :func:`is_cached` answers None
(unknown) rather than guessing.
"""
from __future__ import annotations

__all__ = ["is_cached", "all_cached"]


def is_cached(dispatcher):
    """True if ``dispatcher`` (an ``@njit(cache=True)`` function) has a valid compiled entry in
    its on-disk cache or is already compiled in this process, False if not, None if unknown."""
    try:
        if dispatcher.signatures:
            return True
        cache = dispatcher._cache
        return len(cache._cache_file._load_index()) > 0
    except Exception:          # an internal interface that moved: say "unknown"
        return None


def all_cached(dispatchers):
    """False if any of ``dispatchers`` is known to need compiling, else True (None: unknown)."""
    states = [is_cached(d) for d in dispatchers]
    if any(s is False for s in states):
        return False
    return None if any(s is None for s in states) else True

