"""LAMMPS side of ``bench_vs_lammps.py``: one poured column, run by LAMMPS's Python module in
its own venv (stdlib + numpy + lammps only; peclet is never imported here).

    LD_LIBRARY_PATH=<venv>/lib <venv>/bin/python lammps_column_child.py params.json OUT
    LD_LIBRARY_PATH=<venv>/lib <venv>/bin/mpirun -np 2 <venv>/bin/python ... (2 MPI ranks)

``params.json`` holds every number in SI units (m, s, kg, Pa, J), computed by the benchmark
(``_vs_lammps.lammps_params``; its docstring is the unit mapping). The run: ``units si``,
``atom_style sphere``, ``pair_style granular`` with ``hertz/material E e nu tangential mindlin
NULL xgammat mu damping coeff_restitution``, ``fix wall/gran granular`` (the same model, the
wall's modulus 2 E: LAMMPS builds a sphere-wall contact from the wall's coefficients alone, so
2 E is the rigid wall's E* = E / (1 - nu^2); examples/downstream/lammps_dem/README.md) as a
``zcylinder`` and a ``zplane`` floor, ``fix gravity``, ``fix nve/sphere``, and ``fix pour`` into
a ``region cylinder`` that moves up with the bed (its ``rate``). The processor grid is
``processors * * 1`` (the column is split across its axis, never along it: the bed sits at the
bottom). Settled: every sphere inserted and the kinetic energy (translational + rotational)
per sphere below ``ke_tol`` at ``calm_checks`` consecutive checks ``check_every`` steps apart.

Writes OUT.npz (``x``: final centres, m, any order) and OUT.json (steps, dt, wall seconds of
the stepping, sphere-steps, settled flag, version) from rank 0, and OUT.rank<r>.json (peak RSS
in kB) from every rank.
"""
import json
import sys
import time

import numpy as np

# the benchmark's stdlib + numpy helpers, beside this file (on sys.path as the script's folder)
from _vs_lammps import peak_rss_kb


def commands(p):
    """The LAMMPS input (set-up, no run) for the parameter dict ``p`` (SI units)."""
    r, d, ins = p["radius"], p["d"], p["insert"]
    model = ("hertz/material {E!r} {e!r} {nu!r} tangential mindlin NULL {xg!r} {mu!r} "
             "damping coeff_restitution")
    pair = model.format(E=p["youngs"], e=p["e"], nu=p["poisson"], xg=p["xgammat"], mu=p["mu"])
    wall = model.format(E=2.0 * p["youngs"], e=p["e"], nu=p["poisson"], xg=p["xgammat"],
                        mu=p["wall_mu"])
    b = r + d
    return "\n".join([
        "units si", "atom_style sphere", "atom_modify map array", "boundary f f f",
        "newton off", "comm_modify vel yes", "processors * * 1",
        f"region box block {-b!r} {b!r} {-b!r} {b!r} {-d!r} {p['box_top']!r} units box",
        "create_box 1 box",
        "pair_style granular", f"pair_coeff * * {pair}",
        f"neighbor {p['skin']!r} bin", "neigh_modify delay 0 every 1 check yes",
        f"fix wallc all wall/gran granular {wall} zcylinder {r!r}",
        f"fix wallf all wall/gran granular {wall} zplane 0.0 NULL",
        f"fix grav all gravity {p['g']!r} vector 0 0 -1",
        f"region ins cylinder z 0 0 {ins['rc']!r} {ins['zlo']!r} {ins['zhi']!r} units box",
        f"fix pour all pour {p['count']} 1 {p['seed']} region ins diam one {d!r} dens "
        f"{p['rho']!r} {p['rho']!r} vol {ins['volfrac']!r} {ins['attempts']} vel 0 0 0 0 "
        f"{ins['vz']!r} rate {ins['rate']!r}",
        "fix integrate all nve/sphere",
        f"timestep {p['dt']!r}", "thermo 0"])


def main(params_path, out):
    from lammps import lammps
    with open(params_path) as f:
        p = json.load(f)
    lmp = lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    rank = lmp.extract_setting("world_rank")
    ranks = lmp.extract_setting("world_size")
    lmp.commands_string(commands(p))

    def gather(name, cols):
        n = lmp.get_natoms()
        return np.array(lmp.gather_atoms_concat(name, 1, cols), dtype=float).reshape(n, cols)

    def ke():
        """Translational + rotational kinetic energy of all spheres (J; solid spheres)."""
        m, r = gather("rmass", 1)[:, 0], gather("radius", 1)[:, 0]
        v, w = gather("v", 3), gather("omega", 3)
        return float(0.5 * (m * (v * v).sum(1)).sum() + 0.2 * (m * r * r * (w * w).sum(1)).sum())

    k, steps, sphere_steps, calm, settled, first = p["check_every"], 0, 0.0, 0, False, True
    n0 = 0
    t0 = time.perf_counter()
    while steps < p["max_steps"]:
        lmp.command(f"run {k}" + ("" if first else " pre no post no"))
        first = False
        steps += k
        n = lmp.get_natoms()
        sphere_steps += 0.5 * (n0 + n) * k       # the chunk's mean count (exact once poured)
        n0 = n
        if n < p["count"]:
            continue
        calm = calm + 1 if ke() / n < p["ke_tol"] else 0
        if calm >= p["calm_checks"]:
            settled = True
            break
    wall = time.perf_counter() - t0
    n = lmp.get_natoms()
    x = gather("x", 3)
    ke_end = ke() / max(n, 1)
    if rank == 0:
        np.savez(out + ".npz", x=x)
        with open(out + ".json", "w") as f:
            json.dump(dict(version=lmp.version(), ranks=ranks, steps=steps, dt=p["dt"],
                           sim_time=steps * p["dt"], wall_s=wall, sphere_steps=sphere_steps,
                           count=n, settled=settled, ke_per_sphere_end=ke_end), f, indent=1)
    with open(f"{out}.rank{rank}.json", "w") as f:
        json.dump(dict(rank=rank, peak_rss_kb=peak_rss_kb()), f)
    lmp.close()


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: lammps_column_child.py params.json OUT_PREFIX")
    main(sys.argv[1], sys.argv[2])
