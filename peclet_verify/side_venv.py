"""What a downstream project's ``conftest.py`` needs to certify an engine living in a venv of
its own: that venv's interpreter, named by an environment variable, and every test skipped
with the reason (and how to make the venv) when it is not there. Stdlib and pytest only."""
from __future__ import annotations

import os

__all__ = ["side_python", "skip_without_venv"]


def side_python(variable, packages, example="/tmp/venv"):
    """``(python, None)``: the interpreter of the venv the environment variable ``variable``
    names, or ``(None, why)`` with how to make one holding ``packages`` (a pip argument
    string) when the variable is unset or names no venv."""
    venv = os.environ.get(variable)
    if not venv:
        return None, (f"{variable} is not set: create the venv with `python -m venv {example} "
                      f"&& {example}/bin/pip install {packages}` and set "
                      f"{variable}={example}")
    python = os.path.join(venv, "bin", "python")
    if not os.path.isfile(python):
        return None, f"{variable}={venv}: no interpreter at {python}"
    return python, None


def skip_without_venv(items, variable, packages, engine, example="/tmp/venv"):
    """Mark every collected test in ``items`` skipped, saying that ``engine`` is not available
    and why, when :func:`side_python` finds no interpreter (call it from
    ``pytest_collection_modifyitems``)."""
    import pytest
    python, why = side_python(variable, packages, example)
    if python is None:
        skip = pytest.mark.skip(reason=f"{engine} not available: {why}")
        for item in items:
            item.add_marker(skip)
