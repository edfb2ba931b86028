"""What ``peclet pack`` (and the column benchmark) make of a :class:`~peclet.packing.bed.api.
PackResult`: the bed's analysis (bulk voidage and f_env with standard errors over axial
windows, the radial profile of a column and its features, the axial profile, orientation,
coordination with wall contacts), figures and exports, ``results.json`` and a results table.

The measuring itself is :mod:`peclet.packing.analysis.profiles`, the files :mod:`peclet.packing.output.export`
and :mod:`peclet.packing.output.bed_figures`; this module only says which are computed for which
container, with which cuts. Lengths in element diameters D unless said otherwise.
"""
from __future__ import annotations

import math
import os
import time

import numpy as np

from peclet.core.files import write_json

__all__ = ["analyse", "radial_features", "write_results", "table", "CROP", "CONTACT_GAP"]

#: Floor and free-surface zones cropped from bulk and profile windows (D), reduced for a
#: shallow bed so that at least a third of its height remains.
CROP = 2.0

#: Contact gap for coordination (D), as the page's pipeline (pipeline.CONTACT_GAP): the
#: engine's gap between two elements (or an element and a wall) below it is a contact.
CONTACT_GAP = 1e-3

#: With the merged STL layout, beds up to this many elements get an ASCII STL with one named
#: solid per element and the container as its own solid (about 300 bytes a triangle: 60 MB
#: for 200 elements at the default 1000 triangles); larger ones one merged binary STL (50
#: bytes a triangle), the container then only in the VTU.
STL_PER_ELEMENT_MAX = 200

#: ``stl_layout`` values: one STL file, or a directory ``bed_stl/`` of one binary STL file
#: per element (and ``container.stl``).
STL_LAYOUTS = ("merged", "per-element")


def bed_floor(pack, cont):
    """The height the bed stands on: the container's floor, or for a tree container (a vessel
    whose internals, e.g. a support plate, hold the bed above its lowest point) the lowest
    element's bounding-sphere bottom."""
    if cont.kind != "tree":
        return cont.floor_y
    return float((pack.positions[:, 1] - pack.bounding_radius).min())


def _crop(pack, cont):
    top = float(pack.positions[:, 1].max())
    h = (top - bed_floor(pack, cont)) / cont.d
    return min(CROP, h / 3.0), top


def radial_features(z, eps):
    """Features of a radial voidage profile eps(z) (z from the wall in D): the wall value
    (first shell), the first minimum (z in [0.3, 0.8]), the maximum (z in [0.8, 1.25]) and the
    second minimum (z in [1.25, 1.75]), each as (z, eps); None where z does not reach."""
    z, eps = np.asarray(z, float), np.asarray(eps, float)

    def pick(lo, hi, fn):
        m = (z >= lo) & (z <= hi)
        if not m.any():
            return None
        k = np.flatnonzero(m)[fn(eps[m])]
        return (float(z[k]), float(eps[k]))
    return dict(wall=(float(z[0]), float(eps[0])), min1=pick(0.3, 0.8, np.argmin),
                max1=pick(0.8, 1.25, np.argmax), min2=pick(1.25, 1.75, np.argmin))


def analyse(res, out=None, figures=True, samples=100_000, shell_samples=3000, exports=True,
            spacing=0.04, stl_resolution=None, stl_layout="merged"):
    """The bed's analysis as a JSON-able dict; with ``out`` and ``figures``, also the PNG
    figures (radial profile of a column, axial profile, bed view; element meshes at the
    lattice step ``spacing``, in D) and with ``exports`` the STL (``stl_layout`` "merged": one
    solid per element and the container as its own solid, or merged above
    :data:`STL_PER_ELEMENT_MAX` elements; "per-element": the directory ``bed_stl/`` of one
    binary file per element and ``container.stl``), VTU (with the container) and transforms
    CSV, the element meshed at ``stl_resolution`` (default
    :data:`peclet.packing.output.export.DEFAULT_RESOLUTION`; see :func:`peclet.packing.output.export.
    export_mesh`), what the mesh came to in ``rep["export"]``. ``timing`` holds the seconds
    of each part."""
    from ..analysis import profiles

    pack, cont, d = res.pack, res.container, res.container.d
    crop, top = _crop(pack, cont)
    timing = {}
    t = time.perf_counter()
    if cont.kind == "column":
        section = profiles.ColumnSection(cont.radius, cont.center_xz)
    elif cont.kind == "box":
        section = profiles.periodic_section(pack)
    elif cont.kind == "tree":
        lo, hi = cont.fluid_box()
        section = profiles.FluidSection(profiles.BoxSection((lo[0], lo[2]), (hi[0], hi[2])),
                                        lambda p: cont.fluid_phi(p) < 0.0)
    else:
        section = profiles.BoxSection(*_box_section(cont))
    floor = bed_floor(pack, cont)
    rep = dict(container=cont.label(), element=res.element.name, count=int(pack.n),
               d_elem=d, crop=crop, bed_top=top)
    b = profiles.bulk(pack, section, floor_y=floor, top_y=top, d_elem=d, crop=crop,
                      samples_per_window=samples)
    rep["bulk"] = {k: b[k] for k in ("eps", "eps_se", "f_env", "f_env_se")}
    rep["bulk"]["eps_windows"] = np.asarray(b["eps_windows"]).tolist()
    timing["bulk"] = time.perf_counter() - t
    y_lo, y_hi = floor + crop * d, top - crop * d
    prof = None
    if cont.kind == "column":
        t = time.perf_counter()
        prof = profiles.radial_profile(pack, cont.radius, cont.center_xz, y_lo, y_hi,
                                       d_elem=d, shell_width=0.02,
                                       samples_per_shell=shell_samples)
        rep["radial"] = dict(z=prof["z"].tolist(), eps=prof["eps"].tolist(),
                             eps_se=prof["eps_se"].tolist(),
                             features=radial_features(prof["z"], prof["eps"]))
        if res.element.sphere:
            rep["benyahia_oneill"] = float(profiles.benyahia_oneill_voidage(cont.size[0]))
        timing["radial"] = time.perf_counter() - t
    t = time.perf_counter()
    ax = profiles.axial_profile(pack, section, floor, top + 0.5 * d, slab=0.1,
                                d_elem=d, samples_per_slab=2000)
    rep["axial"] = dict(y=ax["y"].tolist(), eps=ax["eps"].tolist())
    ori = profiles.orientation_to_axis(pack, (0.0, 1.0, 0.0))
    rep["orientation"] = {k: ori[k] for k in ("mean", "sem", "sem_iso", "s2")}
    co = profiles.coordination(pack, walls=cont.solid_walls(top + 4 * d), gap=CONTACT_GAP * d,
                               periodic=cont.kind == "box")
    rep["coordination"] = dict(z_total=co["z_total"], z_elem=co["z_elem"],
                               rattlers=co["rattlers"], under_stable=co["under_stable"],
                               wall_contacts=int(np.sum(co["wall"])), pairs=co["pairs"],
                               gap=co["gap"], gap_d=CONTACT_GAP, method=co["method"],
                               engine_min_gap=co["min_gap"],
                               probe_max_depth=co["probe_max_depth"],
                               contacts_per_element=co["total"].tolist())
    timing["axial_orientation_coordination"] = time.perf_counter() - t
    if out is not None and (figures or exports):
        rep["files"] = _files(res, out, rep, prof, ax, b, figures, exports, spacing, timing,
                              stl_resolution, stl_layout)
    rep["timing"] = timing
    return rep


def _box_section(cont):
    Lx, Lz = cont.period
    cx, cz = cont.center_xz
    hx, hz = 0.5 * cont.size[0] * cont.d, 0.5 * cont.size[1] * cont.d
    return (cx - hx, cx + hx), (cz - hz, cz + hz)


def _files(res, out, rep, prof, ax, b, figures, exports, spacing, timing,
           stl_resolution=None, stl_layout="merged"):
    from . import bed_figures, export

    pack, cont, d = res.pack, res.container, res.container.d
    files = {}
    if figures:
        # the bed view's mesh (the exports mesh the element on their own, at their resolution)
        t = time.perf_counter()
        mesh = export.element_mesh(pack, spacing=spacing, d_elem=d)
        timing["mesh"] = time.perf_counter() - t
        t = time.perf_counter()
        if prof is not None:
            files["radial_profile"] = bed_figures.radial_profile_figure(
                prof, os.path.join(out, "radial_profile.png"), sphere=res.element.sphere,
                title=f"{res.element.name}, {cont.label()}")
        files["axial_profile"] = bed_figures.axial_profile_figure(
            ax, os.path.join(out, "axial_profile.png"), d_elem=d, floor_y=cont.floor_y, bulk=b)
        files["bed"] = bed_figures.bed_view(
            pack, mesh, os.path.join(out, "bed.png"),
            cutaway_center_xz=cont.center_xz if cont.kind == "column" else None,
            floor_y=cont.floor_y, d_elem=d)
        timing["figures"] = time.perf_counter() - t
    if exports:
        t = time.perf_counter()
        resolution = export.check_bed_triangles(
            pack.n, export.DEFAULT_RESOLUTION if stl_resolution is None else stl_resolution,
            "stl_resolution")
        if stl_layout not in STL_LAYOUTS:
            from peclet.core.validation import PecletArgumentError
            raise PecletArgumentError("stl_layout", "one of " + ", ".join(STL_LAYOUTS),
                                      stl_layout)
        v0, f0, info = export.export_mesh(pack, resolution, d_elem=d, name="stl_resolution",
                                          min_feature=getattr(res.element, "min_feature", None))
        export.check_bed_triangles(pack.n, resolution, "stl_resolution", per_element=len(f0))
        rep["export"] = dict(info, layout=stl_layout)
        solid = cont.export_solid(rep["bed_top"] + 0.5 * d)
        if solid is not None:  # meshed once for the STL and the VTU
            solid = export.container_mesh(*solid, max_triangles=export.CONTAINER_TRIANGLES)
        if stl_layout == "per-element":
            files["stl"] = export.write_stl_files(os.path.join(out, "bed_stl"), pack,
                                                  container=solid, home_mesh=(v0, f0))["path"]
        else:
            per = pack.n <= STL_PER_ELEMENT_MAX
            files["stl"] = export.write_stl(os.path.join(out, "bed.stl"), pack,
                                            per_element=per, container=solid if per else None,
                                            home_mesh=(v0, f0))["path"]
        files["vtu"] = export.write_vtu(os.path.join(out, "bed.vtu"), pack, container=solid,
                                        home_mesh=(v0, f0), resolution=resolution)["path"]
        files["transforms"] = export.write_transforms_csv(os.path.join(out, "transforms.csv"),
                                                          pack, element=res.element.name)
        timing["exports"] = time.perf_counter() - t
    return {k: os.path.abspath(v) for k, v in files.items()}


def _element_doc(res):
    """results.json's ``element``: the name, the resolved construction parameters (lengths in
    the element's unit, D = 1 at the defaults), their canonical ``--element`` text (re-parsable;
    None for a user's tree) and the shell probe count the DEM used (it follows the thinnest
    wall: ``api.element_model``)."""
    from ..bed.elements import ELEMENTS, element_text

    name, params = res.spec.get("element"), res.spec.get("element_params") or {}
    text = element_text(name, params) if name in ELEMENTS and params else None
    return dict(name=name, params=params, text=text, shell_probes=int(len(res.element.shell)))


def _contact_doc(res):
    """The Hertz law's step rule as the run used it: substeps K per protocol step, the
    substep (time units), the element's Rayleigh time and the line the command prints."""
    from ..bed.contact import parse_contact

    law, dt = parse_contact(res.spec["contact"]), float(res.spec["protocol"]["dt"])
    k, sub, tr = law.schedule(res.element, dt)
    return dict(law.to_spec(), substeps=k, dt=sub, rayleigh_time=tr,
                text=law.describe(res.element, dt))


def write_results(path, res, rep):
    """``results.json``: the run's spec, its figures (steps, seconds, state hash) and ``rep``."""
    doc = dict(spec=res.spec, run=dict(steps=res.steps, seconds=res.seconds,
                                       first_step_seconds=res.first_step_seconds,
                                       ms_per_step=res.ms_per_step(),
                                       complete=res.complete, state_sha256=res.state_hash(),
                                       ke_end=float(res.ke[-1]) if res.ke else None),
               analysis=rep)
    if "contact" in res.spec:
        doc["run"]["contact"] = _contact_doc(res)
    doc["element"] = _element_doc(res)
    return write_json(path, doc)


def table(res, rep):
    """The results table (text)."""
    sp, bk, co = res.spec, rep["bulk"], rep["coordination"]
    m, wm = sp["material"], sp["wall_material"]
    rows = [("element, count", f"{rep['element']}, {rep['count']} (D = {rep['d_elem']:g})"),
            ("container", rep["container"]),
            ("protocol", f"{sp['protocol']['kind']}"),
            ("contact law", "impulse" if "contact" not in sp
             else _contact_doc(res)["text"][len("contact "):]),
            ("material (e_n, mu) / wall", f"({m['e_n']:g}, {m['mu']:g}) / "
                                          f"({wm['e_n']:g}, {wm['mu']:g})"),
            ("steps, wall-clock", f"{res.steps} steps, {res.seconds:.1f} s "
                                  f"({res.ms_per_step():.2f} ms/step after the first step, "
                                  f"which took {res.first_step_seconds:.1f} s)"),
            ("bed top (y, D)", f"{rep['bed_top'] / rep['d_elem']:.2f}, crop {rep['crop']:.2f} D"),
            ("bulk voidage eps", f"{bk['eps']:.4f} +- {bk['eps_se']:.4f}")]
    if "benyahia_oneill" in rep:
        rows.append(("  Benyahia & O'Neill 2005", f"{rep['benyahia_oneill']:.4f}"))
    if bk["f_env"] is not None and math.isfinite(bk["f_env"]):
        rows.append(("envelope fraction f_env", f"{bk['f_env']:.4f} +- {bk['f_env_se']:.4f}"))
    if "radial" in rep:
        f = rep["radial"]["features"]
        fmt = lambda p: "n/a" if p is None else f"{p[1]:.3f} at z = {p[0]:.2f}"  # noqa: E731
        rows += [("radial: wall eps", fmt(f["wall"])), ("  first minimum", fmt(f["min1"])),
                 ("  maximum", fmt(f["max1"])), ("  second minimum", fmt(f["min2"]))]
    o = rep["orientation"]
    rows += [("coordination (with walls)", f"{co['z_total']:.2f} ({co['z_elem']:.2f} element-"
              f"element), {co['rattlers']} rattlers, {co['under_stable']} with < 4 contacts "
              f"(engine contacts, gap < {co['gap_d']:g} D)"),
             ("axis |cos| to the vertical", f"{o['mean']:.3f} +- {o['sem']:.3f} (isotropic "
              f"0.500), S2 {o['s2']:+.3f}"),
             ("state SHA-256", res.state_hash()[:16] + "...")]
    w0 = max(len(r[0]) for r in rows)
    return "\n".join(f"{a:<{w0}}  {b}" for a, b in rows)
