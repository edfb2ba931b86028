"""`SceneBuilder`: author CSG trees of signed-distance leaves, certify, evaluate and encode them.

Conventions (docs/architecture.md §2)
--------------------------
- phi < 0 inside the solid, > 0 outside; gradients point outward. Lengths are in the user's unit.
- A node's value in its parent frame is ``s * f(R^T (p - t) / s)`` for its transform
  ``(t, q, s)``: translation t (3 finite numbers), unit quaternion q = (x, y, z, w) (active
  rotation; 4 finite numbers, a non-unit one is normalised, one within 1e-14 of unit is kept bit
  for bit, a zero one is an error), isotropic scale s > 0 (a finite number).
- Every public method checks its arguments first (:mod:`peclet.core.validation`): a bad one
  raises :class:`~peclet.core.validation.PecletArgumentError` (a ``ValueError``) naming it.
- union = min, intersection = max, difference(a, b) = max(a, -b); on a tie the LEFT child wins
  (its value and gradient are returned).
- Nodes are append-only and immutable: an index, once returned, always means the same subtree.
"""
from __future__ import annotations

import math

import numpy as np

from peclet.core.validation import (PecletArgumentError, as_points, check_array, check_choice,
                                    check_float)

from . import kernels as K
from .bounds import combine
from .encoding import (INST_INT_COLS, INST_REAL_COLS, INST_ROOT, INST_ROTATION, INST_SCALE,
                       INST_TRANSLATION, NODE_INT_COLS, NODE_REAL_COLS, PARAMS, ROTATION, SCALE,
                       TRANSLATION, instance_transform, node_transform)
from .leaves import (DATA, DIFFERENCE, GRID, INTERSECTION, LEAF_NAMES, LEAVES_BY_KIND, MAX_PARAMS,
                     OPERATOR_NAMES, UNION, leaf_spec)
from .program import Program, compile_root
from .sampled import check_grid_values, data_rows, grid_lipschitz, grid_radius, grid_values
from .transforms import as_quaternion, compose, transform_ball

#: Most lattice points one bake may hold (1024^3 values are 8 GiB already).
MAX_BAKE_POINTS = 1024 ** 3


def as_transform(translation=None, rotation=None, scale=None):
    """(t (3,), q (4,), s) from a node's or instance's transform arguments; None is identity.

    translation: 3 finite numbers; rotation: a quaternion (x, y, z, w) of 4 finite numbers, not
    all zero, normalised to unit length; scale: a finite number > 0.
    """
    t = np.zeros(3) if translation is None else check_array("translation", translation, (3,))
    # any finite non-zero magnitude normalises (as_quaternion scales before squaring)
    q = None if rotation is None else check_array("rotation", rotation, (4,))
    q = as_quaternion(q, "rotation")
    s = 1.0 if scale is None else check_float("scale", scale, 0.0, math.inf, lo_open=True)
    return t, q, s


def leaf_params(kind, params, name="params"):
    """(LeafSpec, params as float64 (n,)) for a leaf of ``kind``, checked against the table."""
    try:
        spec = leaf_spec(kind)
    except ValueError:
        raise PecletArgumentError("kind", f"one of {list(LEAF_NAMES)} or their ids "
                                  f"{sorted(LEAVES_BY_KIND)}", kind) from None
    names = ", ".join(spec.param_names)
    arr = check_array(name, params, (None,))
    if arr.size != spec.n_params:
        raise PecletArgumentError(name, f"{spec.n_params} number{'s' * (spec.n_params > 1)} "
                                  f"({names}) for a {spec.name}", params)
    try:
        return spec, spec.validate(arr)
    except ValueError as e:
        raise PecletArgumentError(name, f"valid {spec.name} parameters ({names})", params,
                                  str(e)) from None


class SceneBuilder:
    """A growing table of CSG nodes and scene instances over the flat encoding.

    Every ``add_*`` call validates its arguments and returns the new node's index. Any node can
    serve as a root. ``encode()`` produces the flat arrays of docs/architecture.md §2;
    :meth:`decode` rebuilds a builder from them, re-validating every node.
    """

    def __init__(self):
        self._ints: list[tuple[int, int, int]] = []
        self._reals: list[np.ndarray] = []
        # per node: ball centre/radius (parent frame), certified, lipschitz, stack need
        self._ball_c: list[np.ndarray] = []
        self._ball_r: list[float] = []
        self._cert: list[bool] = []
        self._lip: list[bool] = []
        self._lipk: list[float] = []          # a Lipschitz constant per node (inf: none known)
        self._need: list[int] = []
        self._inst_roots: list[int] = []
        self._inst_reals: list[np.ndarray] = []
        self._programs: dict[int, Program] = {}
        self._scene_cache = None

    # ------------------------------------------------------------------ authoring
    def add_leaf(self, kind, params, translation=None, rotation=None, scale=None) -> int:
        """Add a primitive of ``kind`` (name or id, see :data:`LEAF_NAMES`) with ``params``.

        ``params`` must be a 1-D sequence of exactly the leaf's parameter count of finite
        numbers (see the leaf table), each in the leaf's range (radii/extents > 0, ...).
        ``translation``/``rotation``/``scale``: see :func:`as_transform`. Returns the node index.
        """
        spec, prm = leaf_params(kind, params)
        return self._append(spec.kind, -1, -1, prm, translation, rotation, scale)

    def add_grid(self, values, spacing, translation=None, rotation=None, scale=None) -> int:
        """Add a grid leaf: signed-distance samples ``values`` (nx, ny, nz), indexed (x, y, z),
        on a lattice of ``spacing`` (a length > 0) centred on the leaf's origin (sample (i, j, k)
        at ``((i - (nx - 1) / 2) h, ...)``); the samples become data rows of the node table
        just before the leaf (:mod:`peclet.core.geom.sampled`). ``values``: 2 to 1024 finite
        samples per axis, some < 0, all > 0 on the lattice's faces (the solid inside with a
        margin). Field: trilinear inside, distance to the box plus the box value outside
        (:mod:`peclet.core.geom.grid_kernel`). Returns the leaf's node index; the leaf is
        neither exact nor 1-Lipschitz, so it is never certified (its ball is measured, §4).
        For meshes, callables and saved grids see :mod:`peclet.core.geom.grids`."""
        v, h = check_grid_values(values, spacing)
        translation, rotation, scale = as_transform(translation, rotation, scale)  # before rows
        first = len(self._ints)
        for row in data_rows(v):
            self._append_data(row)
        params = np.array([first, *v.shape, h], np.float64)
        return self._append(GRID, -1, -1, params, translation, rotation, scale)

    def _append_data(self, row):
        # a data row: not a node; placeholders keep the per-node lists aligned
        self._ints.append((DATA, -1, -1))
        self._reals.append(np.asarray(row, np.float64))
        self._ball_c.append(np.zeros(3))
        self._ball_r.append(float("nan"))
        self._cert.append(False)
        self._lip.append(False)
        self._lipk.append(math.inf)
        self._need.append(0)

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
        outer = as_transform(translation, rotation, scale)
        t, q, s = compose(outer, node_transform(rec))
        return self._append(kind, left, right, rec[PARAMS].copy(), t, q, s)

    def num_nodes(self) -> int:
        """Number of nodes in the table."""
        return len(self._ints)

    def _add_op(self, op, a, b, translation, rotation, scale) -> int:
        a = self._check_index(a, "a")
        b = self._check_index(b, "b")
        return self._append(op, a, b, np.zeros(MAX_PARAMS), translation, rotation, scale)

    def _check_index(self, idx, name, data_ok=False) -> int:
        n = len(self._ints)
        if isinstance(idx, (bool, np.bool_)) or not isinstance(idx, (int, np.integer)) \
                or not 0 <= idx < n:
            raise PecletArgumentError(name, f"an existing node index (an int in [0, {n}))", idx)
        if not data_ok and self._ints[idx][0] == DATA:
            raise PecletArgumentError(name, "a node index, not a data row (a grid leaf's "
                                      "samples)", idx)
        return int(idx)

    def _append(self, kind, left, right, params, translation, rotation, scale) -> int:
        t, q, s = as_transform(translation, rotation, scale)
        if left < 0:
            spec = LEAVES_BY_KIND[kind]
            c = np.zeros(3)
            if spec.sampled:
                values, h = check_grid_values(grid_values(
                    [k for k, _, _ in self._ints], self._reals, params, len(self._ints)),
                    params[4], "params")
                r = grid_radius(values, h)
                lipk = grid_lipschitz(values, h)
            else:
                r = float(spec.radius(params))
                lipk = 1.0 if spec.lipschitz else math.inf
            cert, lip, need = spec.exact, spec.lipschitz, 1
        else:
            ball_l = (self._ball_c[left], self._ball_r[left], self._cert[left], self._lip[left])
            ball_r = (self._ball_c[right], self._ball_r[right], self._cert[right],
                      self._lip[right])
            c, r, cert, lip = combine(kind, ball_l, ball_r)
            lipk = max(self._lipk[left], self._lipk[right])   # min and max keep the larger
            need = max(self._need[left], self._need[right] + 1)
            if need > K.MAX_STACK:
                raise PecletArgumentError(
                    "b", f"a subtree shallow enough for the evaluator's {K.MAX_STACK} stack "
                    "slots", right, f"tree too deep: evaluating this {OPERATOR_NAMES[kind]} "
                    f"needs {need} stack slots; build long chains left-deep (add_union(chain, "
                    "leaf)) or balanced")
        c, r = transform_ball(c, r, t, q, s)
        rec = np.zeros(NODE_REAL_COLS)
        rec[:len(params)] = params[:MAX_PARAMS]
        rec[TRANSLATION] = t
        rec[ROTATION] = q
        rec[SCALE] = s
        self._ints.append((int(kind), int(left), int(right)))
        self._reals.append(rec)
        self._ball_c.append(np.asarray(c, dtype=np.float64))
        self._ball_r.append(float(r))
        self._cert.append(bool(cert))
        self._lip.append(bool(lip))
        self._lipk.append(float(lipk))
        self._need.append(int(need))
        return len(self._ints) - 1

    # ------------------------------------------------------------------ queries
    def node_bound(self, root):
        """(centre (3,), radius, certified) of ``root``'s ball in its parent frame.

        The ball contains the solid. ``certified`` means Equation 1 holds,
        ``phi(p) >= |p - centre| - radius`` for every p, and phi is 1-Lipschitz
        (docs/architecture.md §4).
        A tree with a half-space on the left of its root has an infinite radius.
        """
        root = self._check_index(root, "root")
        return self._ball_c[root].copy(), self._ball_r[root], self._cert[root]

    def is_lipschitz(self, root) -> bool:
        """True if every leaf under ``root`` is 1-Lipschitz (so phi is)."""
        return self._lip[self._check_index(root, "root")]

    def lipschitz_constant(self, root) -> float:
        """A proven Lipschitz constant of ``root``'s field (dimensionless; conformal transforms
        keep it): 1.0 when every leaf is 1-Lipschitz, the largest leaf's where grid leaves
        (measured from their samples, :func:`~peclet.core.geom.sampled.grid_lipschitz`) are
        present, ``inf`` with a leaf that has none (ellipsoid, superquadric). The quadrature
        searches phi / L, which has phi's solid and is 1-Lipschitz."""
        return self._lipk[self._check_index(root, "root")]

    def node(self, index):
        """(kind, left, right, params (8,), translation, quaternion, scale) of a node; for a
        data row (kind DATA) the same slots of its row of samples."""
        index = self._check_index(index, "index", data_ok=True)
        rec = self._reals[index]
        kind, left, right = self._ints[index]
        return (kind, left, right, rec[PARAMS].copy(), rec[TRANSLATION].copy(),
                rec[ROTATION].copy(), rec[SCALE])

    def program(self, root) -> Program:
        """The flat evaluation program of ``root`` (cached; nodes are immutable)."""
        root = self._check_index(root, "root")
        prog = self._programs.get(root)
        if prog is None:
            ni, nr = self.node_arrays()
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
        o = check_array("origin", origin, (3,))
        sp = check_array("spacing", spacing, (3,))
        if not np.all(sp > 0.0):
            raise PecletArgumentError("spacing", "3 finite numbers > 0", spacing)
        d = check_array("dims", dims, (3,))
        if not all(v.is_integer() and v >= 1 for v in d.tolist()) \
                or math.prod(d.tolist()) > MAX_BAKE_POINTS:
            raise PecletArgumentError("dims", f"3 integers >= 1 with a product <= "
                                      f"{MAX_BAKE_POINTS} (1024^3)", dims)
        d = d.astype(np.int64)
        if band is None:
            band = -1.0
        else:
            band = check_float("band", band, 0.0)
            if not self.is_lipschitz(root):
                raise PecletArgumentError("band", "None for a root that is not 1-Lipschitz "
                                          "(a leaf neither distance-exact nor a Lipschitz "
                                          "bound): bake without band", band)
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
        rec[INST_TRANSLATION], rec[INST_ROTATION], rec[INST_SCALE] = as_transform(
            translation, rotation, scale)
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
        from .scene import Scene, as_box, as_periodic
        box = as_box(box)
        periodic = as_periodic(periodic)
        check_choice("method", method, ("pruned", "brute"))
        key = (None if box is None else (tuple(box[0].tolist()), tuple(box[1].tolist())),
               periodic)
        if self._scene_cache is None or self._scene_cache[0] != key:
            self._scene_cache = (key, Scene.from_builder(self, box=box, periodic=periodic))
        return self._scene_cache[1].evaluate(points, method=method)

    # ------------------------------------------------------------------ encoding
    def node_arrays(self):
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
        ni, nr = self.node_arrays()
        ii = np.zeros((len(self._inst_roots), INST_INT_COLS), dtype=np.int32)
        ii[:, INST_ROOT] = self._inst_roots
        ir = np.array(self._inst_reals, dtype=np.float64).reshape(-1, INST_REAL_COLS)
        return ni, nr, ii, ir

    @classmethod
    def decode(cls, node_ints, node_reals, inst_ints=None, inst_reals=None) -> "SceneBuilder":
        """Rebuild a builder from :meth:`encode`'s arrays, validating every node.

        Children must precede their parents (as :meth:`encode` writes them). Leaf parameter
        slots beyond a kind's count are ignored. float32 input is accepted and widened.
        """
        ni = _index_table("node_ints", node_ints, NODE_INT_COLS)
        nr = check_array("node_reals", node_reals, (len(ni), NODE_REAL_COLS))
        b = cls()
        for i, (kind, left, right) in enumerate(ni.tolist()):
            try:
                if kind == DATA:
                    if left != -1 or right != -1:
                        raise PecletArgumentError("left", "-1 (and right -1) for a data row",
                                                  (left, right))
                    b._append_data(nr[i])
                elif kind in OPERATOR_NAMES:
                    for nm, c in (("left", left), ("right", right)):
                        if not 0 <= c < i:
                            raise PecletArgumentError(nm, f"a child index in [0, {i}) (children "
                                                      "precede their parents)", c)
                    b._append(kind, left, right, np.zeros(MAX_PARAMS), *node_transform(nr[i]))
                else:
                    if left != -1 or right != -1:
                        raise PecletArgumentError("left", "-1 (and right -1) for a leaf",
                                                  (left, right))
                    # slots beyond the kind's count are padding (an unknown kind fails on kind)
                    n = LEAVES_BY_KIND[kind].n_params if kind in LEAVES_BY_KIND else MAX_PARAMS
                    spec, prm = leaf_params(kind, nr[i, :n])
                    b._append(spec.kind, -1, -1, prm, *node_transform(nr[i]))
            except PecletArgumentError as e:
                table = "node_ints" if e.argument in ("kind", "left", "right") else "node_reals"
                row = (ni if table == "node_ints" else nr)[i].tolist()
                raise PecletArgumentError(f"{table}[{i}]", "a valid node record", row,
                                          str(e)) from None
        if (inst_ints is None) != (inst_reals is None):
            raise PecletArgumentError("inst_reals" if inst_reals is None else "inst_ints",
                                      "given together with the other instance table (or both "
                                      "None)", None)
        if inst_ints is not None:
            ii = _index_table("inst_ints", inst_ints, INST_INT_COLS)
            ir = check_array("inst_reals", inst_reals, (len(ii), INST_REAL_COLS))
            for k in range(len(ii)):
                try:
                    b.add_instance(int(ii[k, INST_ROOT]), *instance_transform(ir[k]))
                except PecletArgumentError as e:
                    table, rows = ("inst_ints", ii) if e.argument == "root" else ("inst_reals", ir)
                    raise PecletArgumentError(f"{table}[{k}]", "a valid instance record",
                                              rows[k].tolist(), str(e)) from None
        return b


def _index_table(name, value, cols):
    """An integer table (n, cols) as int64; integral floats pass, anything else is an error."""
    arr = check_array(name, value, (None, cols))
    if not np.all(arr == np.round(arr)) or np.any(np.abs(arr) > 2 ** 31):
        raise PecletArgumentError(name, f"an array of shape (N, {cols}) of integers", value)
    return arr.astype(np.int64)


def decode(node_ints, node_reals, inst_ints=None, inst_reals=None) -> SceneBuilder:
    """Module-level alias of :meth:`SceneBuilder.decode`."""
    return SceneBuilder.decode(node_ints, node_reals, inst_ints, inst_reals)


def evaluate(node_ints, node_reals, root, points) -> np.ndarray:
    """phi of ``root`` of a flat encoding at ``points`` — the backend protocol's reference."""
    return SceneBuilder.decode(node_ints, node_reals).eval_root(root, points)
