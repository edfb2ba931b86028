"""`SceneBuilder`: author CSG trees of signed-distance leaves, certify, evaluate and encode them.

Conventions (DESIGN.md §2)
--------------------------
- phi < 0 inside the solid, > 0 outside; gradients point outward. Lengths are in the user's unit.
- A node's value in its parent frame is ``s * f(R^T (p - t) / s)`` for its transform
  ``(t, q, s)``: translation t, unit quaternion q = (x, y, z, w) (active rotation), isotropic
  scale s > 0. A non-unit quaternion is normalised (one within 1e-14 of unit is kept bit for bit);
  a zero one is an error.
- union = min, intersection = max, difference(a, b) = max(a, -b); on a tie the LEFT child wins
  (its value and gradient are returned).
- Nodes are append-only and immutable: an index, once returned, always means the same subtree.
"""
from __future__ import annotations

import math

import numpy as np

from . import kernels as K
from .bounds import combine
from .leaves import (DIFFERENCE, INTERSECTION, LEAVES_BY_KIND, MAX_PARAMS, OPERATOR_NAMES,
                     UNION, leaf_spec)
from .program import Program, compile_root
from .transforms import as_quaternion, as_scale, as_translation, compose, transform_ball

NODE_INT_COLS = 3
NODE_REAL_COLS = 16
INST_INT_COLS = 2
INST_REAL_COLS = 8


def as_points(points, name="points") -> np.ndarray:
    """Validate ``points`` as a finite (N, 3) float64 C-contiguous array."""
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.argwhere(~np.isfinite(arr).all(axis=1))[0, 0])
        raise ValueError(f"{name} must be finite; row {bad} is {arr[bad].tolist()}")
    return np.ascontiguousarray(arr)


class SceneBuilder:
    """A growing table of CSG nodes and scene instances over the flat encoding.

    Every ``add_*`` call validates its arguments and returns the new node's index. Any node can
    serve as a root. ``encode()`` produces the flat arrays of DESIGN.md §2; :meth:`decode`
    rebuilds a builder from them, re-validating every node.
    """

    def __init__(self):
        self._ints: list[tuple[int, int, int]] = []
        self._reals: list[np.ndarray] = []
        # per node: ball centre/radius (parent frame), certified, lipschitz, stack need
        self._ball_c: list[np.ndarray] = []
        self._ball_r: list[float] = []
        self._cert: list[bool] = []
        self._lip: list[bool] = []
        self._need: list[int] = []
        self._inst_roots: list[int] = []
        self._inst_reals: list[np.ndarray] = []
        self._programs: dict[int, Program] = {}
        self._scene_cache = None

    # ------------------------------------------------------------------ authoring
    def add_leaf(self, kind, params, translation=None, rotation=None, scale=None) -> int:
        """Add a primitive of ``kind`` (name or id, see :data:`LEAF_NAMES`) with ``params``.

        ``params`` must have exactly the leaf's parameter count (see the leaf table); each
        radius/extent must be > 0. Returns the node index.
        """
        spec = leaf_spec(kind)
        prm = spec.validate(params)
        return self._append(spec.kind, -1, -1, prm, translation, rotation, scale)

    def add_union(self, a, b, translation=None, rotation=None, scale=None) -> int:
        """min(a, b): the solid covered by either child."""
        return self._add_op(UNION, a, b, translation, rotation, scale)

    def add_intersection(self, a, b, translation=None, rotation=None, scale=None) -> int:
        """max(a, b): the solid covered by both children. Keeps ``a``'s ball."""
        return self._add_op(INTERSECTION, a, b, translation, rotation, scale)

    def add_difference(self, a, b, translation=None, rotation=None, scale=None) -> int:
        """max(a, -b): ``a`` with ``b`` removed. Keeps ``a``'s ball: put the certified solid left."""
        return self._add_op(DIFFERENCE, a, b, translation, rotation, scale)

    def add_reframed(self, node, translation=None, rotation=None, scale=None) -> int:
        """A copy of ``node`` whose transform is ``(translation, rotation, scale) ∘ node's own``.

        The copy shares the node's children and parameters; only its transform changes, so the
        reframed solid is exact (no resampling). Use it to move a finished tree into another
        frame, e.g. its principal frame.
        """
        node = self._check_index(node, "node")
        kind, left, right = self._ints[node]
        rec = self._reals[node]
        outer = (as_translation(translation), as_quaternion(rotation), as_scale(scale))
        t, q, s = compose(outer, (rec[8:11], rec[11:15], float(rec[15])))
        return self._append(kind, left, right, rec[:8].copy(), t, q, s)

    def num_nodes(self) -> int:
        """Number of nodes in the table."""
        return len(self._ints)

    def _add_op(self, op, a, b, translation, rotation, scale) -> int:
        a = self._check_index(a, "a")
        b = self._check_index(b, "b")
        return self._append(op, a, b, np.zeros(MAX_PARAMS), translation, rotation, scale)

    def _check_index(self, idx, name) -> int:
        if isinstance(idx, bool) or not isinstance(idx, (int, np.integer)):
            raise ValueError(f"{name} must be a node index (int), got {idx!r}")
        idx = int(idx)
        if not 0 <= idx < len(self._ints):
            raise ValueError(f"{name} must be an existing node index in [0, {len(self._ints)}), "
                             f"got {idx}")
        return idx

    def _append(self, kind, left, right, params, translation, rotation, scale) -> int:
        t = as_translation(translation)
        q = as_quaternion(rotation)
        s = as_scale(scale)
        if left < 0:
            spec = LEAVES_BY_KIND[kind]
            c = np.zeros(3)
            r = float(spec.radius(params))
            cert, lip, need = spec.exact, spec.lipschitz, 1
        else:
            ball_l = (self._ball_c[left], self._ball_r[left], self._cert[left], self._lip[left])
            ball_r = (self._ball_c[right], self._ball_r[right], self._cert[right],
                      self._lip[right])
            c, r, cert, lip = combine(kind, ball_l, ball_r)
            need = max(self._need[left], self._need[right] + 1)
            if need > K.MAX_STACK:
                raise ValueError(
                    f"tree too deep: evaluating this {OPERATOR_NAMES[kind]} needs {need} stack "
                    f"slots, the evaluator has {K.MAX_STACK}; build long chains left-deep "
                    "(add_union(chain, leaf)) or balanced")
        c, r = transform_ball(c, r, t, q, s)
        rec = np.zeros(NODE_REAL_COLS)
        rec[:MAX_PARAMS] = 0.0
        rec[:len(params)] = params[:MAX_PARAMS]
        rec[8:11] = t
        rec[11:15] = q
        rec[15] = s
        self._ints.append((int(kind), int(left), int(right)))
        self._reals.append(rec)
        self._ball_c.append(np.asarray(c, dtype=np.float64))
        self._ball_r.append(float(r))
        self._cert.append(bool(cert))
        self._lip.append(bool(lip))
        self._need.append(int(need))
        return len(self._ints) - 1

    # ------------------------------------------------------------------ queries
    def node_bound(self, root):
        """(centre (3,), radius, certified) of ``root``'s ball in its parent frame.

        The ball contains the solid. ``certified`` means Equation 1 holds,
        ``phi(p) >= |p - centre| - radius`` for every p, and phi is 1-Lipschitz (DESIGN.md §3).
        A tree with a half-space on the left of its root has an infinite radius.
        """
        root = self._check_index(root, "root")
        return self._ball_c[root].copy(), self._ball_r[root], self._cert[root]

    def is_lipschitz(self, root) -> bool:
        """True if every leaf under ``root`` is 1-Lipschitz (so phi is)."""
        return self._lip[self._check_index(root, "root")]

    def node(self, index):
        """(kind, left, right, params (8,), translation, quaternion, scale) of a node."""
        index = self._check_index(index, "index")
        rec = self._reals[index]
        kind, left, right = self._ints[index]
        return kind, left, right, rec[:8].copy(), rec[8:11].copy(), rec[11:15].copy(), rec[15]

    def program(self, root) -> Program:
        """The flat evaluation program of ``root`` (cached; nodes are immutable)."""
        root = self._check_index(root, "root")
        prog = self._programs.get(root)
        if prog is None:
            ni, nr = self._node_arrays()
            prog = compile_root(ni, nr, root)
            self._programs[root] = prog
        return prog

    def eval_root(self, root, points) -> np.ndarray:
        """phi of the tree at ``root`` at each row of ``points`` (N, 3); returns (N,) float64."""
        phi, _ = self._eval(root, points, False)
        return phi

    def eval_root_grad(self, root, points):
        """(phi (N,), gradient (N, 3)) of the tree at ``root``; the gradient is the active
        leaf's analytic gradient rotated to the root's parent frame (ties go left)."""
        return self._eval(root, points, True)

    def _eval(self, root, points, with_grad):
        prog = self.program(root)
        pts = as_points(points)
        phi = np.empty(len(pts))
        grad = np.empty((len(pts) if with_grad else 0, 3))
        K.eval_points(prog.ops, prog.leaf_kind, prog.leaf_reals, prog.op_begin, prog.op_end,
                      pts, phi, grad, with_grad)
        return phi, grad

    def bake(self, root, origin, spacing, dims, band=None) -> np.ndarray:
        """phi on the lattice ``origin + (i, j, k) * spacing``, i < dims[0], ... .

        Returns a flat array of ``prod(dims)`` values with x fastest, so
        ``bake(...).reshape(dims, order="F")[i, j, k]`` is the value at (i, j, k). Each value is
        bitwise equal to :meth:`eval_root` at ``origin + idx * spacing``.

        ``band`` (>= 0, a narrow band; needs a 1-Lipschitz root): only values with |phi| <=
        band are guaranteed exact; the others may be a bound of the same sign with magnitude
        > band (skipped by sphere tracing along x). With band >= the lattice cell diagonal,
        marching cubes gives the same mesh as on the exact bake, for far fewer evaluations.
        """
        prog = self.program(root)
        o = as_translation(origin, "origin")
        sp = np.asarray(spacing, dtype=np.float64).reshape(-1)
        if sp.size != 3 or not np.all(np.isfinite(sp)) or not np.all(sp > 0):
            raise ValueError(f"spacing must be 3 finite numbers > 0, got {spacing!r}")
        d = np.asarray(dims).reshape(-1)
        if d.size != 3 or not all(float(v).is_integer() and v >= 1 for v in d):
            raise ValueError(f"dims must be 3 integers >= 1, got {dims!r}")
        d = d.astype(np.int64)
        if band is None:
            band = -1.0
        else:
            band = float(band)
            if not (math.isfinite(band) and band >= 0.0):
                raise ValueError(f"band must be a finite number >= 0 (or None), got {band!r}")
            if not self.is_lipschitz(root):
                raise ValueError("band needs a 1-Lipschitz root (every leaf distance-exact or "
                                 "a Lipschitz bound); this tree is not: bake without band")
        out = np.empty(int(np.prod(d)))
        K.bake_lattice(prog.ops, prog.leaf_kind, prog.leaf_reals, prog.op_begin, prog.op_end,
                       o, sp, d, band, out)
        return out

    # ------------------------------------------------------------------ mass properties
    def body_properties(self, root, lo, hi, **kw):
        """Mass properties of ``root`` in the box [lo, hi]; see
        :func:`peclet.core.geom.quadrature.body_properties`."""
        from .quadrature import body_properties
        return body_properties(self, root, lo, hi, **kw)

    def principal_frame(self, root, lo, hi, **kw):
        """(new_root, props): ``root`` reframed exactly to its principal frame; see
        :func:`peclet.core.geom.quadrature.principal_frame`."""
        from .quadrature import principal_frame
        return principal_frame(self, root, lo, hi, **kw)

    # ------------------------------------------------------------------ scene
    def add_instance(self, root, translation=None, rotation=None, scale=None) -> int:
        """Place the tree at ``root`` in the scene with a transform; returns the instance index."""
        root = self._check_index(root, "root")
        rec = np.zeros(INST_REAL_COLS)
        rec[0:3] = as_translation(translation)
        rec[3:7] = as_quaternion(rotation)
        rec[7] = as_scale(scale)
        self._inst_roots.append(root)
        self._inst_reals.append(rec)
        self._scene_cache = None
        return len(self._inst_roots) - 1

    def num_instances(self) -> int:
        return len(self._inst_roots)

    def eval_scene(self, points, box=None, periodic=(False, False, False), method="pruned"):
        """phi of the scene (min over instances) at ``points`` (N, 3).

        ``box=(lo, hi)`` with ``periodic`` flags makes the scene periodic on the flagged axes:
        each instance stands at its placed position and at its images shifted by -1, 0, +1
        box lengths on every periodic axis (instances must lie within the box on those axes,
        and their bounding radii be at most one box length). ``method="pruned"`` skips certified
        instances whose ball proves they cannot be the minimum; uncertified instances ride an
        always list. ``method="brute"`` evaluates every image; both return the same bits.
        """
        from .scene import Scene
        if self._scene_cache is None or self._scene_cache[0] != (box_key(box), tuple(periodic)):
            scene = Scene.from_builder(self, box=box, periodic=periodic)
            self._scene_cache = ((box_key(box), tuple(periodic)), scene)
        return self._scene_cache[1].evaluate(points, method=method)

    # ------------------------------------------------------------------ encoding
    def _node_arrays(self):
        ni = np.array(self._ints, dtype=np.int32).reshape(-1, NODE_INT_COLS)
        nr = np.array(self._reals, dtype=np.float64).reshape(-1, NODE_REAL_COLS)
        return ni, nr

    def encode(self):
        """(node_ints (n, 3) int32, node_reals (n, 16) float64, inst_ints (m, 2) int32,
        inst_reals (m, 8) float64).

        node_ints rows are (kind, left, right), -1 for a leaf's children; node_reals rows are
        (params[0:8], t[3], q[4] as x, y, z, w, s). inst_ints rows are (root, 0);
        inst_reals rows are (t[3], q[4], s).
        """
        ni, nr = self._node_arrays()
        ii = np.zeros((len(self._inst_roots), INST_INT_COLS), dtype=np.int32)
        ii[:, 0] = self._inst_roots
        ir = np.array(self._inst_reals, dtype=np.float64).reshape(-1, INST_REAL_COLS)
        return ni, nr, ii, ir

    @classmethod
    def decode(cls, node_ints, node_reals, inst_ints=None, inst_reals=None) -> "SceneBuilder":
        """Rebuild a builder from :meth:`encode`'s arrays, validating every node.

        Children must precede their parents (as :meth:`encode` writes them). Leaf parameter
        slots beyond a kind's count are ignored. float32 input is accepted and widened.
        """
        ni = np.asarray(node_ints)
        nr = np.asarray(node_reals, dtype=np.float64)
        if ni.ndim != 2 or ni.shape[1] != NODE_INT_COLS:
            raise ValueError(f"node_ints must have shape (n, 3), got {ni.shape}")
        if nr.shape != (len(ni), NODE_REAL_COLS):
            raise ValueError(f"node_reals must have shape ({len(ni)}, 16), got {nr.shape}")
        if not np.all(np.isfinite(nr)):
            raise ValueError("node_reals must be finite")
        b = cls()
        for i, (kind, left, right) in enumerate(ni.astype(np.int64)):
            rec = nr[i]
            t, q, s = rec[8:11], rec[11:15], rec[15]
            if kind in OPERATOR_NAMES:
                for nm, c in (("left", left), ("right", right)):
                    if not 0 <= c < i:
                        raise ValueError(f"node {i}: {nm} child must be in [0, {i}), got {c}")
                b._append(int(kind), int(left), int(right), np.zeros(MAX_PARAMS), t, q, s)
            else:
                spec = leaf_spec(int(kind))
                if left != -1 or right != -1:
                    raise ValueError(f"node {i}: a leaf ({spec.name}) must have children -1, "
                                     f"got ({left}, {right})")
                prm = spec.validate(rec[:spec.n_params])
                b._append(spec.kind, -1, -1, prm, t, q, s)
        if inst_ints is not None:
            ii = np.asarray(inst_ints).reshape(-1, INST_INT_COLS)
            ir = np.asarray(inst_reals, dtype=np.float64).reshape(-1, INST_REAL_COLS)
            if len(ii) != len(ir):
                raise ValueError(f"inst_ints and inst_reals must have the same number of rows, "
                                 f"got {len(ii)} and {len(ir)}")
            for root, rec in zip(ii[:, 0], ir):
                b.add_instance(int(root), rec[0:3], rec[3:7], rec[7])
        return b


def box_key(box):
    if box is None:
        return None
    lo, hi = box
    return tuple(np.asarray(lo, float).tolist()), tuple(np.asarray(hi, float).tolist())


def decode(node_ints, node_reals, inst_ints=None, inst_reals=None) -> SceneBuilder:
    """Module-level alias of :meth:`SceneBuilder.decode`."""
    return SceneBuilder.decode(node_ints, node_reals, inst_ints, inst_reals)


def evaluate(node_ints, node_reals, root, points) -> np.ndarray:
    """phi of ``root`` of a flat encoding at ``points`` — the backend protocol's reference."""
    return SceneBuilder.decode(node_ints, node_reals).eval_root(int(root), points)
