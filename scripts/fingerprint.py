"""Fingerprint of the engine's behaviour, for bit-for-bit restructures.

    python scripts/fingerprint.py OUT.json [--skip-pour]

Writes (and prints) the Pall ring's quadrature figures at tol 1e-6/1e-7/1e-8 (volume, com,
inertia, principal moments, estimates, cell counts, every float as its exact hex) and the
SHA-256 of the page's pack (``peclet pall-ring``, 48 rings, seed 5: positions and quaternions
of ``pall_ring_pack.npz``). Two runs of the same behaviour give byte-identical files; compare
them with ``cmp`` or ``diff``.
"""
import hashlib
import json
import os
import sys
import tempfile

import numpy as np


def _hex(a):
    return [float(x).hex() for x in np.asarray(a, dtype=np.float64).ravel()]


def quadrature_figures():
    from peclet.packing.bed import elements

    ring = elements.pall_ring()
    b, root = ring
    out = {}
    for tol in (1e-6, 1e-7, 1e-8):
        p = b.body_properties(root, *ring.bounds, n=32, tol=tol)
        out[f"{tol:g}"] = dict(volume=_hex(p.volume), com=_hex(p.com), inertia=_hex(p.inertia),
                               principal=_hex(p.principal), quat=_hex(p.quat),
                               volume_error=_hex(p.volume_error),
                               moment_error=_hex(p.moment_error),
                               cells={k: v for k, v in p.diagnostics.items()
                                      if isinstance(v, (int, float, str))})
    return out


def pack_hash():
    from peclet.packing.page import pipeline

    with tempfile.TemporaryDirectory() as d:
        pipeline.run(out=d, progress=False, write_figures=False, log=lambda *a, **k: None)
        z = np.load(os.path.join(d, "pall_ring_pack.npz"))
        h = hashlib.sha256()
        for k in ("positions", "quaternions"):
            h.update(np.ascontiguousarray(z[k], dtype=np.float64).tobytes())
        return h.hexdigest()


def main(argv):
    if not argv:
        print(__doc__)
        return 2
    res = dict(quadrature=quadrature_figures())
    if "--skip-pour" not in argv:
        res["pack_sha256"] = pack_hash()
    text = json.dumps(res, indent=1, sort_keys=True)
    with open(argv[0], "w") as fh:
        fh.write(text + "\n")
    print(text[-400:])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
