"""Child-side server of peclet's own engines for the family protocol
(:mod:`peclet_verify.family_wire`): the DEM engine (``peclet.dem.Simulation``) and the mass
properties of the implicit quadrature. Run it with the interpreter of an environment that has
peclet and peclet_verify; it is also the template of a downstream engine's child::

    SubprocessDemBackend([python, path_to_this_file])
    SubprocessMassBackend([python, path_to_this_file])

Its thread count comes from ``NUMBA_NUM_THREADS`` (set per child by SubprocessDemBackend).
"""
import os
import sys

if __name__ == "__main__":
    # run by file path: make the package importable, and never shadow it by this folder
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    sys.path.insert(0, os.path.dirname(here))
    from peclet_verify.dem_backends import PecletDemBackend
    from peclet_verify.family_wire import serve
    from peclet_verify.mass_backends import PecletMassBackend
    serve(dem=PecletDemBackend(), mass=PecletMassBackend())
