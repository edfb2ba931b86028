"""The facade's walls, per-pair materials and external loads (a part of
:class:`peclet.dem.Simulation`, kept apart for size): thin validated setters and copying getters
over ``self.world`` (:mod:`peclet.dem.world`)."""
from __future__ import annotations

import numpy as np

from peclet.core.validation import PecletArgumentError, check_array, check_int
from peclet.dem.materials import MAX_MATERIAL_ID


class WallsAndLoads:
    """Moving walls, material ids and pairs, external forces and torques of a Simulation."""

    # ------------------------------------------------------------------ moving walls
    def set_wall_transform(self, wall, translation=(0.0, 0.0, 0.0),
                           quaternion=(0.0, 0.0, 0.0, 1.0)):
        """Pose of ``wall`` (an index from :meth:`add_analytic_wall`): the wall's tree, authored
        in the world frame, is placed at ``p = R(quaternion) p_tree + translation``.
        ``translation``: 3 finite numbers; ``quaternion`` (x, y, z, w): unit to within 1e-6.
        Contacts at the next step see the wall there (see :mod:`peclet.dem.wallmotion`)."""
        self.world.wall_motion.set_transform(wall, translation, quaternion)

    def set_wall_velocity(self, wall, linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, 0.0),
                          center=(0.0, 0.0, 0.0)):
        """Rigid velocity of ``wall``: ``linear`` (length/time) and ``angular`` (rad/time,
        world frame) about the world point ``center``, each 3 finite numbers. The surface
        velocity at p is ``linear + angular x (p - center)``: contacts take it as the wall's
        velocity (friction drags, restitution is relative to the moving surface), and each step
        advances the wall's pose by it (a later :meth:`set_wall_transform` overrides that)."""
        self.world.wall_motion.set_velocity(wall, linear, angular, center)

    def get_wall_transform(self, wall):
        """(translation (3,), quaternion (4,) x y z w) of ``wall``, copies."""
        i = self.world.wall_motion.index(wall)
        return self.world.wall_motion.pos[i].copy(), self.world.wall_motion.quat[i].copy()

    def get_wall_velocity(self, wall):
        """(linear (3,), angular (3,), center (3,)) of ``wall``, copies."""
        i = self.world.wall_motion.index(wall)
        m = self.world.wall_motion
        return m.vel[i].copy(), m.omega[i].copy(), m.center[i].copy()

    # ------------------------------------------------------------------ materials per pair
    def set_material_ids(self, ids):
        """Material id per body (N,), integers in [0, 1023] (default 0 for every body). A
        contact of bodies with ids (i, j) uses the pair declared by :meth:`set_pair_material`;
        (0, 0) defaults to :meth:`set_material_params`. When N changes later, the first
        min(N_old, N) bodies keep their ids and new ones get 0."""
        n = self.world.bodies.n
        raw = check_array("ids", ids, (n,))            # numbers, finite, one per body
        if not np.all(raw == np.floor(raw)):
            raise PecletArgumentError("ids", f"integers in [0, {MAX_MATERIAL_ID}]", ids,
                                      "a non-integer entry")
        ids = raw.astype(np.int64)
        if n and (ids.min() < 0 or ids.max() > MAX_MATERIAL_ID):
            raise PecletArgumentError("ids", f"integers in [0, {MAX_MATERIAL_ID}]",
                                      (int(ids.min()), int(ids.max())))
        self.world.materials.body_ids = ids.copy()

    def get_material_ids(self):
        """(N,) material id per body."""
        self.world.sync_material_ids()
        ids = self.world.materials.body_ids
        return np.zeros(self.world.bodies.n, np.int64) if ids is None else ids.copy()

    def set_pair_material(self, a, b, e_n, e_t, mu):
        """Material of contacts between material ids ``a`` and ``b`` (either order; ids in
        [0, 1023]): normal restitution ``e_n`` in [0, 1], tangential restitution ``e_t`` in
        [-1, 1], friction ``mu`` >= 0. A wall with a material id (:meth:`set_wall_material_id`)
        takes the pair (body id, wall id)."""
        self.world.materials.set_pair(a, b, e_n, e_t, mu)

    def set_wall_material_id(self, wall, material_id):
        """Give ``wall`` the material id ``material_id`` in [0, 1023] (-1: back to the wall's own
        restitution and friction from :meth:`add_analytic_wall`)."""
        i = self.world.wall_motion.index(wall)
        self.world.materials.wall_ids[i] = check_int("material_id", material_id, -1,
                                                MAX_MATERIAL_ID)


    # ------------------------------------------------------------------ external loads
    def set_external_forces(self, forces):
        """Force (N, 3) on each body's centre of mass (world frame, mass length / time^2),
        applied at every step until changed or cleared; finite numbers."""
        self.world.ext_force = check_array("forces", forces, (self.world.bodies.n, 3)).copy()

    def set_external_torques(self, torques):
        """Torque (N, 3) on each body (world frame), applied at every step until changed or
        cleared; finite numbers."""
        self.world.ext_torque = check_array("torques", torques, (self.world.bodies.n, 3)).copy()

    def clear_external_forces(self):
        self.world.ext_force = None

    def clear_external_torques(self):
        self.world.ext_torque = None

    def get_external_forces(self):
        """(N, 3) external forces (zeros when none are set)."""
        f = self.world.ext_force
        return np.zeros((self.world.bodies.n, 3)) if f is None else f.copy()

    def get_external_torques(self):
        """(N, 3) external torques (zeros when none are set)."""
        t = self.world.ext_torque
        return np.zeros((self.world.bodies.n, 3)) if t is None else t.copy()
