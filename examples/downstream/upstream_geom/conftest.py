"""The one entry a downstream project needs: the hook that hands peclet the engine to certify.

The engine is the upstream ``peclet-geom`` wheel. It ships its own top-level ``peclet``
package, which must not meet the one under test, so it lives in its own virtual environment
and is served out of process (numpy arrays over a pipe). PECLET_GEOM_PYTHON names that
environment's interpreter (default: ./.venv/bin/python next to this file)."""
import os

HERE = os.path.dirname(os.path.abspath(__file__))


def pytest_peclet_make_backend(config):
    from peclet_verify.geometry.backend import SubprocessBackend, wheel_child_command
    python = os.environ.get("PECLET_GEOM_PYTHON") or os.path.join(HERE, ".venv", "bin", "python")
    if not os.path.isfile(python):
        # a ValueError here is reported by peclet as a one-line usage error
        raise ValueError(f"no interpreter with peclet-geom at {python}: run `python -m venv "
                         f"{HERE}/.venv && {HERE}/.venv/bin/pip install peclet-geom` or set "
                         f"PECLET_GEOM_PYTHON")
    return SubprocessBackend(wheel_child_command(python), name="peclet-geom")
