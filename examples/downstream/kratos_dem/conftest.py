"""The entry a downstream project needs: the hook that hands peclet the impact engine to certify.

The engine is Kratos DEM (``pip install KratosMultiphysics KratosDEMApplication``, 10.4.4),
spoken to through the adapter in ``kratos_child.py`` in a child process of its own venv.
PECLET_KRATOS_VENV names that venv (a directory with ``bin/python``), PECLET_KRATOS_LAW the
contact law (``hertz``, the default: DEM_D_Hertz_viscous_Coulomb; or ``linear``:
DEM_D_Linear_viscous_Coulomb), e.g.::

    python -m venv /tmp/krvenv && /tmp/krvenv/bin/pip install KratosMultiphysics \
        KratosDEMApplication numpy
    PECLET_KRATOS_VENV=/tmp/krvenv pytest --peclet-certify --peclet-xfails xfails.toml

The child runs Kratos on one OpenMP thread (OMP_NUM_THREADS=1: one impact is two spheres).
Without the venv every certificate is skipped, with the reason saying so.
"""
import os

from peclet_verify.side_venv import side_python, skip_without_venv

HERE = os.path.dirname(os.path.abspath(__file__))
VENV_VARIABLE = "PECLET_KRATOS_VENV"
LAW_VARIABLE = "PECLET_KRATOS_LAW"


PACKAGES = "KratosMultiphysics KratosDEMApplication numpy"
EXAMPLE = "/tmp/krvenv"


def _python():
    """The side venv's interpreter, or None with the reason."""
    return side_python(VENV_VARIABLE, PACKAGES, EXAMPLE)


def pytest_collection_modifyitems(config, items):
    skip_without_venv(items, VENV_VARIABLE, PACKAGES, "Kratos DEM", EXAMPLE)


def pytest_peclet_make_impact_backend(config):
    import peclet_verify.wire
    from peclet_verify.impact.backend import SubprocessImpactBackend
    python, _ = _python()
    law = os.environ.get(LAW_VARIABLE, "hertz")
    if law not in ("hertz", "linear"):
        raise ValueError(f"{LAW_VARIABLE}={law!r}: must be 'hertz' or 'linear'")
    wire_dir = os.path.dirname(os.path.abspath(peclet_verify.wire.__file__))
    return SubprocessImpactBackend([python, os.path.join(HERE, "kratos_child.py"), law],
                                   env={"PECLET_VERIFY_DIR": wire_dir, "OMP_NUM_THREADS": "1"},
                                   timeout=600.0)
