"""The one entry a downstream project needs: the hook that hands peclet the engine to certify."""
import os


def pytest_peclet_make_backend(config):
    from meshsdf import MeshEngine  # this folder is on sys.path (pytest's rootdir conftest)
    # MESH_ENGINE_N: lattice points per axis (resolution; the default-suite test runs coarser)
    return MeshEngine(n=int(os.environ.get("MESH_ENGINE_N", "40")))
