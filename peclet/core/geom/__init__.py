"""Geometry core: CSG trees of signed-distance leaves over the flat encoding
(docs/architecture.md §2).

>>> from peclet.core import geom
>>> b = geom.SceneBuilder()
>>> ball = b.add_leaf("sphere", [1.0])
>>> float(b.eval_root(ball, [[2.0, 0.0, 0.0]])[0])
1.0
"""
from . import encoding
from .builder import SceneBuilder, as_points, as_transform, decode, evaluate
from .certificate import check_equation1, equation1_slack, equation1_violations
from .leaves import (DIFFERENCE, INTERSECTION, LEAF_NAMES, LEAVES_BY_KIND, LEAVES_BY_NAME,
                     UNION, LeafSpec, leaf_spec)
from .quadrature import BodyProperties, body_properties, principal_frame
from .mesh import surface_mesh
from .shell import count_for_spacing, even_spacing, shell_probes
from .transforms import matrix_to_quat, quat_multiply, quat_to_matrix

__all__ = ["SceneBuilder", "decode", "evaluate", "as_points", "LEAF_NAMES", "LEAVES_BY_KIND",
           "LEAVES_BY_NAME", "LeafSpec", "leaf_spec", "UNION", "INTERSECTION", "DIFFERENCE",
           "quat_to_matrix", "matrix_to_quat", "quat_multiply", "BodyProperties",
           "body_properties", "principal_frame", "shell_probes", "count_for_spacing",
           "even_spacing", "surface_mesh", "as_transform", "encoding", "check_equation1",
           "equation1_slack", "equation1_violations"]
