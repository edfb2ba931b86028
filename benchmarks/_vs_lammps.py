"""Helpers of ``bench_vs_lammps.py``: the column's one parameter set (:class:`Column`), its
LAMMPS parameters in SI units (:func:`lammps_params`, the unit mapping), the peclet run (a child
process of its own: :func:`run_peclet`, ``python _vs_lammps.py peclet PARAMS OUT``) and the one
analysis both engines' final centres go through (:func:`analyse`).

Units. peclet: lengths in sphere diameters D (d = 1), gravity 9.81 D/T^2, so its time unit is
T = sqrt(d / 1 m) s when d is given in metres. LAMMPS (``units si``): d = ``d_si`` m (1 mm by
default), g = 9.81 m/s^2, glass density ``rho`` 2500 kg/m^3, E = ``youngs`` (1e7 Pa), nu 0.3. So
a length L D is L d_si m, a time t T is t sqrt(d_si) s, a speed v D/T is v sqrt(d_si) m/s, and
an energy per sphere in m g d is that times rho (pi / 6) d_si^3 g d_si J.
"""
from __future__ import annotations

import json
import math
import os
import resource
import sys
import time
from dataclasses import dataclass

import numpy as np

__all__ = ["Column", "insertion", "lammps_params", "run_peclet", "from_lammps", "analyse",
           "benyahia_oneill"]

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

G = 9.81                 # D / T^2 (peclet) and m / s^2 (LAMMPS)
V_SPHERE = math.pi / 6.0  # D^3
#: fix pour's insertion region: height (D), the largest volume fraction asked of it (random
#: sequential insertion fails well below jamming), clearance to the wall (D), attempts
INSERT_HEIGHT, VOLFRAC_MAX, INSERT_CLEAR, INSERT_ATTEMPTS = 4.0, 0.2, 0.02, 200
#: LAMMPS's check interval for the settle criterion (T) and its neighbour skin (d)
CHECK_TIME, SKIN = 0.02, 0.2


def benyahia_oneill(n):
    """Benyahia & O'Neill (2005): mean voidage of equal spheres in a tube of N = D_t / d."""
    return 0.390 + 1.740 / (n + 1.140) ** 2


@dataclass(frozen=True)
class Column:
    """One poured column, the parameters of both engines: N = D_t / d, ``count`` spheres,
    friction ``mu`` (spheres and wall), normal restitution ``e``, the seed; LAMMPS's physical
    scale (``d_si`` m, ``rho`` kg/m^3, ``youngs`` Pa, ``poisson``), mindlin's ``xgammat`` and
    its time step rule: dt = the shortest Hertz contact time at the fastest impact /
    ``steps_per_contact``."""

    n: float = 16.0
    count: int = 4600
    mu: float = 0.3
    e: float = 0.3
    seed: int = 1
    d_si: float = 1e-3
    rho: float = 2500.0
    youngs: float = 1e7
    poisson: float = 0.3
    xgammat: float = 1.0
    steps_per_contact: float = 20.0

    def rain(self):
        """peclet's deposition: the rain protocol at its defaults (issue 42's command line)."""
        from peclet.packing import RainProtocol
        return RainProtocol()

    def material(self):
        from peclet.packing import Material
        return Material(e_n=self.e, e_t=0.0, mu=self.mu)


def hertz_time(m_eff, r_eff, e_star, v):
    """Hertz's elastic contact duration (s) of an impact at ``v`` m/s (Johnson 1985)."""
    return 2.868 * (m_eff * m_eff / (r_eff * e_star * e_star * v)) ** 0.2


def insertion(col):
    """fix pour's insertion, in D and T, matched to peclet's rain (:meth:`Column.rain`): the
    same rate (``batch / (insert_every dt)`` spheres per T) into a region of
    :data:`INSERT_HEIGHT` that rises with the bed (its estimated growth speed ``u``, solid
    fraction from Benyahia & O'Neill), spheres moving down at the rain's ``speed``, the region's
    centre ``drop`` D above the bed's surface: peclet's rain. A narrow column cannot take the
    rate at that speed below :data:`VOLFRAC_MAX`; then the insertion speed ``vz`` is raised and
    the region lowered so that the impact speed sqrt(speed^2 + 2 g drop) is kept."""
    rain = col.rain()
    rate = rain.batch / (rain.insert_every * rain.dt)
    radius = 0.5 * col.n
    rc, h = radius - 0.5 - INSERT_CLEAR, INSERT_HEIGHT
    if rc <= 0.0:
        raise ValueError(f"n = {col.n}: a column narrower than one sphere and its clearance")
    u = rate * V_SPHERE / (math.pi * radius ** 2 * (1.0 - benyahia_oneill(col.n)))
    t_max = VOLFRAC_MAX * math.pi * rc * rc * h / (rate * V_SPHERE)
    vz = max(rain.speed, h / t_max - 0.5 * G * t_max - u)
    w = vz + u                                  # speed relative to the rising region
    t_fall = (math.sqrt(w * w + 2.0 * G * h) - w) / G   # through the region (fix pour's nfreq)
    v_imp = math.sqrt(rain.speed ** 2 + 2.0 * G * rain.drop)
    above = max((v_imp ** 2 - vz ** 2) / (2.0 * G), 0.5 * h + 1.0)
    return dict(rate=rate, rc=rc, height=h, u=u, vz=vz, t_fall=t_fall, centre_above=above,
                volfrac=rate * V_SPHERE * t_fall / (math.pi * rc * rc * h), impact=v_imp,
                t_rain=col.count / rate)


def lammps_params(col):
    """The LAMMPS child's parameter dict, SI units (see the module's unit mapping)."""
    rain, ins, d = col.rain(), insertion(col), col.d_si
    T, V = math.sqrt(d), math.sqrt(d)          # time and speed units (s, m/s)
    m = col.rho * V_SPHERE * d ** 3
    zlo = ins["centre_above"] - 0.5 * ins["height"]
    zhi = zlo + ins["height"]
    v_max = math.sqrt(ins["vz"] ** 2 + 2.0 * G * zhi) * V
    e_pair = col.youngs / (2.0 * (1.0 - col.poisson ** 2))
    t_c = min(hertz_time(0.5 * m, 0.25 * d, e_pair, v_max),
              hertz_time(m, 0.5 * d, 2.0 * e_pair, v_max))     # sphere-sphere, sphere-wall
    dt = t_c / col.steps_per_contact
    nfreq = int(ins["t_fall"] * T / dt + 0.5)
    nper = int(ins["volfrac"] * math.pi * ins["rc"] ** 2 * ins["height"] / V_SPHERE)
    check = max(1, int(round(CHECK_TIME * T / dt)))
    t_total = 1.5 * ins["t_rain"] + math.sqrt(2.0 * zhi / G) + rain.settle_steps * rain.dt
    return dict(
        d=d, rho=col.rho, youngs=col.youngs, poisson=col.poisson, e=col.e, mu=col.mu,
        wall_mu=col.mu, xgammat=col.xgammat, g=G, radius=0.5 * col.n * d, count=col.count,
        seed=col.seed + 1000, dt=dt, skin=SKIN * d,
        insert=dict(rc=ins["rc"] * d, zlo=zlo * d, zhi=zhi * d, vz=-ins["vz"] * V,
                    rate=ins["u"] * V, volfrac=ins["volfrac"], attempts=INSERT_ATTEMPTS),
        box_top=(zhi + 1.5 * ins["u"] * ins["t_rain"] + 2.0) * d,
        check_every=check, calm_checks=int(math.ceil(rain.calm_steps * rain.dt / CHECK_TIME)),
        ke_tol=rain.ke_tol * m * G * d, max_steps=check * int(math.ceil(t_total * T / dt / check)),
        # for the report: the insertion as LAMMPS runs it, in D and T
        report=dict(ins, rate_lammps=nper / (nfreq * dt / T), nper=nper, nfreq=nfreq,
                    contact_time_s=t_c, v_max_si=v_max, time_unit_s=T))


# ---------------------------------------------------------------------------- peclet
def peak_rss_kb():
    """This process's peak resident set (kB): VmHWM of /proc/self/status (ru_maxrss, the
    fallback off Linux, keeps the forking parent's peak across exec)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def run_peclet(col, threads, out):
    """Pour ``col`` with ``peclet.packing.pack`` at ``threads`` Numba threads (after a short
    warm-up pour that loads the compiled kernels); writes OUT.npz (``x``: final centres, D) and
    OUT.json (steps, dt, seconds to the settled bed, sphere-steps, peak RSS)."""
    from peclet.packing import pack
    rain = col.rain()
    kw = dict(protocol=rain, material=col.material(), seed=col.seed, threads=threads,
              progress=False)
    pack("sphere", f"column:{col.n:g}", count=20, max_steps=40, **kw)       # warm-up
    rss0 = peak_rss_kb()
    res = pack("sphere", f"column:{col.n:g}", count=col.count, **kw)
    rss = peak_rss_kb()
    n = res.pack.n
    # sphere-steps from the rain's schedule (a batch every insert_every steps until all are in)
    per = rain.insert_every / rain.batch
    rain_steps = min(res.steps, per * n)
    sphere_steps = n * res.steps - 0.5 * n * rain_steps
    m_g_d = res.element.mass * G * res.container.d
    np.savez(out + ".npz", x=np.asarray(res.pack.positions))
    with open(out + ".json", "w") as f:
        json.dump(dict(threads=threads, steps=res.steps, dt=rain.dt, wall_s=res.seconds,
                       first_step_s=res.first_step_seconds, sphere_steps=sphere_steps,
                       count=int(n), settled=bool(res.complete and res.landed),
                       ke_per_sphere_end=float(res.ke[-1]) / (n * m_g_d),
                       peak_rss_kb=rss, rss_before_kb=rss0), f, indent=1)


# ---------------------------------------------------------------------------- analysis
def from_lammps(x_si, col):
    """LAMMPS's centres (m; z up, column axis x = y = 0, floor z = 0) in peclet's frame (D; y
    up, the column container's axis and floor)."""
    cont = _container(col)
    x = np.asarray(x_si, float) / col.d_si
    return np.column_stack([x[:, 0] + cont.center_xz[0], x[:, 2] + cont.floor_y,
                            x[:, 1] + cont.center_xz[1]])


def _container(col):
    from peclet.packing.bed.containers import parse_container
    return parse_container(f"column:{col.n:g}").bound(1.0)


def analyse(positions, col, samples=100_000, shell_samples=3000):
    """The one analysis of a final bed (centres (N, 3) in D, peclet's frame): bulk voidage over
    the column's whole cross-section between floor + crop and top - crop (top: the highest
    centre; crop 2 D, less for a shallow bed: ``peclet.packing.output.report``'s rule), and
    the radial profile eps(z) in shells of 0.02 D from the wall over the same heights, with
    its features; both by exact point sampling on the spheres
    (``peclet.packing.analysis.profiles``, as ``peclet pack`` reports its beds)."""
    from peclet.packing.analysis import profiles
    from peclet.packing.bed.api import element_model, resolve_element
    from peclet.packing.bed.freeze import Pack
    from peclet.packing.output.report import CROP, radial_features
    m, cont = element_model(resolve_element("sphere")), _container(col)
    pos = np.asarray(positions, float)
    pk = Pack(pos, np.tile([0.0, 0.0, 0.0, 1.0], (len(pos), 1)), list(cont.period), m.volume,
              m.node_ints, m.node_reals, m.home_root, m.bounding_radius, m.shell, m.mass,
              m.inv_inertia, m.envelope_root, m.envelope_volume, m.axis_home)
    top = float(pos[:, 1].max())
    crop = min(CROP, (top - cont.floor_y) / 3.0)
    sec = profiles.ColumnSection(cont.radius, cont.center_xz)
    b = profiles.bulk(pk, sec, floor_y=cont.floor_y, top_y=top, crop=crop,
                      samples_per_window=samples)
    lo, hi = cont.floor_y + crop, top - crop
    prof = profiles.radial_profile(pk, cont.radius, cont.center_xz, lo, hi, shell_width=0.02,
                                   samples_per_shell=shell_samples)
    return dict(eps=b["eps"], eps_se=b["eps_se"], window=[lo, hi], crop=crop, top=top,
                count=len(pos), eps_benyahia=benyahia_oneill(col.n),
                radial=dict(z=prof["z"].tolist(), eps=prof["eps"].tolist(),
                            features=radial_features(prof["z"], prof["eps"])))


def main(argv):
    if len(argv) != 4 or argv[1] != "peclet":
        sys.exit("usage: _vs_lammps.py peclet PARAMS.json OUT_PREFIX")
    with open(argv[2]) as f:
        p = json.load(f)
    threads = p.pop("threads")
    t0 = time.perf_counter()
    run_peclet(Column(**p), threads, argv[3])
    print(f"peclet, {threads} thread(s): {time.perf_counter() - t0:.1f} s", file=sys.stderr)


if __name__ == "__main__":
    main(sys.argv)

