"""Freeze a pack to ``pall_ring_pack.npz`` and load it back (page Step 7).

The file carries the page's fields — ``positions`` (N, 3), ``quaternions`` (N, 4) as (x, y, z, w),
``box`` = [L_x, L_z] (periodic in x and z, floor at y = 0), ``ring_volume``, ``node_ints`` (n, 3),
``node_reals`` (n, 16), ``home_root``, ``bounding_radius`` — plus what rebuilding a Simulation
needs: ``shell`` (M, 3) home-frame probes, ``mass``, ``inv_inertia`` (3,) principal-frame inverse
moments of one element, and for the analysis ``envelope_root`` (the envelope tree in the home
frame, -1 if none), ``envelope_volume`` and ``axis_home`` (the element axis in the home frame).

Unlike the page, everything is stored in float64: the tree of a frozen pack then evaluates
bitwise like the tree that was poured. A consumer needs nothing but the file.

Trust: :func:`load_pack` reads with ``allow_pickle=False`` and checks every field (kind,
shape, finiteness, ranges, the tree decodes, roots in range, one quaternion per position);
anything else is one :class:`~peclet.core.validation.PecletArgumentError` naming ``path``.
"""
from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass, fields

import numpy as np

from peclet.core import geom
from peclet.core.files import atomic_write, check_writable_path
from peclet.core.geom.transforms import quats_to_matrices
from peclet.core.validation import (PecletArgumentError, check_array, check_bool, check_float,
                                    check_int)

# atomic_write is re-exported for code that imported it from here before it moved to core
__all__ = ["Pack", "save_pack", "load_pack", "pack_to_simulation", "atomic_write"]

#: The page's fields: a file without one of them is not a pack.
_REQUIRED = ("positions", "quaternions", "box", "ring_volume", "node_ints", "node_reals",
             "home_root", "bounding_radius")
#: Integer-valued fields (stored as int32; float in a file is refused).
_INT_FIELDS = ("node_ints", "home_root", "envelope_root")


def unit_quaternions(q, name="quaternions"):
    """(N, 4) quaternions (x, y, z, w) scaled to unit length without overflow or underflow.

    Rows already unit within 1e-14 are returned bit for bit (so save -> load is the identity);
    others are divided by their largest component first, so 1e200 or 1e-200 rows normalise
    exactly as their direction says. A zero row has no direction and is refused.
    """
    q = check_array(name, q, (None, 4))
    big = np.abs(q).max(axis=1) if len(q) else np.zeros(0)
    if np.any(big == 0.0):
        raise PecletArgumentError(name, "an array of non-zero quaternions (x, y, z, w)",
                                  f"shape {q.shape}",
                                  f"row {int(np.flatnonzero(big == 0.0)[0])} is zero")
    with np.errstate(over="ignore", under="ignore"):   # an overflowed norm (inf) is fixed
        fix = np.abs(np.sqrt((q * q).sum(axis=1)) - 1.0) > 1e-14
    q = q.copy()
    s = q[fix] / big[fix, None]
    q[fix] = s / np.linalg.norm(s, axis=1)[:, None]
    return q


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

    Construction checks every field (:class:`PecletArgumentError` naming it): N >= 1 finite
    positions, one non-zero finite quaternion per position (normalised), a finite box > 0, a
    tree that decodes with the roots in range, finite volumes and radii > 0. The page's own
    file lacks the rebuild fields: an empty shell with mass / inv_inertia / envelope_volume NaN
    stands for "absent" (:func:`pack_to_simulation` then refuses it).
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
        self.positions = check_array("positions", self.positions, (None, 3))
        n = len(self.positions)
        if n < 1:
            raise PecletArgumentError("positions", "an array of shape (N, 3) with N >= 1",
                                      self.positions)
        q = check_array("quaternions", self.quaternions, (None, 4))
        if len(q) != n:
            raise PecletArgumentError("quaternions", f"an array of shape ({n}, 4), one row per "
                                      "position", f"shape {q.shape}")
        self.quaternions = unit_quaternions(q)
        self.box = check_array("box", self.box, (2,))
        if not np.all(self.box > 0):
            raise PecletArgumentError("box", "2 finite lengths (L_x, L_z) > 0",
                                      self.box.tolist())
        self.node_ints = _int_array("node_ints", self.node_ints, (None, 3))
        self.node_reals = check_array("node_reals", self.node_reals, (len(self.node_ints), 16))
        m = len(self.node_ints)
        if m < 1:
            raise PecletArgumentError("node_ints", "an array of shape (n, 3) with n >= 1",
                                      self.node_ints)
        try:
            geom.SceneBuilder.decode(self.node_ints, self.node_reals)
        except ValueError as exc:
            raise PecletArgumentError("node_ints", "a valid flat tree encoding with "
                                      "node_reals", f"{m} nodes", str(exc)) from None
        self.home_root = check_int("home_root", self.home_root, 0, m - 1)
        self.envelope_root = check_int("envelope_root", self.envelope_root, -1, m - 1)
        self.ring_volume = check_float("ring_volume", self.ring_volume, 0.0, lo_open=True)
        self.bounding_radius = check_float("bounding_radius", self.bounding_radius, 0.0,
                                           lo_open=True)
        self.shell = check_array("shell", self.shell, (None, 3))
        self.mass = _positive_or_absent("mass", self.mass)
        self.inv_inertia = check_array("inv_inertia", self.inv_inertia, (3,), finite=False)
        if not (np.all(np.isnan(self.inv_inertia))
                or np.all(np.isfinite(self.inv_inertia) & (self.inv_inertia > 0))):
            raise PecletArgumentError("inv_inertia", "3 finite inverse moments > 0 (or all NaN "
                                      "when absent)", self.inv_inertia.tolist())
        self.envelope_volume = _positive_or_absent("envelope_volume", self.envelope_volume)
        if self.axis_home is None:
            self.axis_home = np.array([0.0, 1.0, 0.0])
        self.axis_home = check_array("axis_home", self.axis_home, (3,))
        if not np.any(self.axis_home != 0):
            raise PecletArgumentError("axis_home", "a non-zero axis", self.axis_home.tolist())

    @property
    def n(self) -> int:
        return len(self.positions)

    def builder(self) -> geom.SceneBuilder:
        """A SceneBuilder decoded (and re-validated) from the stored tree."""
        return geom.SceneBuilder.decode(self.node_ints, self.node_reals)

    def rotations(self) -> np.ndarray:
        """(N, 3, 3) rotation matrices of the quaternions (home -> world)."""
        return rotation_matrices(self.quaternions)


def rotation_matrices(q) -> np.ndarray:
    """(N, 3, 3) rotation matrices of unit quaternions ``q`` (N, 4), (x, y, z, w), active
    (the core's :func:`~peclet.core.geom.transforms.quats_to_matrices`)."""
    return quats_to_matrices(np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 4))


def _int_array(name, value, shape):
    """An int32 array of ``shape``; float, bool and object arrays are refused (a tree index
    stored as a float is not a peclet file)."""
    a = np.asarray(value) if not isinstance(value, (str, bytes)) else None
    if a is None or a.dtype.kind not in "iu":
        raise PecletArgumentError(name, "an integer array",
                                  value if a is None else f"dtype {a.dtype}")
    a = check_array(name, a, shape, dtype=np.int64, finite=False)
    if a.size and (a.min() < np.iinfo(np.int32).min or a.max() > np.iinfo(np.int32).max):
        raise PecletArgumentError(name, "an int32 array", f"values in [{a.min()}, {a.max()}]")
    return np.ascontiguousarray(a, dtype=np.int32)


def _positive_or_absent(name, value):
    """A finite float > 0, or NaN meaning "not stored" (the page's file)."""
    if isinstance(value, (float, np.floating)) and np.isnan(value):
        return float("nan")
    return check_float(name, value, 0.0, lo_open=True)


def save_pack(path, pack: Pack):
    """Write ``pack`` to ``path`` (.npz, compressed) with :func:`peclet.core.files.atomic_write`.

    The pack is checked again first (its fields may have been changed since it was made):
    NaN positions and the like raise :class:`PecletArgumentError` and nothing is written.
    Returns the path.
    """
    if not isinstance(pack, Pack):
        raise PecletArgumentError("pack", "a peclet.packing.bed.freeze.Pack", pack)
    check_writable_path(path, "path")
    try:
        pk = Pack(**{f.name: getattr(pack, f.name) for f in fields(Pack)})
    except PecletArgumentError as exc:
        raise PecletArgumentError(f"pack.{exc.argument}", "consistent", exc.value,
                                  _one_line(exc)) from None
    fields_ = dict(
        positions=pk.positions, quaternions=pk.quaternions, box=pk.box,
        ring_volume=np.float64(pk.ring_volume), node_ints=pk.node_ints,
        node_reals=pk.node_reals, home_root=np.int32(pk.home_root),
        bounding_radius=np.float64(pk.bounding_radius), shell=pk.shell,
        mass=np.float64(pk.mass), inv_inertia=pk.inv_inertia,
        envelope_root=np.int32(pk.envelope_root),
        envelope_volume=np.float64(pk.envelope_volume), axis_home=pk.axis_home)

    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **fields_)
    return atomic_write(path, write)


def _one_line(text):
    """``text`` with its line breaks and runs of spaces folded (an array's repr spans lines)."""
    return " ".join(str(text).split())


def _not_a_pack(path, why):
    return PecletArgumentError("path", "a peclet pack file (.npz written by save_pack)",
                               os.fspath(path), _one_line(why))


def load_pack(path) -> Pack:
    """Read a pack written by :func:`save_pack` (or the page's file, which lacks the shell and
    mass fields: those then come back empty / NaN and :func:`pack_to_simulation` refuses it).

    Raises :class:`PecletArgumentError` (argument ``path``) for anything that is not a
    consistent pack: a missing or unreadable file, a file that is not an .npz archive, pickled
    (object) content, a missing field, a field of the wrong kind or shape, non-finite values,
    a tree that does not decode, roots out of range, rows that do not match.
    """
    if not isinstance(path, (str, bytes, os.PathLike)):
        raise PecletArgumentError("path", "a path to a peclet pack file", path)
    if not os.path.isfile(path):
        raise _not_a_pack(path, "no such file")
    try:
        z = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise _not_a_pack(path, f"{type(exc).__name__}: {str(exc).splitlines()[0][:120]}") \
            from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise _not_a_pack(path, "a single .npy array, not an .npz archive")
    with z:
        missing = [k for k in _REQUIRED if k not in z.files]
        if missing:
            raise _not_a_pack(path, f"missing fields {missing}")
        d = {}
        for k in z.files:
            if k not in _FIELD_NAMES:
                continue          # never read: an unknown field cannot run code or cost time
            try:
                d[k] = z[k]
            except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
                raise _not_a_pack(path, f"field {k}: {type(exc).__name__}: "
                                        f"{str(exc)[:120]}") from None
    try:
        for k, v in d.items():
            if v.dtype.kind not in ("iu" if k in _INT_FIELDS else "iuf"):
                raise PecletArgumentError(k, "stored as " + ("integers" if k in _INT_FIELDS
                                                             else "numbers"), v.dtype.str)
        for k in ("ring_volume", "home_root", "bounding_radius", "mass", "envelope_root",
                  "envelope_volume"):
            if k in d:
                if d[k].shape != ():
                    raise PecletArgumentError(k, "a scalar", f"shape {d[k].shape}")
                d[k] = d[k][()]
        d.setdefault("shell", np.zeros((0, 3)))
        d.setdefault("mass", np.nan)
        d.setdefault("inv_inertia", np.full(3, np.nan))
        d.setdefault("envelope_root", -1)
        d.setdefault("envelope_volume", np.nan)
        d.setdefault("axis_home", None)
        for k in ("ring_volume", "bounding_radius", "mass", "envelope_volume"):
            d[k] = np.float64(d[k])      # the page stores float32 scalars
        return Pack(**d)
    except PecletArgumentError as exc:
        raise _not_a_pack(path, f"field {str(exc)}") from None


_FIELD_NAMES = frozenset(f.name for f in fields(Pack))


def pack_to_simulation(path_or_pack, material=(0.15, 0.0, 0.5), iterations=(10, 8),
                       gravity=(0.0, -9.81, 0.0), dt=2e-3, floor=True, y_top=None):
    """A ``peclet.dem.Simulation`` holding the frozen pack at rest, as the page set it up:
    periodic in x and z over [0, L), an analytic box floor below y = 0, the given material
    (e_n, e_t, mu), solver iterations, gravity (gx, gy, gz) (length/time^2) and time step; the
    domain's top ``y_top`` defaults to the page's 60 D or, for a taller pack, 2 D above its
    highest centre (:func:`peclet.packing.bed.pour.y_top_for`). With the ``floor`` the pack
    rests on it, so gravity must point towards it (gy < 0; a tilt in x or z is taken): gravity
    pointing up or along the floor would carry the pack off it, and is refused (naming
    ``gravity``). Returns (sim, shape_id)."""
    from peclet.dem import Simulation

    from .pour import y_top_for

    gravity = check_array("gravity", gravity, (3,))
    floor = check_bool("floor", floor)
    if floor and not gravity[1] < 0.0:
        raise PecletArgumentError(
            "gravity", "a vector pointing towards the floor the pack rests on (gy < 0, "
            "length/time^2) when floor=True", tuple(float(g) for g in gravity),
            "gy >= 0 lifts the pack off the floor or lets it drift along it; pass floor=False "
            "for a pack without a floor")

    pack = path_or_pack if isinstance(path_or_pack, Pack) else load_pack(path_or_pack)
    if len(pack.shell) == 0 or not np.isfinite(pack.mass) \
            or not np.all(np.isfinite(pack.inv_inertia)):
        raise PecletArgumentError("path_or_pack", "a pack with the shell, mass and inv_inertia "
                                  "fields (save_pack writes them; the page's file lacks them)",
                                  f"a pack of {pack.n} elements")
    low = y_top_for(pack.positions[:, 1].max())
    y_top = low if y_top is None else check_float("y_top", y_top, low)
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
