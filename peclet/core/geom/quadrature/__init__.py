"""Mass properties of a CSG solid by implicit quadrature (sign of phi only).

Method: an adaptive octree of cells with a Saye-style height-function rule in each cut cell
(Saye, SIAM J. Sci. Comput. 37(2) A993, 2015), extended with exact breakpoints at CSG creases.

- **Cells.** The box is split into ``n`` cells per axis. For a 1-Lipschitz root (every leaf
  1-Lipschitz; the certificate's second half) one evaluation at the centre decides a cell whose
  half-diagonal is below ``|phi|``: wholly inside (its box moments are added exactly) or
  outside. Other cells are *cut*.
- **Height direction.** In a cut cell the height axis k is the largest component of grad phi
  at the centre; u and v are the other two axes.
- **Inner (k), exact.** Along a line (u, v, .) every root of phi in the cell is bracketed by
  sign (steps of ``max(|phi|, hmin)`` for a 1-Lipschitz tree: ``|phi|`` proves the skipped
  stretch has no root; a uniform ``hmin`` otherwise) and refined to round-off by the Illinois
  method. The inside runs give the moments of 1, k, k^2 in closed form.
- **Middle (v), breakpoints.** The line integrals are smooth in v except where the line's
  *signature* changes: its number of roots, or the leaf active at a root (a crease; the
  evaluator reports the active leaf). Signatures are sampled at 5 points across the cell and
  every change is located by bisection to ~1e-13 of the cell; each smooth piece gets its own
  Gauss-Legendre rule, so creases and the jumps of walls parallel to k cost no accuracy.
- **Outer (u)** Gauss-Legendre across the cell.
- **Error estimate and adaptivity.** Every cut cell is integrated with q = 5 and q = 7 points
  per transverse axis; the reported value is the q = 7 one and |I7 - I5| its error estimate,
  which over-estimates the q = 7 error wherever the rule converges (plus a few ulps of the
  cell for the round-off of its roots). Refinement is global: while the estimates, measured
  against the solid's own volume and second moments, add up to more than ``tol``, the cells
  with the largest are split into 8 (down to ``MAX_DEPTH`` levels). The estimates of all
  accepted cells add up to the reported error.
- **Missed structure.** A vertex of the solid poking into a cell between the probe lines
  leaves no trace in the rule; in a cell the certificate cannot decide whose rule found no
  surface, Newton projections from the centre and the octant centres look for it, and a
  cell found to hold surface that way is split. A wedge thinning towards a vertex is
  followed by its extrapolated midpoints while a u-breakpoint is bisected, and the bracket's
  lower end is probed again with the upper end's pieces.

The work is parallel over the cells of each refinement pass, each writing its own row, and
the rows are summed in a fixed order: results are bitwise identical at any thread count.

Modules, in the order of the algorithm: :mod:`.constants` (every tuning constant, with why),
:mod:`.line_search` (the certified 1-D line search and a line's moments), :mod:`.pieces`
(knots, signatures, piece midpoints), :mod:`.levels` (what the break search's two levels
differ in, its probe grid), :mod:`.breaks` (the break search, one scan serving the v-level and
the u-level), :mod:`.cell_rule` (the cell rule and its error estimate),
:mod:`.refine` (the octree refinement driver), :mod:`.api` (the public functions).
"""
from .api import BodyProperties, body_properties, check_box, principal_axes, principal_frame

__all__ = ["BodyProperties", "body_properties", "principal_frame", "principal_axes",
           "check_box"]
