"""Exports of a frozen pack for CFD and visualisation: STL, a transforms CSV and VTU.

The element is meshed ONCE in its home frame (marching cubes of its tree through
:func:`peclet.core.geom.mesh.surface_mesh`) and every element is that mesh moved by its pose,
``v_world = R(q) v_home + p`` (quaternions (x, y, z, w), active, home -> world).

``shrink`` (a fraction of the element diameter ``d_elem``) opens point contacts for meshing: the
mesh is the level set phi = -shrink d_elem, i.e. the solid offset inward by shrink d_elem where
phi is a distance (every leaf's phi is, away from the CSG edges, where the offset surface keeps
a sharp edge). Two elements that touched are then 2 shrink d_elem apart; the element volume
falls by about shrink d_elem times its area.

Resolution (:func:`export_mesh`, what the writers use): the marching-cubes mesh of a fine
lattice (0.02 D, finer for a thinner wall) is decimated by quadric edge collapse
(fast-simplification) to what ``resolution`` asks, given as text or a number:

* ``"Ntri"`` (e.g. ``"2000tri"``): a budget of N triangles per element, N an integer in
  [:data:`MIN_ELEMENT_TRIANGLES`, :data:`MAX_ELEMENT_TRIANGLES`]; the mesh has N (fewer if
  the lattice mesh has fewer; more only if no mesh of N triangles keeps the element closed
  with its topology: a Pall ring needs 388).
* ``"0.01"`` or ``"0.01D"`` (or the number 0.01): a chord error in element diameters D, in
  [:data:`CHORD_MIN`, :data:`CHORD_MAX`]: the fewest triangles (to 5 %) whose chord error is
  at most that. The chord error is the largest |phi| (phi + shrink d_elem with a shrink) over
  the mesh's vertices, edge midpoints and face centroids, in D: the distance from the mesh to
  the element's surface where the tree is a distance (1-Lipschitz, as every library element).

The default, :data:`DEFAULT_RESOLUTION` = ``"1000tri"``, is chosen so that 1000 elements write
a 50 MB binary STL (50 bytes a triangle) and a 22.5 MB VTU (zlib). On the Pall ring it has a
chord error of 0.0064 D and an enclosed volume 0.9 % under the exact one (the old undecimated
0.04 D lattice: 10112 triangles, 0.015 D, -4.0 %, 506 MB + 228 MB): quadric collapse keeps
the flat faces and the cylinders' curvature, and marching cubes rounds the sharp edges at its
lattice scale, which is where the volume goes. Every element mesh is checked watertight (every edge
shared by exactly two faces, consistently wound, positive volume) before it is written; a
decimation that is not is redone less aggressively or with more triangles. Bounds from memory:
the lattice has at most :data:`EXPORT_LATTICE_MAX` points per axis and the VTU, assembled in
memory by meshio, at most :data:`MAX_BED_TRIANGLES` triangles in all.

Layouts: :func:`write_stl` writes one file (binary, one merged solid; or ASCII with one named
solid per element and the container); :func:`write_stl_files` a directory of binary STL files,
one per element (and ``container.stl``).

Libraries: trimesh writes and reads the STL files (ASCII with one named solid per element, or
binary for one merged solid) and checks that a mesh is watertight and what volume it encloses;
fast-simplification decimates; meshio writes the VTU that ParaView reads (triangles, with the
element id as cell data). Every file is written through
:func:`peclet.core.files.atomic_write` (a directory of files through a temporary sibling
renamed into place).

Modules: :mod:`~peclet.packing.output.resolution` (what ``resolution`` accepts, the bed's
triangle cap), :mod:`~peclet.packing.output.meshing` (the element's and the container's
meshes, decimation and the watertight check), :mod:`~peclet.packing.output.stl`,
:mod:`~peclet.packing.output.vtu` and :mod:`~peclet.packing.output.transforms` (one writer
each). This module gathers their names: import them from here.
"""
from __future__ import annotations

from .meshing import (BASE_SPACING, CONTAINER_TRIANGLES, EXPORT_LATTICE_MAX, bed_meshes,
                      container_mesh, element_mesh, export_mesh)
from .resolution import (CHORD_MAX, CHORD_MIN, DEFAULT_RESOLUTION, MAX_BED_TRIANGLES,
                         MAX_ELEMENT_TRIANGLES, MIN_ELEMENT_TRIANGLES, RESOLUTION_HELP,
                         Resolution, check_bed_triangles, parse_resolution)
from .stl import write_stl, write_stl_files
from .transforms import CSV_HEADER, read_transforms_csv, write_transforms_csv
from .vtu import write_vtu

__all__ = ["element_mesh", "export_mesh", "container_mesh", "bed_meshes", "write_stl",
           "write_stl_files", "write_vtu", "write_transforms_csv", "read_transforms_csv",
           "parse_resolution", "check_bed_triangles", "Resolution", "CSV_HEADER",
           "DEFAULT_RESOLUTION", "RESOLUTION_HELP", "MIN_ELEMENT_TRIANGLES",
           "MAX_ELEMENT_TRIANGLES", "CHORD_MIN", "CHORD_MAX", "EXPORT_LATTICE_MAX",
           "MAX_BED_TRIANGLES", "BASE_SPACING", "CONTAINER_TRIANGLES"]
