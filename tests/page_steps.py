"""Steps 1-2 of the reference Pall-ring page, verbatim but for the imports.

Imported by the geometry tests; ``run_step2()`` returns the page's printed figures.
"""
import numpy as np

from peclet.core import geom

R_O, H, T = 0.5, 1.0, 0.12          # outer radius, height, wall thickness
R_I = R_O - T
NWIN, YWIN = 4, 0.24                # windows per row; the two rows sit at y = ±YWIN
WR, WA, WT = 0.16, 0.17, 0.13       # window box half-extents: radial, axial, tangential
WEB = (0.40, 0.06, 0.06)            # inner web plate half-extents

def qy(a):
    """Quaternion (x,y,z,w) for a rotation by `a` about the y axis."""
    return [0.0, float(np.sin(0.5 * a)), 0.0, float(np.cos(0.5 * a))]

def pall_ring(b, certified=True):
    # The tube. core's `hollow_cylinder` [rOuter, height, thickness] is about y and is
    # DISTANCE-EXACT; `hollow_cylinder_shell` describes the same solid but is only SIGN-exact.
    if certified:
        tube = b.add_leaf("hollow_cylinder", [R_O, H, T])
    else:
        tube = b.add_leaf("hollow_cylinder_shell", [R_O, R_I, H],
                          rotation=[float(np.sin(np.pi / 4)), 0.0, 0.0, float(np.cos(np.pi / 4))])
    # Two rows of window boxes, the lower row rotated half a pitch, each box's local x pointing
    # radially outward and spanning the whole wall.
    wins = []
    for row, ysign in enumerate((+1, -1)):
        for k in range(NWIN):
            phi = 2 * np.pi * k / NWIN + (np.pi / NWIN if row else 0.0)
            wins.append(b.add_leaf("box", [WR, WA, WT],
                                   translation=[R_O * np.cos(phi), ysign * YWIN,
                                                R_O * np.sin(phi)],
                                   rotation=qy(-phi)))
    w = wins[0]
    for x in wins[1:]:
        w = b.add_union(w, x)
    # THE DESIGN DECISION: tube on the LEFT of the difference.
    shell = b.add_difference(tube, w)
    # ...and the two inner webs, unioned on (union keeps the certificate iff BOTH children have it,
    # and a box leaf does).
    return b.add_union(
        b.add_union(shell, b.add_leaf("box", list(WEB), translation=[0.0, +YWIN, 0.0])),
        b.add_leaf("box", list(WEB), translation=[0.0, -YWIN, 0.0], rotation=qy(np.pi / 2)))

b = geom.SceneBuilder()
ring = pall_ring(b, certified=True)
b_bad = geom.SceneBuilder()
ring_bad = pall_ring(b_bad, certified=False)


def run_step2():
    """The page's Step 2, returning (same_sign_fraction, cert_rows, R_BALL)."""
    R_BALL = np.sqrt(R_O ** 2 + (H / 2) ** 2)
    assert YWIN + np.linalg.norm(WEB) <= R_BALL, "web ball escapes the tube's ball"
    
    rng = np.random.default_rng(11)
    # 1) the two trees must describe the SAME solid
    q = rng.uniform(-1.0, 1.0, size=(200_000, 3))
    same = (np.sign(np.asarray(b.eval_root(ring, q)))
            == np.sign(np.asarray(b_bad.eval_root(ring_bad, q)))).mean()
    
    # 2) probe strictly outside the ball and compare phi against the distance to the ball
    u = rng.normal(size=(200_000, 3)); u /= np.linalg.norm(u, axis=1)[:, None]
    r = R_BALL * (1.0 + rng.random(200_000) * 1.4)
    p = u * r[:, None]
    lower = r - R_BALL
    
    cert_rows = []
    for lbl, bb, rr in (("certified  (hollow_cylinder)", b, ring),
                        ("uncertified (hollow_cylinder_shell)", b_bad, ring_bad)):
        phi = np.asarray(bb.eval_root(rr, p))
        slack = phi - lower
        viol = slack < 0
        cert_rows.append((lbl, slack.min(), 100 * viol.mean(),
                          (phi[viol] / lower[viol]).min() if viol.any() else 1.0))
    return same, cert_rows, R_BALL
