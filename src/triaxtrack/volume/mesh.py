"""Soil volume of one frame, the membrane's thickness, and the closed meshes (mm, mm^3)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from triaxtrack.volume.cap import TopCap, _readonly
from triaxtrack.volume.grid import MembraneGrid
from triaxtrack.volume.surface import (
    _closed_from_rings,
    _ring_volume,
    _Surface,
    _surface_rings,
    signed_volume,
)

REFINE_LEVELS = (2, 4)  # mesh refinements m, 2 m of the smooth surface (Richardson)


@dataclass(frozen=True)
class VolumeResult:
    """Volumes of one frame, mm^3 (``volume_mm3 = mesh_volume_mm3 + chordal_mm3 - membrane_mm3``).

    ``volume_mm3`` the soil volume (inside the membrane's inner surface, between the faces);
    ``mesh_volume_mm3`` the facetted outer surface through the dots; ``chordal_mm3`` the smooth
    outer surface minus that; ``membrane_mm3`` the membrane shell removed; ``outer_mm3`` the
    smooth outer volume; ``richardson_mm3`` the change the Richardson step made to the soil
    volume (an upper bound of the remaining discretisation error); ``height_mm`` the top face
    centre's height; ``filled_dots`` the dots filled from neighbours.
    """

    volume_mm3: float
    mesh_volume_mm3: float
    chordal_mm3: float
    membrane_mm3: float
    outer_mm3: float
    richardson_mm3: float
    height_mm: float
    filled_dots: int


def specimen_volume(
    grid: MembraneGrid,
    cap: TopCap,
    thickness_mm: float | np.ndarray,
    levels: tuple[int, int] = REFINE_LEVELS,
) -> VolumeResult:
    """Soil volume of one frame (see the module docstring for the method).

    ``thickness_mm``: the membrane thickness in mm, a scalar or (R, C) per dot
    (:func:`membrane_thickness`); 0 gives the volume inside the printed surface. ``levels``: the
    refinements ``(m, 2 m)`` of the smooth surface's meshes that are Richardson-extrapolated.
    """
    m1, m2 = levels
    ratio = (m2 / m1) ** 2
    mesh = _ring_volume(_surface_rings(_Surface.build(grid, thickness_mm, 1), grid, cap, 1, inner=False))
    vols = {}
    for m in (m1, m2):
        surf = _Surface.build(grid, thickness_mm, m)
        vols[m] = (
            _ring_volume(_surface_rings(surf, grid, cap, m, inner=False)),
            _ring_volume(_surface_rings(surf, grid, cap, m, inner=True)),
        )
    outer = (ratio * vols[m2][0] - vols[m1][0]) / (ratio - 1)
    inner = (ratio * vols[m2][1] - vols[m1][1]) / (ratio - 1)
    return VolumeResult(
        volume_mm3=float(inner),
        mesh_volume_mm3=float(mesh),
        chordal_mm3=float(outer - mesh),
        membrane_mm3=float(outer - inner),
        outer_mm3=float(outer),
        richardson_mm3=float(inner - vols[m2][1]),
        height_mm=float(cap.height_mm),
        filled_dots=grid.filled,
    )


def membrane_thickness(
    grid: MembraneGrid, grid0: MembraneGrid, t0: float, iterations: int = 2, model: str = "area"
) -> np.ndarray:
    """(R, C) membrane thickness in mm at each dot, for incompressible rubber.

    ``model="area"`` (default, volume-conserving): ``t = t0 A0 / A`` with ``A = |x_theta x x_z|``
    the area element of the membrane's *inner* surface (the soil boundary) at the dot in this
    frame and ``A0`` in the reference frame ``grid0`` (where the thickness is ``t0``).
    ``model="stretch"``: ``t = t0 / (lambda_theta lambda_z)``, the product of the stretches of
    the two tangents ``|x_theta|, |x_z|``, as the simulator (:mod:`triaxtrack.deformation`)
    defines it; it equals the area model unless the grid shears (tangents no longer
    orthogonal), where it gives a thinner membrane. The inner surface depends on the thickness,
    so this iterates from the printed surface's elements (``iterations`` more passes; the first
    guess is within ~0.1 % of t).
    """
    if grid.xyz.shape != grid0.xyz.shape:
        raise ValueError("the grid and the reference grid differ in shape")
    if model not in ("area", "stretch"):
        raise ValueError(f"unknown membrane thickness model {model!r} (use 'area' or 'stretch')")
    zq = np.repeat(np.asarray(grid.z, float)[:, None], len(grid.theta), axis=1)

    def element(g: MembraneGrid, t: float | np.ndarray) -> np.ndarray:
        xyz = np.asarray(g.xyz, float)
        if np.any(t):
            xyz = _Surface.build(g, t, 1).points(zq, inner=True)
        surf = _Surface.build(_replace_xyz(g, xyz), 0.0, 1)
        if model == "area":
            return surf.area(zq)[..., 0]
        return np.linalg.norm(surf.d_theta(zq), axis=-1) * np.linalg.norm(surf.pos(zq, 1), axis=-1)

    t = t0 * element(grid0, 0.0) / element(grid, 0.0)
    if iterations > 0:
        a0 = element(grid0, t0)
        for _ in range(iterations):
            t = t0 * a0 / element(grid, t)
    return t


def _replace_xyz(g: MembraneGrid, xyz: np.ndarray) -> MembraneGrid:
    return MembraneGrid(_readonly(xyz), g.measured, g.theta, g.z, g.rows, g.cols, g.sigma_mm)


# ---------------------------------------------------------------- meshes
def closed_mesh(
    grid: MembraneGrid,
    cap: TopCap,
    refine: int = 1,
    thickness_mm: float | np.ndarray = 0.0,
    inner: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Closed, outward-oriented triangle mesh of the specimen: vertices (N, 3) mm, triangles
    (M, 3) int64.

    ``refine = 1``: the lateral surface through the dots (continued to the face planes), flat fan
    caps on the faces; ``refine > 1`` meshes the smooth interpolant that much finer; ``inner``
    the membrane's inner surface (offset by ``thickness_mm``) instead of the printed one.
    """
    surf = _Surface.build(grid, thickness_mm, refine)
    return _closed_from_rings(_surface_rings(surf, grid, cap, refine, inner))


def check_mesh(vertices: np.ndarray, triangles: np.ndarray) -> dict:
    """Topology of a triangle mesh (mm) by Open3D, and its orientation.

    Returns ``watertight`` (Open3D: edge- and vertex-manifold and not self-intersecting; its
    self-intersection test is brute force, ~0.2 s for a 4000-vertex dot mesh), ``orientable``,
    ``edge_manifold`` (every edge in exactly two triangles), ``vertex_manifold`` (bools),
    ``signed_volume_mm3`` (divergence theorem) and ``outward`` (that volume > 0: the triangles
    are oriented with outward normals).
    """
    from triaxtrack.open3d_loader import import_open3d

    o3d = import_open3d()
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(vertices, float)),
        o3d.utility.Vector3iVector(np.asarray(triangles, np.int32)),
    )
    vol = signed_volume(np.asarray(vertices, float), np.asarray(triangles, np.int64))
    return {
        "watertight": bool(mesh.is_watertight()),
        "orientable": bool(mesh.is_orientable()),
        "edge_manifold": bool(mesh.is_edge_manifold(allow_boundary_edges=False)),
        "vertex_manifold": bool(mesh.is_vertex_manifold()),
        "signed_volume_mm3": vol,
        "outward": vol > 0,
    }


def write_ply(path: str | Path, vertices: np.ndarray, triangles: np.ndarray) -> None:
    """Write a triangle mesh (mm) as PLY via Open3D (with vertex normals); OSError on failure."""
    from triaxtrack.open3d_loader import import_open3d

    o3d = import_open3d()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(vertices, float)),
        o3d.utility.Vector3iVector(np.asarray(triangles, np.int32)),
    )
    mesh.compute_vertex_normals()
    if not o3d.io.write_triangle_mesh(str(path), mesh):
        raise OSError(f"{path}: Open3D could not write the mesh")
