"""Whether a Numba kernel's on-disk cache already holds a compiled version (first-run honesty).

A cold cache costs minutes of compilation on the first step of a run; the progress bar says so
up front instead of showing an ETA of hours. Numba keeps a kernel's cache as an index file
(``<module>.<function>-<line>.pyXY.nbi``, next to the module in ``__pycache__`` or under
``NUMBA_CACHE_DIR``) whose entries are dropped when the source file's stamp changes; a kernel
counts as cached when its index loads with at least one compiled signature. Reading the index
uses Numba's cache object, an internal interface: if it moves, :func:`is_cached` answers None
(unknown) rather than guessing.

:func:`purge_stale` (run by ``import peclet``) drops peclet's compiled kernels when any of its
source files changed since they were compiled. Numba checks a kernel's entry against its OWN
file only, yet a kernel keeps, in its entry, the machine code of every kernel it calls from
other modules: after an edit of ``quadrature/breaks.py`` (a ``git pull``, an editable install)
the unchanged ``cell_rule.py`` went on running the old break search from its cache, silently.
"""
from __future__ import annotations

import os

__all__ = ["is_cached", "all_cached", "purge_stale"]

#: Name of the file, beside the compiled kernels of peclet's top package, that holds the source
#: stamp they were compiled from.
STAMP_FILE = "peclet-kernels.stamp"


def is_cached(dispatcher):
    """True if ``dispatcher`` (an ``@njit(cache=True)`` function) has a valid compiled entry in
    its on-disk cache or is already compiled in this process, False if not, None if unknown."""
    try:
        if dispatcher.signatures:
            return True
        # Numba's own cache objects: no public call says whether a kernel is cached
        cache = dispatcher._cache                               # noqa: SLF001
        return len(cache._cache_file._load_index()) > 0         # noqa: SLF001
    except Exception:          # an internal interface that moved: say "unknown"
        return None


def all_cached(dispatchers):
    """False if any of ``dispatchers`` is known to need compiling, else True (None: unknown)."""
    states = [is_cached(d) for d in dispatchers]
    if any(s is False for s in states):
        return False
    return None if any(s is None for s in states) else True


def _cache_dir(directory):
    """The directory Numba keeps the kernels of the modules in ``directory`` in, found with
    Numba's own cache locators (an internal interface; raises if it moved), or None."""
    from numba.core.caching import CacheImpl

    def anchor():                      # a function for the locators to place
        pass

    py = sorted(n for n in os.listdir(directory) if n.endswith(".py"))
    if not py:
        return None
    for cls in CacheImpl._locator_classes:      # noqa: SLF001 (Numba's, see the docstring)
        loc = cls.from_function(anchor, os.path.join(directory, py[0]))
        if loc is not None:
            return loc.get_cache_path()
    return None


def purge_stale():
    """Delete peclet's compiled kernels (Numba's ``.nbi`` / ``.nbc`` files) unless they were
    compiled from the current sources, and record the current sources' stamp
    (:func:`peclet.core.results_cache.code_stamp`: every ``.py`` file of the package, the
    library versions, the CPU) beside the top package's kernels. Returns the number of files
    deleted, or None when Numba's cache layout could not be found (nothing is then touched).

    When nothing changed it reads one stamp file (the stamp itself costs about 10 ms). Two
    processes that start together after a change may both purge; a kernel one of them compiled
    in between is then compiled again, never loaded stale (Numba reads an entry whose file
    vanished as a miss)."""
    from .files import write_text
    from .results_cache import code_stamp, package_dirs, package_root

    try:
        top = _cache_dir(package_root())
    except Exception:                  # Numba's internals moved: leave its cache alone
        return None
    if top is None:
        return None
    stamp_path = os.path.join(top, STAMP_FILE)
    stamp = code_stamp()
    try:
        with open(stamp_path) as fh:
            if fh.read() == stamp:
                return 0
    except OSError:
        pass
    caches = set()
    for d in package_dirs():
        try:
            c = _cache_dir(d)
        except Exception:
            return None
        if c is not None:
            caches.add(c)
    gone = 0
    for cache in sorted(caches):
        try:
            names = os.listdir(cache)
        except OSError:
            continue
        for name in names:
            if name.endswith((".nbi", ".nbc")):
                try:
                    os.remove(os.path.join(cache, name))
                    gone += 1
                except OSError:
                    pass
    try:
        write_text(stamp_path, stamp)
    except OSError:                    # an unwritable cache: Numba will not write one either
        pass
    return gone
