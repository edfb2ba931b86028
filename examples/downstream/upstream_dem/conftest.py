"""The entries a downstream project needs: hooks that hand peclet the engines to certify.

The engines are the upstream wheels ``peclet-dem`` 1.1.0 (DEM) and ``peclet-geom`` 1.0.1
(geometry and mass properties). Both ship a top-level ``peclet`` package of their own, which
must not meet the one under test, so they live in their own virtual environment and are
served out of process (numpy arrays over a pipe), each through its dialect adapter in
peclet_verify (``dem/wheel_child.py``, ``geometry/wheel_child.py``, ``mass/wheel_child.py``).

PECLET_UPSTREAM_VENV names that environment (a directory with ``bin/python``), e.g.::

    python -m venv /tmp/updem && /tmp/updem/bin/pip install peclet-dem==1.1.0 peclet-geom==1.0.1
    PECLET_UPSTREAM_VENV=/tmp/updem pytest --peclet-certify

Without it every certificate is skipped, with the reason saying so.
"""

from peclet_verify.side_venv import side_python, skip_without_venv

VENV_VARIABLE = "PECLET_UPSTREAM_VENV"
#: Seconds each answer of a wheel may take (a DEM run of a few thousand steps in float32).
TIMEOUT = 600.0


PACKAGES = "peclet-dem==1.1.0 peclet-geom==1.0.1"
EXAMPLE = "/tmp/updem"


def _python():
    """The side venv's interpreter, or None with the reason."""
    return side_python(VENV_VARIABLE, PACKAGES, EXAMPLE)


def pytest_collection_modifyitems(config, items):
    skip_without_venv(items, VENV_VARIABLE, PACKAGES, "upstream wheels", EXAMPLE)


def _env():
    # the wheel's Kokkos prints a warning at start-up without it (stderr, harmless)
    return {"OMP_PROC_BIND": "false"}


def pytest_peclet_make_backend(config):
    from peclet_verify.geometry.backend import SubprocessBackend, wheel_child_command
    python, _ = _python()
    return SubprocessBackend(wheel_child_command(python), name="peclet-geom 1.0.1",
                             env=_env(), timeout=TIMEOUT)


def pytest_peclet_make_dem_backend(config):
    from peclet_verify.dem.backend import SubprocessDemBackend, wheel_child_command
    python, _ = _python()
    return SubprocessDemBackend(wheel_child_command(python), name="peclet-dem 1.1.0",
                                env=_env(), timeout=TIMEOUT)


def pytest_peclet_make_mass_backend(config):
    from peclet_verify.mass.backend import SubprocessMassBackend, wheel_child_command
    python, _ = _python()
    return SubprocessMassBackend(wheel_child_command(python), name="peclet-geom 1.0.1",
                                 env=_env(), timeout=TIMEOUT)
