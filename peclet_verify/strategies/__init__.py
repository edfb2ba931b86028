"""Hypothesis strategies of the certificates, by family (every name importable from here):

- :mod:`~peclet_verify.strategies.geometry`: CSG trees as recipes, leaves, transforms, probe
  points;
- :mod:`~peclet_verify.strategies.mass`: one-leaf solids with closed-form mass properties;
- :mod:`~peclet_verify.strategies.dem`: rigid-body states and capacity sequences (peclet's
  engine), pours and capacity hints (any DEM backend);
- :mod:`~peclet_verify.strategies.mechanics`: the closed-form mechanics cases.

>>> from hypothesis import given
>>> from peclet_verify import strategies as pst
>>> @given(pst.trees(max_leaves=3))
... def test_builds(recipe):
...     b, root = recipe.build()
...     assert b.num_nodes() == recipe.num_nodes
"""
from .dem import *  # noqa: F401,F403
from .dem import __all__ as _dem
from .geometry import *  # noqa: F401,F403
from .geometry import __all__ as _geometry
from .mass import *  # noqa: F401,F403
from .mass import __all__ as _mass
from .mechanics import *  # noqa: F401,F403
from .mechanics import __all__ as _mechanics

__all__ = _geometry + _mass + _dem + _mechanics
