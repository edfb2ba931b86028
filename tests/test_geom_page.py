"""Steps 1-2 of the Pall-ring page: node count, sign agreement, Equation 1 on both trees."""
import numpy as np

import page_steps


def test_pall_ring_has_21_nodes():
    assert page_steps.b.num_nodes() == 21


def test_root_ball_is_the_tube_ball_and_certified():
    c, r, cert = page_steps.b.node_bound(page_steps.ring)
    assert np.array_equal(c, np.zeros(3))
    assert r == np.sqrt(page_steps.R_O ** 2 + (page_steps.H / 2) ** 2)
    assert cert
    assert not page_steps.b_bad.node_bound(page_steps.ring_bad)[2]


def test_step2_figures():
    same, rows, _ = page_steps.run_step2()
    assert same == 1.0
    (_, slack_c, viol_c, _), (_, slack_u, viol_u, ratio_u) = rows
    # certified tree: Equation 1 holds everywhere outside the ball, up to round-off
    assert viol_c == 0.0
    assert slack_c >= -1e-12
    # sign-exact tree: a quarter of the exterior violates it, worst ratio 1/sqrt(2)
    assert abs(viol_u - 24.7) <= 0.3
    assert abs(ratio_u - 1 / np.sqrt(2)) <= 1e-3
    assert slack_u < -0.2
