"""Certification properties as plain functions returning :class:`PropertyResult`, by family
(every name importable from here):

- :mod:`~peclet_verify.properties.core`: :class:`PropertyResult`, the statuses, :func:`search`
  and the active certification profile;
- :mod:`~peclet_verify.properties.geometry`: Equation 1, sign and distance agreement;
- :mod:`~peclet_verify.properties.mass`: quadrature convergence, any mass-property engine
  against the closed forms;
- :mod:`~peclet_verify.properties.dem`: determinism and contact-buffer growth (peclet's engine,
  any DEM backend);
- :mod:`~peclet_verify.properties.mechanics`: closed-form mechanics of any DEM backend.

Each property checks ONE input (a tree recipe, a state, a scenario) and returns a result with
its measured figure (labels: :data:`peclet_verify.registry.FIGURES`); :func:`search` runs a
property over a Hypothesis strategy. Nothing here needs pytest.
"""
from ..backends import ReferenceBackend  # noqa: F401  (published here since the first suite)
from .core import *  # noqa: F401,F403
from .core import __all__ as _core
from .core import _bad_answer, _fixed_constant_pool, _result  # noqa: F401
from .dem import *  # noqa: F401,F403
from .dem import __all__ as _dem
from .dem import _buffer_growth_inprocess  # noqa: F401  (the buffer-growth child imports it)
from .geometry import *  # noqa: F401,F403
from .geometry import __all__ as _geometry
from .mass import *  # noqa: F401,F403
from .mass import __all__ as _mass
from .mechanics import *  # noqa: F401,F403
from .mechanics import __all__ as _mechanics

__all__ = _core + _geometry + _mass + _dem + _mechanics
