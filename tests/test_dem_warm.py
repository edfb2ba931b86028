"""Compiling the step ahead (peclet.dem.warm): the tail child's stand-in detection must give every
kernel it reaches the signature a real step gives it, or the run would compile those kernels
again after waiting for the children (a cold first run's time, not its bits)."""
import numpy as np
import pytest
from numba.core.registry import CPUDispatcher

from peclet.dem import warm
from peclet.dem import broadphase, contacts, guards, narrowphase, rigid, solver


def _dispatchers():
    mods = (broadphase, contacts, guards, narrowphase, rigid, solver)
    return {f"{m.__name__}.{k}": v for m in mods for k, v in vars(m).items()
            if isinstance(v, CPUDispatcher)}


def test_the_tail_compile_adds_no_signature_a_real_step_does_not_have():
    warm.compile_step_kernels("all")                 # real detection: the real signatures
    before = {k: set(d.signatures) for k, d in _dispatchers().items()}
    sim = warm.compile_step_kernels("tail")
    assert sim._num_contacts == 2                    # the solvers saw the stand-in contacts
    after = {k: set(d.signatures) for k, d in _dispatchers().items()}
    new = {k: after[k] - before.get(k, set()) for k in after if after[k] - before.get(k, set())}
    assert not new, f"the stand-in detection compiled signatures a real step does not use: {new}"


def test_the_stand_in_contacts_are_laid_out_as_gather_lays_them_out():
    c = warm.stand_in_contacts()
    for name in c._fields:
        arr = getattr(c, name)
        assert arr.flags.c_contiguous, name
        assert arr.dtype == (np.int64 if name in ("a", "b", "feat") else np.float64), name
    assert c.shift.shape == c.point.shape == c.normal.shape == (2, 3)


def test_an_unknown_part_is_refused():
    with pytest.raises(ValueError, match="part must be one of"):
        warm.compile_step_kernels("narrow")
