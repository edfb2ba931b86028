"""Kratos DEM (KratosMultiphysics + KratosDEMApplication 10.4.4) as an impact engine, served
over peclet's family protocol (a child process run with the interpreter of a venv that has
``pip install KratosMultiphysics KratosDEMApplication``; it needs numpy and Kratos only).

    PECLET_VERIFY_DIR=... python kratos_child.py [hertz|linear]
    ... python kratos_child.py hertz --project DIR < case.json   (a Kratos DEM project)

``PECLET_VERIFY_DIR`` is the folder of peclet_verify, whose ``wire.py`` and ``impact/cases.py``
and ``impact/follow.py`` are loaded by file path (this interpreter has no peclet). Each impact
is a fresh Kratos DEM project written by this file into a temporary directory (the spheres'
and the wall's ``.mdpa``, ``MaterialsDEM.json``, ``ProjectParametersDEM.json``: nothing is
hand-written), run by Kratos's own ``DEMAnalysisStage`` one time step at a time (its
``AdvanceInTime``, ``InitializeSolutionStep``, ``SolveSolutionStep``,
``FinalizeSolutionStep``), with positions, ``TOTAL_FORCES``, ``VELOCITY`` and
``ANGULAR_VELOCITY`` read from the nodes after every step. ``--project DIR`` writes the same
project for one case, which a Kratos user runs without peclet (``cd DIR && python -m
KratosMultiphysics.DEMApplication.DEM_analysis_stage``; the velocities and angular velocities
after three contact times are in ``impact_Post_Files/impact.post.res``). Kratos prints to the C-level
standard output: the child moves that to standard error before importing Kratos and speaks
the protocol on a duplicate of the original descriptor.

The dialect, all of it here and none of it in the certificates (Kratos 10.4.4):

==============================  ===============================================================
impact case                     Kratos DEM project
==============================  ===============================================================
a ball                          a node and a ``SphericParticle3D`` element in
                                ``impactDEM.mdpa`` (``RADIUS``, ``VELOCITY_*``,
                                ``ANGULAR_VELOCITY_*`` as nodal data), its own sub model part
                                ``SpheresPart.ball<i>`` and material ``ball<i>``
                                (``PARTICLE_DENSITY``, ``YOUNG_MODULUS``, ``POISSON_RATIO``);
                                Kratos's mass 4/3 pi rho R^3 and moment 2/5 m R^2 (read back:
                                equal)
law ``hertz``                   ``DEM_D_Hertz_viscous_Coulomb`` in every material relation:
                                F_n = 4/3 E* sqrt(R*) delta^(3/2) (k_n = 2 E* sqrt(R* delta)),
                                E* and G* mixed by Kratos from each ball's E, nu
law ``linear``                  ``DEM_D_Linear_viscous_Coulomb``, which takes no stiffness: it
                                derives k_n = 1.432 pi 0.31225 E* R* between two balls and
                                k_n = pi 0.31225 E* R against a wall (measured on 10.4.4:
                                F_n / delta = those to 1e-12; the source's
                                ``DEM_D_Linear_viscous_Coulomb_CL.cpp`` says the same). Every
                                modulus of the case (balls and wall) is scaled by one factor s
                                so that Kratos's k_n is the case's ``kn``: s = kn / (c E* R*),
                                c the constant above. Ratios of moduli, and so k_t / k_n = 4 G*
                                / E*, are unchanged
restitution ``e``               ``COEFFICIENT_OF_RESTITUTION`` of the relation (Kratos turns it
                                into ``DAMPING_GAMMA``: Thornton's polynomial fit for Hertz,
                                a bisection on the clamped linear dashpot's e(gamma) for
                                linear; e > 0.999 gives gamma 0)
friction ``mu``                 ``STATIC_FRICTION`` = ``DYNAMIC_FRICTION`` = mu (so the
                                ``FRICTION_DECAY`` law is constant), rolling friction 0
the rigid plane x > 0           two ``RigidFace3D3N`` conditions (a DEM-FEM wall, square of
                                side 20 R in the plane x = 0) in
                                ``impactDEM_FEM_boundary.mdpa``, material ``wall`` of modulus
                                1e12 x the ball's and the ball's nu: E* = E / (1 - nu^2) to
                                1e-12 (Kratos mixes E* with the wall's E)
time step                       ``MaxTimeStep`` = the case's dt, ``NeighbourSearchFrequency``
                                1, Kratos's default ``Symplectic_Euler`` translational and
                                rotational (``Direct_Integration``) schemes, gravity 0
normal force of a step          -``TOTAL_FORCES_X`` of ball 0 (the only force on it is the
                                contact's)
==============================  ===============================================================
"""
import json
import math
import os
import sys
import tempfile

import numpy as np

if __name__ == "__main__":
    sys.path.insert(0, os.environ["PECLET_VERIFY_DIR"])
    # Kratos writes its banner and logs to the C-level stdout: keep fd 1 for the protocol
    PROTOCOL = os.fdopen(os.dup(1), "wb", buffering=0)
    os.dup2(2, 1)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
import wire  # noqa: E402  (by file location, from PECLET_VERIFY_DIR)
from impact.follow import follow_impact  # noqa: E402

#: Kratos's constitutive law of each law of the adapter
LAWS = {"hertz": "DEM_D_Hertz_viscous_Coulomb", "linear": "DEM_D_Linear_viscous_Coulomb"}
#: DEM_D_Linear_viscous_Coulomb's k_n / (E* R*): between two balls, against a wall
LINEAR_KN = {"pair": 1.432 * math.pi * 0.31225, "wall": math.pi * 0.31225}
#: the wall's modulus over the ball's: a rigid plane to 1e-12 (Kratos mixes the wall's modulus
#: into E*; README.md shows what a wall of the ball's own modulus does)
WALL_STIFFER = float(os.environ.get("PECLET_KRATOS_WALL_STIFFER", "1e12"))
#: the wall is a square of side 2 WALL_HALF x the ball's radius
WALL_HALF = 10.0
PROBLEM = "impact"


def _effective_modulus(balls):
    return 1.0 / sum((1.0 - b.poisson ** 2) / b.youngs for b in balls)


def _version():
    from importlib.metadata import version
    return version("KratosDEMApplication")


class KratosImpact:
    """Impacts in Kratos DEM with ``DEM_D_Hertz_viscous_Coulomb`` (``hertz``) or
    ``DEM_D_Linear_viscous_Coulomb`` (``linear``), in a fresh ``DEMAnalysisStage`` each."""

    capabilities = frozenset({"sphere_sphere", "sphere_wall", "unequal_spheres", "restitution",
                              "friction", "spin"})

    def __init__(self, law="hertz"):
        if law not in LAWS:
            raise ValueError(f"law must be one of {sorted(LAWS)}, got {law!r}")
        self.law = law
        self.name = f"Kratos DEM {_version()} ({LAWS[law]})"
        tangential = ("k_t = 4 G*/E* k_n, incremental (history scaled by sqrt(delta/delta_prev) "
                      "on unloading), tangential dashpot of the same gamma, Coulomb limit "
                      "mu x the clamped normal force")
        self.model = ({"normal": "hertz", "damping": "viscous 2 gamma sqrt(m* k_n), k_n = "
                       "2 E* sqrt(R* delta) (Tsuji form), gamma from Thornton's fit of e, "
                       "normal force clamped at 0",
                       "tension": False, "coulomb": "compressive", "tangential": tangential}
                      if law == "hertz" else
                      {"normal": "hooke", "damping": "viscous 2 gamma sqrt(m* k_n), gamma from "
                       "the clamped dashpot's e(gamma), normal force clamped at 0",
                       "tension": False, "coulomb": "compressive", "tangential": tangential})

    # ------------------------------------------------------------------ the project files
    def _scale(self, case):
        """The factor on every modulus (1 for Hertz; for linear, the one that makes Kratos's
        k_n the case's kn)."""
        if self.law == "hertz":
            return 1.0
        if case.wall:
            b = case.balls[0]
            return case.kn / (LINEAR_KN["wall"] * b.youngs / (1.0 - b.poisson ** 2) * b.radius)
        b1, b2 = case.balls[:2]
        r = b1.radius * b2.radius / (b1.radius + b2.radius)
        return case.kn / (LINEAR_KN["pair"] * _effective_modulus(case.balls[:2]) * r)

    def _balls_mdpa(self, case):
        n = len(case.balls)
        lines = ["Begin ModelPartData", "End ModelPartData", "", "Begin Properties 0",
                 "End Properties", "", "Begin Nodes"]
        lines += [f"  {i} {b.x[0]!r} {b.x[1]!r} {b.x[2]!r}" for i, b in enumerate(case.balls, 1)]
        lines += ["End Nodes", "", "Begin Elements SphericParticle3D"]
        lines += [f"  {i} 0 {i}" for i in range(1, n + 1)]
        lines += ["End Elements", ""]

        def nodal(variable, values):
            return ([f"Begin NodalData {variable}"]
                    + [f"  {i} 0 {v!r}" for i, v in enumerate(values, 1)] + ["End NodalData", ""])

        lines += nodal("RADIUS", [b.radius for b in case.balls])
        for k, axis in enumerate("XYZ"):
            lines += nodal(f"VELOCITY_{axis}", [b.v[k] for b in case.balls])
            lines += nodal(f"ANGULAR_VELOCITY_{axis}", [b.w[k] for b in case.balls])
        for i in range(1, n + 1):
            lines += [f"Begin SubModelPart ball{i}", "  Begin SubModelPartNodes", f"    {i}",
                      "  End SubModelPartNodes", "  Begin SubModelPartElements", f"    {i}",
                      "  End SubModelPartElements", "End SubModelPart", ""]
        return "\n".join(lines)

    def _wall_mdpa(self, case):
        h = WALL_HALF * case.balls[0].radius
        corners = [(-h, -h), (h, -h), (h, h), (-h, h)]         # (y, z) in the plane x = 0
        first = len(case.balls) + 1
        ids = list(range(first, first + 4))
        lines = ["Begin ModelPartData", "End ModelPartData", "", "Begin Properties 0",
                 "End Properties", "", "Begin Nodes"]
        lines += [f"  {i} 0.0 {y!r} {z!r}" for i, (y, z) in zip(ids, corners)]
        lines += ["End Nodes", "", "Begin Conditions RigidFace3D3N",
                  f"  1 0 {ids[0]} {ids[1]} {ids[2]}", f"  2 0 {ids[0]} {ids[2]} {ids[3]}",
                  "End Conditions", "", "Begin SubModelPart wall", "  Begin SubModelPartData",
                  "    RIGID_BODY_MOTION 0", "    FIXED_MESH_OPTION 0", "    FREE_BODY_MOTION 0",
                  "    IS_GHOST 0", "    IDENTIFIER wall", "  End SubModelPartData",
                  "  Begin SubModelPartNodes"] + [f"    {i}" for i in ids] + [
                  "  End SubModelPartNodes", "  Begin SubModelPartConditions", "    1", "    2",
                  "  End SubModelPartConditions", "End SubModelPart", ""]
        return "\n".join(lines)

    def _materials(self, case):
        s = self._scale(case)
        mats = [{"material_name": f"ball{i}", "material_id": i,
                 "Variables": {"PARTICLE_DENSITY": b.density, "YOUNG_MODULUS": s * b.youngs,
                               "POISSON_RATIO": b.poisson}}
                for i, b in enumerate(case.balls, 1)]
        table = [[f"SpheresPart.ball{i}", f"ball{i}"] for i in range(1, len(case.balls) + 1)]
        if case.wall:
            b = case.balls[0]
            mats.append({"material_name": "wall", "material_id": len(case.balls) + 1,
                         "Variables": {"YOUNG_MODULUS": WALL_STIFFER * s * b.youngs,
                                       "POISSON_RATIO": b.poisson, "COMPUTE_WEAR": False}})
            table.append(["RigidFacePart.wall", "wall"])
        contact = {"COEFFICIENT_OF_RESTITUTION": case.e, "STATIC_FRICTION": case.mu,
                   "DYNAMIC_FRICTION": case.mu, "FRICTION_DECAY": 500.0,
                   "ROLLING_FRICTION": 0.0, "ROLLING_FRICTION_WITH_WALLS": 0.0,
                   "DEM_ROLLING_FRICTION_MODEL_NAME": "DEMRollingFrictionModelBounded",
                   "DEM_DISCONTINUUM_CONSTITUTIVE_LAW_NAME": LAWS[self.law]}
        relations = [{"material_names_list": [a["material_name"], b["material_name"]],
                      "material_ids_list": [a["material_id"], b["material_id"]],
                      "Variables": dict(contact)}
                     for k, a in enumerate(mats) for b in mats[k:]
                     if a["material_name"] != "wall" or b["material_name"] != "wall"]
        return {"materials": mats, "material_relations": relations,
                "material_assignation_table": table}

    def _max_steps(self, case):
        m = case.balls[0].mass
        return int(50 * math.pi * math.sqrt(m / case.kn) / case.dt) + 100

    def _parameters(self, case, printing=False):
        """ProjectParametersDEM.json. ``printing``: Kratos writes GiD results (velocity and
        angular velocity) at the start and at FinalTime, three linear contact times (a
        project for a person); without it nothing is written (the adapter reads the
        nodes)."""
        final = 3.0 * math.pi * math.sqrt(case.balls[0].mass / case.kn)
        return {"problem_name": PROBLEM, "Dimension": 3, "GravityX": 0.0, "GravityY": 0.0,
                "GravityZ": 0.0, "RotationOption": True, "BoundingBoxOption": False,
                "dem_inlet_option": False, "do_print_results_option": printing,
                "post_gid_option": printing, "OutputTimeStep": final, "OutputFileType": "Ascii",
                "Multifile": "single_file",
                "PostVelocity": True, "PostAngularVelocity": True,
                "ElementType": "SphericPartDEMElement3D",
                "TranslationalIntegrationScheme": "Symplectic_Euler",
                "RotationalIntegrationScheme": "Direct_Integration",
                "MaxTimeStep": case.dt, "FinalTime": final,
                "NeighbourSearchFrequency": 1, "DeltaOption": "Absolute",
                "SearchTolerance": 0.0, "search_tolerance_against_walls": 0.0,
                "GlobalDamping": 0.0, "VirtualMassCoefficient": 1.0,
                "RollingFrictionOption": False, "CleanIndentationsOption": False,
                "solver_settings": {"strategy": "sphere_strategy",
                                    "RemoveBallsInitiallyTouchingWalls": False,
                                    "material_import_settings": {
                                        "materials_filename": "MaterialsDEM.json"}}}

    def project(self, case, printing=False):
        """The Kratos DEM project of ``case``: file name -> text."""
        files = {f"{PROBLEM}DEM.mdpa": self._balls_mdpa(case),
                 "MaterialsDEM.json": json.dumps(self._materials(case), indent=2),
                 "ProjectParametersDEM.json": json.dumps(self._parameters(case, printing),
                                                         indent=2)}
        if case.wall:
            files[f"{PROBLEM}DEM_FEM_boundary.mdpa"] = self._wall_mdpa(case)
        return files

    def write_project(self, case, folder, printing=False):
        os.makedirs(folder, exist_ok=True)
        for name, text in self.project(case, printing).items():
            with open(os.path.join(folder, name), "w") as f:
                f.write(text + "\n")

    # ------------------------------------------------------------------ the run
    def impact(self, case):
        import KratosMultiphysics as K
        from KratosMultiphysics.DEMApplication.DEM_analysis_stage import DEMAnalysisStage
        K.Logger.GetDefaultOutput().SetSeverity(K.Logger.Severity.WARNING)

        class Stage(DEMAnalysisStage):
            def __init__(self, model, parameters, folder):
                self.folder = folder
                super().__init__(model, parameters)

            def GetMainPath(self):
                return self.folder

        with tempfile.TemporaryDirectory(prefix="peclet_kratos_") as folder:
            self.write_project(case, folder)
            with open(os.path.join(folder, "ProjectParametersDEM.json")) as f:
                parameters = K.Parameters(f.read())
            stage = Stage(K.Model(), parameters, folder)
            stage.Initialize()
            try:
                nodes = [stage.spheres_model_part.GetNode(i)
                         for i in range(1, len(case.balls) + 1)]
                r0 = case.balls[0].radius

                def step():
                    stage.time = stage._GetSolver().AdvanceInTime(stage.time)
                    stage.InitializeSolutionStep()
                    stage.SolveSolutionStep()
                    stage.FinalizeSolutionStep()

                def overlap():
                    if case.wall:
                        return nodes[0].X + r0
                    a, b = nodes[0], nodes[1]
                    gap = math.sqrt((b.X - a.X) ** 2 + (b.Y - a.Y) ** 2 + (b.Z - a.Z) ** 2)
                    return r0 + case.balls[1].radius - gap

                def normal_force():
                    return max(0.0, -nodes[0].GetSolutionStepValue(K.TOTAL_FORCES_X))

                dmax, fmax, t = follow_impact(step, overlap, normal_force, case.dt,
                                              self._max_steps(case))
                v = np.array([list(n.GetSolutionStepValue(K.VELOCITY)) for n in nodes], float)
                w = np.array([list(n.GetSolutionStepValue(K.ANGULAR_VELOCITY)) for n in nodes],
                             float)
            finally:
                stage.Finalize()
        return {"v": v, "w": w, "delta_max": dmax, "f_max": fmax,
                "contact_time": math.nan if t is None else t}


if __name__ == "__main__":
    if len(sys.argv) > 3 and sys.argv[2] == "--project":  # law --project DIR < case JSON
        from impact.cases import Impact
        KratosImpact(sys.argv[1]).write_project(Impact.from_json(sys.stdin.read()), sys.argv[3],
                                                printing=True)
    else:
        wire.serve(impact=KratosImpact(sys.argv[1] if len(sys.argv) > 1 else "hertz"),
                   stdout=PROTOCOL)
