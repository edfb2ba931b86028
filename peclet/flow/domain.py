"""The lattice a flow solve lays over a pack: its size (cheap, nothing evaluated), the memory it
needs, and the field on it (:func:`pack_domain`); the module notes of
:mod:`peclet.flow.permeability` say what the window and the y modes are."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from peclet.core.validation import PecletArgumentError, check_choice, check_float

from .geometry import Grid

#: How the window is closed along y: mirrored, wrapped onto itself, or left open (refused).
Y_MODES = ("mirror", "wrap", "open")

#: Peak bytes a lattice cell costs the flow solve (populations twice, the neighbour table,
#: the boundary links, the field), measured: 260-270 B a cell of a sphere pack at porosity 0.5
#: from 617k to 4.9M cells; 512 covers a porosity up to 1.
BYTES_PER_CELL = 512
#: Peak bytes of a flow solve besides its lattice (the pack's scene, Numba's kernels).
BASE_BYTES = 300 * 2 ** 20


@dataclass(frozen=True)
class PeriodicCell:
    """The container of a triply periodic pack (a grown bed: ``peclet pack --protocol grow``):
    periodic in x and z with the pack's box and along y with period ``Ly`` (D); the lattice
    covers one whole period [0, Ly) in y, so there is no window and no seam: the body force is
    the exact dP/L along any axis."""
    Ly: float
    kind: str = "periodic"

    def label(self):
        return f"periodic cell (y period {self.Ly:g} D)"


def wrap_y(pts, y0, H, y_mode):
    """World points with y folded into the window [y0, y0 + H) (wrap) or its mirror period."""
    if y_mode == "mirror":
        t = np.mod(pts[:, 1] - y0, 2.0 * H)
        pts[:, 1] = y0 + np.where(t <= H, t, 2.0 * H - t)
    elif y_mode == "wrap":
        pts[:, 1] = y0 + np.mod(pts[:, 1] - y0, H)
    return pts


def column_window(pack, floor_y=0.0):
    """The default axial section of a column bed: (floor + c, top - c), top the highest
    centre, c = min(2 D, (top - floor) / 3) (the bed analysis's crop, peclet.packing.output.report)."""
    top = float(pack.positions[:, 1].max())
    if not top > floor_y:
        raise PecletArgumentError("pack", "a bed above the floor", f"{pack.n} elements",
                                  f"highest centre at y = {top:.4g}")
    c = min(2.0, (top - floor_y) / 3.0)
    return (floor_y + c, top - c)


def lattice_dims(pack, resolution, window=None, y_mode="wrap", container=None):
    """The lattice :func:`pack_domain` lays over a pack, without evaluating anything: (nx, ny,
    nz, h, y0, y1, H) with h the cell size and [y0, y1] the window in D, H its lattice height
    (arguments and checks as :func:`pack_domain`)."""
    from peclet.packing.analysis.geometry import bulk_windows
    resolution = check_float("resolution", resolution, 4.0, 256.0)
    y_mode = check_choice("y_mode", y_mode, Y_MODES)
    cell = isinstance(container, PeriodicCell)
    column = container is not None and not cell
    Lx, Lz = (float(v) for v in pack.box)
    if cell:
        if window is not None or y_mode != "wrap":
            raise PecletArgumentError("window", "None with y_mode 'wrap' for a triply periodic "
                                      "pack (the lattice covers its whole period)", window)
        window = (0.0, float(container.Ly))
    if column:
        h = 1.0 / resolution
        R = float(container.radius)
        nlat = 2 * int(math.ceil(R / h - 1e-9)) + 2
        nx = nz = nlat
    else:
        nx = int(round(Lx * resolution))
        h = Lx / nx
        nz = int(round(Lz / h))
        if abs(Lz / h - nz) > 1e-9 or nz < 2:
            raise PecletArgumentError("resolution", "a resolution that makes both box sides "
                                      f"whole numbers of cells (box {Lx:g} x {Lz:g} D)",
                                      resolution)
    if window is None:
        window = column_window(pack, container.floor_y) if column \
            else bulk_windows(pack)[0][0]
    if isinstance(window, (str, bytes)) or not hasattr(window, "__len__") or len(window) != 2:
        raise PecletArgumentError("window", "(y0, y1) in D with y1 > y0", window)
    y0 = check_float("window[0]", window[0])
    y1 = check_float("window[1]", window[1], y0, lo_open=True)
    ny_half = max(2, int(round((y1 - y0) / h)))
    if cell and abs((y1 - y0) / h - ny_half) > 1e-9 * ny_half:
        raise PecletArgumentError("resolution", "a resolution that makes every side of the "
                                  f"periodic cell ({Lx:g} x {y1 - y0:g} x {Lz:g} D) a whole "
                                  "number of cells", resolution)
    H = ny_half * h
    ny = 2 * ny_half if y_mode == "mirror" else ny_half
    return nx, ny, nz, h, y0, y1, H


def check_lattice_memory(pack, resolution, window=None, y_mode="wrap", container=None,
                         name="resolution", shown=None):
    """Refuse (PecletArgumentError naming ``name``, showing ``shown`` or the resolution) a
    resolution whose lattice (:func:`lattice_dims`) needs more memory than this machine gives
    a job (:func:`peclet.core.machine.check_memory`), at :data:`BYTES_PER_CELL` a cell plus
    :data:`BASE_BYTES`; returns the lattice's (nx, ny, nz)."""
    from peclet.core.machine import check_memory
    nx, ny, nz = lattice_dims(pack, resolution, window, y_mode, container)[:3]
    cells = nx * ny * nz
    check_memory(name, resolution if shown is None else shown,
                 BASE_BYTES + cells * BYTES_PER_CELL,
                 f"a {nx} x {ny} x {nz} lattice ({cells:.3g} cells) at {BYTES_PER_CELL} B a "
                 "cell")
    return nx, ny, nz


def pack_domain(pack, resolution, window=None, y_mode="wrap", container=None):
    """(grid, phi, info) for a pack: the lattice over the window and the field on it.

    resolution: cells per D (>= 4). window: (y0, y1) in D, default the page's first bulk
    window (a column: :func:`column_window`; a :class:`PeriodicCell`: its whole period, no
    window allowed). y_mode: see the module docstring. container: None (the periodic box), a
    column Container (:func:`pack_container`) or a :class:`PeriodicCell`. The box sides must
    be whole numbers of cells (to 1e-9 of a cell); a column's lattice is the square of
    2 ceil(R / h) + 2 nodes about its axis (the outer nodes are in the wall).
    """
    y_mode = check_choice("y_mode", y_mode, Y_MODES)
    nx, ny, nz, h, y0, y1, H = lattice_dims(pack, resolution, window, y_mode, container)
    cell = isinstance(container, PeriodicCell)
    column = container is not None and not cell
    Lx, Lz = (float(v) for v in pack.box)
    if column:
        R = float(container.radius)
        cx, cz = container.center_xz
        nlat = nx
    b = pack.builder()
    pos = pack.positions.copy()
    if not column:
        pos[:, 0] = np.mod(pos[:, 0], Lx)
        pos[:, 2] = np.mod(pos[:, 2], Lz)
    if cell:
        pos[:, 1] = np.mod(pos[:, 1], H)
    for p, q in zip(pos, pack.quaternions):
        b.add_instance(pack.home_root, translation=p, rotation=q)
    big = 1e6
    box = ((0.0, -big, 0.0), (Lx, big, Lz))
    if column:
        # the container's own side wall (solid where phi < 0), reaching well past the window
        wb, wroot = container.solid_walls(y1 + 2.0 * R + 4.0)[-1]

        def phi(points):
            pts = wrap_y(np.array(points, dtype=np.float64, copy=True), y0, H, y_mode)
            return np.minimum(b.eval_scene(pts), wb.eval_root(wroot, pts))
        origin = (cx - 0.5 * (nlat - 1) * h, y0 + 0.5 * h, cz - 0.5 * (nlat - 1) * h)
    elif cell:
        cbox = ((0.0, 0.0, 0.0), (Lx, H, Lz))

        def phi(points):
            pts = wrap_y(np.array(points, dtype=np.float64, copy=True), 0.0, H, "wrap")
            return b.eval_scene(pts, box=cbox, periodic=(True, True, True))
        origin = (0.5 * h, 0.5 * h, 0.5 * h)
    else:
        def phi(points):
            pts = wrap_y(np.array(points, dtype=np.float64, copy=True), y0, H, y_mode)
            return b.eval_scene(pts, box=box, periodic=(True, False, True))
        origin = (0.5 * h, y0 + 0.5 * h, 0.5 * h)
    grid = Grid(origin=origin, h=h, dims=(nx, ny, nz),
                periodic=(not column, y_mode != "open", not column))
    info = {"window": [y0, y0 + H], "y_mode": y_mode, "h_D": h, "dims": [nx, ny, nz],
            "box": [Lx, Lz], "container": "column" if column else "periodic" if cell
            else "box"}
    if column:
        info.update({"column_diameter_D": 2.0 * R, "axis_xz": [float(cx), float(cz)]})
    return grid, phi, info
