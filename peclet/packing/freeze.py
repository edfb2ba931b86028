"""Freeze a pack to ``pall_ring_pack.npz`` and load it back (page Step 7).

The file carries the page's fields — ``positions`` (N, 3), ``quaternions`` (N, 4) as (x, y, z, w),
``box`` = [L_x, L_z] (periodic in x and z, floor at y = 0), ``ring_volume``, ``node_ints`` (n, 3),
``node_reals`` (n, 16), ``home_root``, ``bounding_radius`` — plus what rebuilding a Simulation
needs: ``shell`` (M, 3) home-frame probes, ``mass``, ``inv_inertia`` (3,) principal-frame inverse
moments of one element, and for the analysis ``envelope_root`` (the envelope tree in the home
frame, -1 if none), ``envelope_volume`` and ``axis_home`` (the element axis in the home frame).

Unlike the page, everything is stored in float64: the tree of a frozen pack then evaluates
bitwise like the tree that was poured. A consumer needs nothing but the file.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass

import numpy as np

from peclet.core import geom

__all__ = ["Pack", "save_pack", "load_pack", "pack_to_simulation", "atomic_write"]

_REQUIRED = ("positions", "quaternions", "box", "ring_volume", "node_ints", "node_reals",
             "home_root", "bounding_radius")


@dataclass
class Pack:
    """A frozen pack of identical elements (world frame: y up, floor at y = 0).

    positions (N, 3) centres of mass; quaternions (N, 4) (x, y, z, w) rotating the home
    (principal) frame into the world; box (L_x, L_z) the periodic box sides; node_ints /
    node_reals the flat tree encoding; home_root the element's root in its home frame;
    bounding_radius a radius about the home origin containing the solid; shell (M, 3) surface
    probes in the home frame; ring_volume, mass (density x volume), inv_inertia (3,) inverse
    principal moments; envelope_root (-1 if none) and envelope_volume; axis_home (3,) the
    element's symmetry axis in the home frame.
    """

    positions: np.ndarray
    quaternions: np.ndarray
    box: np.ndarray
    ring_volume: float
    node_ints: np.ndarray
    node_reals: np.ndarray
    home_root: int
    bounding_radius: float
    shell: np.ndarray
    mass: float
    inv_inertia: np.ndarray
    envelope_root: int = -1
    envelope_volume: float = float("nan")
    axis_home: np.ndarray = None

    def __post_init__(self):
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float64).reshape(-1, 3)
        q = np.asarray(self.quaternions, dtype=np.float64).reshape(-1, 4)
        nq = np.linalg.norm(q, axis=1)
        if len(q) != len(self.positions):
            raise ValueError(f"quaternions must have one row per position ({len(self.positions)}"
                             f"), got {len(q)}")
        if np.any(nq == 0) or not np.all(np.isfinite(q)):
            raise ValueError("quaternions must be finite and non-zero (x, y, z, w)")
        # rows already unit within 1e-14 are kept bit for bit (save -> load is the identity)
        fix = np.abs(nq - 1.0) > 1e-14
        q = q.copy()
        q[fix] /= nq[fix, None]
        self.quaternions = np.ascontiguousarray(q)
        self.box = np.asarray(self.box, dtype=np.float64).reshape(2)
        if not np.all(self.box > 0):
            raise ValueError(f"box must be 2 lengths (L_x, L_z) > 0, got {self.box.tolist()}")
        self.node_ints = np.ascontiguousarray(self.node_ints, dtype=np.int32)
        self.node_reals = np.ascontiguousarray(self.node_reals, dtype=np.float64)
        self.shell = np.ascontiguousarray(self.shell, dtype=np.float64).reshape(-1, 3)
        self.inv_inertia = np.asarray(self.inv_inertia, dtype=np.float64).reshape(3)
        self.home_root = int(self.home_root)
        self.envelope_root = int(self.envelope_root)
        if self.axis_home is None:
            self.axis_home = np.array([0.0, 1.0, 0.0])
        self.axis_home = np.asarray(self.axis_home, dtype=np.float64).reshape(3)

    @property
    def n(self) -> int:
        return len(self.positions)

    def builder(self) -> geom.SceneBuilder:
        """A SceneBuilder decoded (and re-validated) from the stored tree."""
        return geom.SceneBuilder.decode(self.node_ints, self.node_reals)

    def rotations(self) -> np.ndarray:
        """(N, 3, 3) rotation matrices of the quaternions (home -> world)."""
        x, y, z, w = self.quaternions.T
        R = np.empty((self.n, 3, 3))
        R[:, 0, 0] = 1 - 2 * (y * y + z * z)
        R[:, 0, 1] = 2 * (x * y - z * w)
        R[:, 0, 2] = 2 * (x * z + y * w)
        R[:, 1, 0] = 2 * (x * y + z * w)
        R[:, 1, 1] = 1 - 2 * (x * x + z * z)
        R[:, 1, 2] = 2 * (y * z - x * w)
        R[:, 2, 0] = 2 * (x * z - y * w)
        R[:, 2, 1] = 2 * (y * z + x * w)
        R[:, 2, 2] = 1 - 2 * (x * x + y * y)
        return R


def atomic_write(path, write):
    """Call ``write(tmp_path)`` on a temp file beside ``path``, then ``os.replace`` it over."""
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=d, prefix=".tmp-", suffix=os.path.splitext(path)[1])
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    return path


def save_pack(path, pack: Pack):
    """Write ``pack`` to ``path`` (.npz, compressed), atomically. Returns the path."""
    fields = dict(
        positions=pack.positions, quaternions=pack.quaternions, box=pack.box,
        ring_volume=np.float64(pack.ring_volume), node_ints=pack.node_ints,
        node_reals=pack.node_reals, home_root=np.int32(pack.home_root),
        bounding_radius=np.float64(pack.bounding_radius), shell=pack.shell,
        mass=np.float64(pack.mass), inv_inertia=pack.inv_inertia,
        envelope_root=np.int32(pack.envelope_root),
        envelope_volume=np.float64(pack.envelope_volume), axis_home=pack.axis_home)

    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **fields)
    return atomic_write(path, write)


def load_pack(path) -> Pack:
    """Read a pack written by :func:`save_pack` (or the page's file, which lacks the shell and
    mass fields: those then come back empty / NaN and :func:`pack_to_simulation` refuses it)."""
    with np.load(path) as z:
        missing = [k for k in _REQUIRED if k not in z.files]
        if missing:
            raise ValueError(f"{path}: not a pack file, missing fields {missing}")
        get = lambda k, d: z[k] if k in z.files else d  # noqa: E731
        return Pack(positions=z["positions"], quaternions=z["quaternions"], box=z["box"],
                    ring_volume=float(z["ring_volume"]), node_ints=z["node_ints"],
                    node_reals=z["node_reals"], home_root=int(z["home_root"]),
                    bounding_radius=float(z["bounding_radius"]),
                    shell=get("shell", np.zeros((0, 3))), mass=float(get("mass", np.nan)),
                    inv_inertia=get("inv_inertia", np.full(3, np.nan)),
                    envelope_root=int(get("envelope_root", -1)),
                    envelope_volume=float(get("envelope_volume", np.nan)),
                    axis_home=get("axis_home", None))


def pack_to_simulation(path_or_pack, material=(0.15, 0.0, 0.5), iterations=(10, 8),
                       gravity=(0.0, -9.81, 0.0), dt=2e-3, floor=True, y_top=60.0):
    """A ``peclet.dem.Simulation`` holding the frozen pack at rest, as the page set it up:
    periodic in x and z over [0, L), an analytic box floor below y = 0, the given material
    (e_n, e_t, mu), solver iterations, gravity and time step. Returns (sim, shape_id)."""
    from peclet.dem import Simulation

    pack = path_or_pack if isinstance(path_or_pack, Pack) else load_pack(path_or_pack)
    if len(pack.shell) == 0 or not np.isfinite(pack.mass):
        raise ValueError("pack has no shell/mass fields: it cannot be rebuilt into a Simulation")
    Lx, Lz = pack.box
    sim = Simulation(pack.n + 8)
    sim.set_domain((0.0, -1.2, 0.0), (Lx, y_top, Lz))
    sim.enable_periodicity(True, False, True)
    sim.set_gravity(*gravity)
    sim.set_material_params(*material)
    sim.set_solver_iterations(*iterations)
    sid = sim.add_scene_shape(pack.node_ints, pack.node_reals, pack.home_root, pack.shell,
                              pack.bounding_radius)
    if floor:
        add_floor(sim, Lx, Lz, material)
    sim.set_positions(pack.positions)
    sim.set_shape_ids(np.full(pack.n, sid, np.int32))
    sim.set_quaternions(pack.quaternions)
    sim.set_inv_mass(np.full(pack.n, 1.0 / pack.mass))
    sim.set_inv_inertia(np.tile(pack.inv_inertia, (pack.n, 1)))
    sim.set_dt(dt)
    return sim, sid


def add_floor(sim, Lx, Lz, material=(0.15, 0.0, 0.5)):
    """The page's analytic floor: a solid box below y = 0 (its top face at y = 0)."""
    fb = geom.SceneBuilder()
    floor = fb.add_leaf("box", [40.0 + Lx, 1.0, 40.0 + Lz], translation=[Lx / 2, -1.0, Lz / 2])
    fi, fr, _, _ = fb.encode()
    return sim.add_analytic_wall(fi, fr, floor, False, material[0], material[2])
