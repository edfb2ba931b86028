"""Child-side adapter: serve the upstream ``peclet-geom`` wheel (``from peclet import geom``)
over the :mod:`wire` protocol. Run it as a script with the interpreter of the environment
that has the wheel installed::

    SubprocessBackend([venv_python, path_to_this_file], name="peclet-geom")

It rebuilds each flat encoding (docs/architecture.md §2) with the upstream ``SceneBuilder``
calls, then evaluates with its ``eval_root`` / ``eval_root_grad``. The upstream API has no
bounding-ball query, so this backend offers no ``bound`` (the reference rule is used instead).
"""
import os
import sys

# the folder peclet_verify/ first: its wire modules load by file location
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import wheel_path  # noqa: E402  (by file location, like the wire modules)

wheel_path.drop_this_project()   # an inherited PYTHONPATH to our tree must not shadow the wheel
import numpy as np  # noqa: E402

import wire  # noqa: E402  (by file location: this interpreter may have no peclet_verify)

# kind id -> (upstream leaf name, parameter count); ids are the shared layout of
# docs/architecture.md §2
LEAVES = {1: ("sphere", 1), 2: ("hollow_cylinder", 3), 3: ("box", 3),
          4: ("hollow_cylinder_shell", 3), 5: ("capsule", 2), 6: ("torus", 2), 7: ("cone", 3),
          8: ("ellipsoid", 3), 9: ("superquadric", 4)}
OPS = {32: "add_union", 33: "add_intersection", 34: "add_difference"}


class UpstreamGeom:
    def __init__(self):
        from peclet import geom
        self.geom = geom

    def build(self, ni, nr, root):
        b = self.geom.SceneBuilder()
        idx = {}
        for i in range(int(root) + 1):
            kind, left, right = (int(v) for v in ni[i])
            rec = nr[i]
            kw = dict(translation=[float(v) for v in rec[8:11]],
                      rotation=[float(v) for v in rec[11:15]], scale=float(rec[15]))
            if kind in OPS:
                idx[i] = getattr(b, OPS[kind])(idx[left], idx[right], **kw)
            elif kind in LEAVES:
                name, n = LEAVES[kind]
                idx[i] = b.add_leaf(name, [float(v) for v in rec[:n]], **kw)
            else:
                raise ValueError(f"node {i}: kind {kind} is not an upstream leaf or operator")
        return b, idx[int(root)]

    def evaluate(self, ni, nr, root, points):
        b, r = self.build(ni, nr, root)
        return np.asarray(b.eval_root(r, np.ascontiguousarray(points, dtype=np.float64)),
                          dtype=np.float64)

    def evaluate_grad(self, ni, nr, root, points):
        b, r = self.build(ni, nr, root)
        phi, g = b.eval_root_grad(r, np.ascontiguousarray(points, dtype=np.float64))
        return np.asarray(phi, np.float64), np.asarray(g, np.float64)


if __name__ == "__main__":
    wire.serve(UpstreamGeom())
