"""The page's Results table (Step 7 and the text) beside a run's numbers:
:func:`results_table` of :func:`peclet.packing.page.pipeline.run`'s results, and :data:`PAGE`."""
from __future__ import annotations

__all__ = ["PAGE", "results_table"]

#: The reference page's Results (Step 7 table and the text), for the side-by-side table.
PAGE = dict(cert_violating=0.0, sign_exact_violating=0.2468, sign_exact_worst=0.7071,
            volume_fraction=0.3413, area=6.5607, specific_surface=8.353,
            probe_spacing_median=0.0369, eps=0.800, eps_spread=0.0011, f_env=0.582,
            z_mean=3.75, rattlers=0, cos_mean=0.526, cos_sem=0.042, ke_ratio=4.7e-4,
            max_overlap=0.027, max_overlap_wall=0.23, double=0.000092,
            eps_thin=0.957, eps_thick=0.743, runtime_s=346.0)


def results_table(res):
    """The page's Results table with our numbers beside the page's, as text."""
    c, p, k, s = res["certificate"], res["particle"], res["pack"], res["pour"]
    sw = {round(r["t_over_d"], 4): r for r in res["sweep"]}
    thin, thick = sw.get(0.024), sw.get(0.16)
    P = PAGE
    rows = [
        ("certified tree: exterior probes violating Eq. 1",
         f"{100 * c['certified']['violating']:.2f}% (min slack {c['certified']['min_slack']:+.1e})",
         "0.00% (min slack +1.9e-12)"),
        ("sign-exact tree, same solid: violations",
         f"{100 * c['sign_exact']['violating']:.2f}% (worst ratio "
         f"{c['sign_exact']['worst_ratio']:.4f})", "24.68% (worst ratio 0.7071)"),
        ("ring solid volume / envelope cylinder",
         f"{p['volume_fraction']:.6f} (V = {p['volume']:.8f} +- {p['volume_error']:.1e})",
         "0.3413 (V = 0.268032)"),
        ("surface area, specific surface",
         f"{p['surface_area']:.3f} D^2, {p['specific_surface']:.2f} /D (mc {p['mesh_n']}^3)",
         "6.561 D^2, 8.35 /D"),
        ("probe spacing (median) vs feature/3",
         f"{p['probe_spacing_median']:.4f} vs {p['min_feature'] / 3:.4f} "
         f"({p['shell_points']} probes)", "0.0369 vs 0.0400"),
        ("bed voidage eps",
         f"{k['eps']:.3f} +- {k['eps_se']:.3f} (MC); {k['eps_spread']:.4f} over 3 windows",
         "0.800 (0.0011 over three bulk windows)"),
        ("envelope packing fraction f_env", f"{k['f_env']:.3f} +- {k['f_env_se']:.3f}",
         "0.582"),
        ("mean coordination number (with the floor)",
         f"{k['z_mean']:.2f} ({k['z_elem']:.2f} ring-ring), {k['rattlers']} rattlers "
         f"(engine contacts, gap < {k['contact_gap']:g} D)",
         "3.75, 0 rattlers (probe strictly inside, in an engine overlapping 23% of the wall)"),
        ("ring-axis |cos theta|",
         f"{k['cos_mean']:.3f} +- {k['cos_sem']:.3f} (isotropic 0.500 +- {k['cos_sem_iso']:.3f})",
         "0.526 +- 0.042 (isotropic 0.500)"),
        ("residual kinetic energy after the quench",
         f"{s['ke_ratio']:.1e} of a one-diameter bed lift", "4.7e-04 of a one-diameter bed lift"),
        ("max contact overlap (probe depth); doubly-covered",
         f"{k['max_overlap']:.4f} = {100 * k['max_overlap_wall']:.0f}% of the wall; "
         f"{100 * k['double']:.4f}%", "0.027 = 23% of the wall; 0.0092%"),
        ("  engine's compute_overlaps()", f"{s['max_overlap_engine']:.4f} = "
         f"{100 * k['max_overlap_engine_wall']:.0f}% of the wall", "-"),
        ("lowest probe (floor y = 0); all in box",
         f"{k['lowest_probe']:+.4f}; {k['all_in_box']}", "-"),
        ("eps predicted at t/D = 0.024 / 0.16",
         (f"{thin['eps']:.3f} / {thick['eps']:.3f} (s by quadrature, err "
          f"{max(thin['s_err'], thick['s_err']):.1e})") if thin and thick else "n/a",
         "0.957 / 0.743 vs published 0.90-0.95 / 0.74-0.78"),
        ("pour", f"{s['steps']} steps in {s['seconds']:.1f} s ({s['ms_per_step']:.2f} ms/step "
                 f"after the first step, which took {s['first_step_seconds']:.1f} s)",
         "3700 steps in 299 s (81 ms/step)"),
        ("total runtime", f"{res['timing']['total']:.1f} s", f"{P['runtime_s']:.0f} s"),
    ]
    fl = res.get("flow")
    if fl is not None:
        rows[-1:-1] = [
            (f"permeability k (lattice Boltzmann, D/{fl['resolution']:g})",
             f"{fl['k_D2']:.4g} D^2 (eps {fl['eps']:.3f} on the lattice, Re {fl['Re']:.2g}, "
             f"{fl['steps']} steps)", "-"),
            ("dP/L / Ergun viscous term (Sauter d; envelope d)",
             f"{fl['ergun_ratio_sauter']:.3f}; {fl['ergun_ratio_envelope']:.3f} (Kozeny "
             f"constant {fl['kozeny']:.2f})", "-")]
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows)
    lines = [f"{'claim':<{w0}}  {'peclet (this run)':<{w1}}  the page",
             "-" * (w0 + w1 + 40)]
    lines += [f"{a:<{w0}}  {b_:<{w1}}  {c_}" for a, b_, c_ in rows]
    return "\n".join(lines)
