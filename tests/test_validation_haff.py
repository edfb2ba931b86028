"""Haff's law (validation/haff.py) at a reduced size: 300 smooth spheres at phi 0.1, e 0.9,
cooled for half a predicted t0; the fitted t0 must match kinetic theory's (Enskog rate,
Carnahan-Starling contact value) within the run's statistical scatter."""
import math

import pytest

from validation import haff


def test_the_predicted_t0_follows_the_formula():
    # n sigma^2 chi (1 - e^2) scaling: halving 1 - e^2 doubles t0; T0 four times: t0 halves
    a = haff.predicted_t0(0.1, 0.9, 1.0)
    assert haff.predicted_t0(0.1, math.sqrt(1 - 0.19 / 2), 1.0) == pytest.approx(2 * a)
    assert haff.predicted_t0(0.1, 0.9, 4.0) == pytest.approx(a / 2)
    n, chi = 0.1 / (math.pi / 6), 0.95 / 0.9 ** 3
    A = 4 / 3 * math.sqrt(math.pi) * n * chi * 0.19 / math.sqrt(math.pi / 6)
    assert a == pytest.approx(2 / A)


def test_homogeneous_cooling_follows_haffs_law():
    r = haff.run(count=300, phi=0.1, e=0.9, t_end=0.5, seed=2, progress=False)
    assert abs(r["rel_error"]) < 0.08, r["rel_error"]
    T = r["temperatures"]
    assert T[-1] < 0.55 * T[0]                     # it did cool: (1 + 0.5)^-2 = 0.44
