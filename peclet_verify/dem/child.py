"""Child-side server of a DEM engine for the wire protocol (:mod:`peclet_verify.wire`):
peclet's own engine (``peclet.dem.Simulation``), or the engine a ``module:factory`` spec given
as the first argument makes (how the determinism certificate runs an engine in fresh
processes). Run it with the interpreter of an environment that has peclet and peclet_verify;
it is also the template of a downstream engine's child::

    SubprocessDemBackend([python, path_to_this_file])

Its thread count comes from ``NUMBA_NUM_THREADS`` (set per child by SubprocessDemBackend).
"""
import os
import sys

if __name__ == "__main__":
    # run by file path: make the package importable, and never shadow it by this folder
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    sys.path.insert(0, os.path.dirname(os.path.dirname(here)))
    from peclet_verify.dem.backend import load_backend
    from peclet_verify.wire import serve
    serve(dem=load_backend(sys.argv[1] if len(sys.argv) > 1 else "reference"))
