"""The entry a downstream project needs: the hook that hands peclet the DEM engine to certify.

The engine is MuJoCo (``pip install mujoco``), spoken to through the adapter in
``mujoco_child.py`` (the page's API on MuJoCo's MJCF models) in a child process of its own
venv. PECLET_MUJOCO_VENV names that venv (a directory with ``bin/python``), e.g.::

    python -m venv /tmp/mjvenv && /tmp/mjvenv/bin/pip install mujoco
    PECLET_MUJOCO_VENV=/tmp/mjvenv pytest --peclet-certify --peclet-xfails xfails.toml

Without it every certificate is skipped, with the reason saying so.
"""
import os

from peclet_verify.side_venv import side_python, skip_without_venv

HERE = os.path.dirname(os.path.abspath(__file__))
VENV_VARIABLE = "PECLET_MUJOCO_VENV"


PACKAGES = "mujoco"
EXAMPLE = "/tmp/mjvenv"


def _python():
    """The side venv's interpreter, or None with the reason."""
    return side_python(VENV_VARIABLE, PACKAGES, EXAMPLE)


def pytest_collection_modifyitems(config, items):
    skip_without_venv(items, VENV_VARIABLE, PACKAGES, "MuJoCo", EXAMPLE)


def pytest_peclet_make_dem_backend(config):
    import peclet_verify.wire
    from peclet_verify.dem.backend import SubprocessDemBackend
    python, _ = _python()
    wire_dir = os.path.dirname(os.path.abspath(peclet_verify.wire.__file__))
    return SubprocessDemBackend([python, os.path.join(HERE, "mujoco_child.py")],
                                env={"PECLET_VERIFY_DIR": wire_dir}, timeout=600.0)
