"""Which ``peclet`` a wheel child imports: the upstream wheel's, never this project's tree.

The upstream wheels (``peclet-geom``, ``peclet-dem``) install a top-level package named
``peclet``, as this project does. A child adapter (``geometry/wheel_child.py``,
``mass/wheel_child.py``, ``dem/wheel_child.py``) runs under the side venv's
interpreter and must import the wheel; but an inherited ``PYTHONPATH`` naming a clone of this
project (the usual way to run a checkout without installing it) puts our ``peclet`` first on
``sys.path``, and the certifier would then certify our engine while reporting on the wheel.

The rule: a ``sys.path`` entry that holds a ``peclet_verify`` package is this project (its
source tree or an install of it); the wheels never ship ``peclet_verify``. The child removes
those entries before its first ``import peclet``. The folder ``peclet_verify/`` itself (put
first so that the wire modules load by file location) holds no ``peclet_verify`` subfolder
and stays.

Loaded by file location, like the wire modules: the side venv has no ``peclet_verify``.
:func:`load_file` loads another of this package's files the same way (a family's adapter
reusing another's).
"""
import importlib.util
import os
import sys

__all__ = ["holds_this_project", "drop_this_project", "load_file", "HERE"]

#: The folder of this file: ``peclet_verify/``.
HERE = os.path.dirname(os.path.abspath(__file__))


def holds_this_project(entry):
    """True if the ``sys.path`` entry ``entry`` ("" = the working directory) holds this
    project's ``peclet_verify`` package."""
    return os.path.isdir(os.path.join(entry or os.getcwd(), "peclet_verify"))


def drop_this_project():
    """Remove every ``sys.path`` entry that holds this project, in place; returns the removed
    entries (in their order). Call before the first ``import peclet``."""
    dropped = [p for p in sys.path if holds_this_project(p)]
    sys.path[:] = [p for p in sys.path if not holds_this_project(p)]
    return dropped


def load_file(relative, name):
    """The module in ``relative`` (a path under ``peclet_verify/``, e.g.
    ``"geometry/wheel_child.py"``) loaded by file location as module ``name``."""
    spec = importlib.util.spec_from_file_location(name, os.path.join(HERE, relative))
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
