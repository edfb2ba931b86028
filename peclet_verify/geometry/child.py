"""Child-side server of peclet's reference geometry engine for the wire protocol
(:mod:`peclet_verify.wire`). Run it with the interpreter of an environment that has peclet and
peclet_verify; it is also the template of a downstream engine's child::

    SubprocessBackend([python, path_to_this_file])
"""
import os
import sys

if __name__ == "__main__":
    # run by file path: make the package importable, and never shadow it by this folder
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    sys.path.insert(0, os.path.dirname(os.path.dirname(here)))
    from peclet_verify.geometry.backend import ReferenceBackend
    from peclet_verify.wire import serve
    serve(ReferenceBackend())
