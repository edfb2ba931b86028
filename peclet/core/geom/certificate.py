"""Equation 1 checked on points: the one home of the certificate's test (docs/architecture.md §4).

A certified node's ball (c, r) promises ``phi(p) >= |p - c| - r`` for every p (Equation 1 of
the Pall-ring page). Its *slack* at p is ``phi(p) - (|p - c| - r)``: >= 0 where the promise
holds. An exact leaf meets the bound with equality, so a slack of a few ulps below zero is
rounding, not a violation: a violation is a slack below ``-tol * (1 + r)``.

The engine's own check (:func:`check_equation1`) and the certification suite (which asks a
foreign backend for phi) share :func:`equation1_slack` and :func:`equation1_violations`.
"""
from __future__ import annotations

import math

import numpy as np

from peclet.core.validation import PecletArgumentError, check_float, check_int

__all__ = ["equation1_slack", "equation1_violations", "exterior_points", "check_equation1",
           "SLACK_TOL"]

#: Default relative tolerance of a violation (slack < -SLACK_TOL * (1 + r)).
SLACK_TOL = 1e-12


def equation1_slack(phi, dist, radius):
    """Slack ``phi - (dist - radius)`` (lengths) of Equation 1 at points ``dist = |p - c|`` from
    the ball's centre; >= 0 where it holds. ``phi`` and ``dist`` are arrays of one shape."""
    return np.asarray(phi, dtype=np.float64) - (np.asarray(dist, dtype=np.float64) - radius)


def equation1_violations(slack, radius, tol=SLACK_TOL):
    """Boolean mask of the slacks that violate Equation 1: ``slack < -tol * (1 + radius)``.

    A NaN slack is a violation too: a phi that is not a number promises nothing."""
    slack = np.asarray(slack, dtype=np.float64)
    return ~(slack >= -tol * (1.0 + radius))


def exterior_points(centre, radius, n, seed, extent):
    """(points (n, 3), dist (n,)): points at distances ``radius * (1 + U * extent)``, U uniform
    in [0, 1), in uniformly random directions about ``centre`` (numpy ``default_rng(seed)``).
    ``dist`` is the nominal distance of each point (exact up to the rounding of the point)."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    dist = radius * (1.0 + rng.random(n) * extent)
    return centre + u * dist[:, None], dist


def check_equation1(builder, root, n=200_000, seed=11, extent=1.4, tol=SLACK_TOL):
    """Equation 1 of ``root``'s ball tested on ``n`` exterior points (the page's Step 2).

    Points: :func:`exterior_points` (radii up to ``1 + extent`` ball radii). ``n``: int in
    [1, 1e8]; ``seed``: int >= 0; ``extent`` > 0; ``tol`` >= 0 (see the module notes). Returns a
    dict: min_slack (a length), violating (fraction of points), worst_ratio (min of
    phi / (|p - c| - r) over violations, 1 if none), ball_centre, ball_radius and certified
    (the builder's claim). The test runs whatever the claim: an uncertified ball may pass.
    """
    n = check_int("n", n, 1, 10 ** 8)
    seed = check_int("seed", seed, 0)
    extent = check_float("extent", extent, 0.0, math.inf, lo_open=True)
    tol = check_float("tol", tol, 0.0)
    c, rb, cert = builder.node_bound(root)
    if not math.isfinite(rb):
        raise PecletArgumentError("root", "a node with a finite bounding ball (no half-space "
                                  "on the left of an intersection or difference)", root)
    p, dist = exterior_points(c, rb, n, seed, extent)
    phi = builder.eval_root(root, p)
    slack = equation1_slack(phi, dist, rb)
    viol = equation1_violations(slack, rb, tol)
    lower = dist[viol] - rb
    worst = float((phi[viol] / lower).min()) if viol.any() else 1.0
    return dict(min_slack=float(slack.min()), violating=float(viol.mean()), worst_ratio=worst,
                ball_centre=c.tolist(), ball_radius=float(rb), certified=bool(cert))
