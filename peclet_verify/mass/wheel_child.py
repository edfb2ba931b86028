"""Child-side adapter: the upstream ``peclet-geom`` wheel's mass properties
(``SceneBuilder.body_properties``) served over the family protocol
(:mod:`peclet_verify.wire`). Run it as a script with the interpreter of the environment
that has the wheel (numpy and the wheel only; ``wire.py``, ``scenario.py`` and the tree
rebuild of :mod:`peclet_verify.geometry.wheel_child` are loaded by file path)::

    SubprocessMassBackend([venv_python, path_to_this_file], name="peclet-geom 1.0.1")

The dialect: the wheel's knob is ``n``, cells per axis of its octree (it increases: h = 1/n);
it answers a dict (``volume``, ``com``, ``inertia_tensor`` about the centre of mass) and claims
no error. What this adapter states for it, from the wheel's own documentation of
``body_properties`` ("measured ~4e-6 relative at n=32"): a relative error of 4e-6 at n = 32,
falling at least at order 1 in 1/n (``constant`` 4e-6 x 32 = 1.28e-4, ``order`` 1), tried at
n = 32 and 48 (the documented resolution and one refinement: ~0.6 s and ~2 s a solid; n = 64
takes ~4.5 s).
"""
import os
import sys

# the folder peclet_verify/ first: its wire modules load by file location
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import wheel_path  # noqa: E402  (by file location, like the wire modules)

wheel_path.drop_this_project()   # an inherited PYTHONPATH to our tree must not shadow the wheel
import numpy as np  # noqa: E402

import wire  # noqa: E402  (by file location: this interpreter has no peclet_verify)

UpstreamGeom = wheel_path.load_file("geometry/wheel_child.py", "geometry_wheel_child").UpstreamGeom

#: The wheel's documented accuracy: relative error ~4e-6 at n = 32 cells per axis.
DOCUMENTED_ERROR, DOCUMENTED_N = 4e-6, 32


class WheelMass:
    name = "peclet-geom 1.0.1 (body_properties)"
    resolutions = (32, 48)
    order = 1.0
    constant = DOCUMENTED_ERROR * DOCUMENTED_N

    def __init__(self):
        self.geom = UpstreamGeom()

    def mass_properties(self, node_ints, node_reals, root, lo, hi, resolution):
        b, r = self.geom.build(node_ints, node_reals, root)
        p = b.body_properties(r, [float(v) for v in lo], [float(v) for v in hi],
                              n=int(resolution))
        return (float(p["volume"]), np.asarray(p["com"], np.float64),
                np.asarray(p["inertia_tensor"], np.float64).reshape(3, 3), None)


if __name__ == "__main__":
    wire.serve(mass=WheelMass())
