"""Specimen volume and membrane strains from the reconstructed membrane dots.

Units and conventions: positions in mm in the cell frame (origin the centre of the bottom
pedestal's top face, +z up the axis), volumes in mm^3, angles in radians, strains
dimensionless. The specimen strains of :data:`triaxtrack.tables.VOLUME` (axial, radial,
volumetric, and the volume change sign) are compression positive; the local Green-Lagrange
membrane strains of :data:`triaxtrack.tables.STRAINS` are tension positive.

Method
------
The dots are printed on the membrane's *outer* surface on a grid of rows (design z) and columns
(design theta). One frame's dots become a :class:`MembraneGrid` (missing dots filled from their
neighbours). The top cap is a rigid body: its coded targets give a rotation and translation
from the design (:class:`TopCap`), hence the specimen's top face plane and current height; the
bottom face is the plane z = 0.

The soil volume is that inside the membrane's *inner* surface between the two faces:

1. ``mesh_volume_mm3``: the closed triangle mesh through the dot positions (the lateral surface
   continued per column to the two face planes, flat caps on the faces), by the divergence
   theorem ``V = 1/6 sum v0 . (v1 x v2)``.
2. ``chordal_mm3``: flat facets cut the chords of a convex surface (about 0.16 % of the volume
   for 64 columns). A smooth tensor interpolant of the dots -- periodic cubic spline in theta,
   not-a-knot cubic spline in design z, with two ghost rows beyond each end row extrapolated
   per column by a least-squares quadratic over the four end rows -- is meshed ``m`` and ``2 m``
   times finer (nodes at the dots are kept), and the facet volumes are Richardson-extrapolated
   (error ~ h^2) to the smooth surface's volume. The correction is that minus the dot mesh.
3. ``membrane_mm3``: the membrane shell, the volume between the outer surface and its inward
   offset by the local thickness ``t`` along the interpolant's unit normal (offset surfaces share
   their normals, so this inverts the printed-surface construction exactly). The inner surface
   is meshed, clipped to the face planes and Richardson-extrapolated the same way.
   :func:`membrane_thickness` models thinning of incompressible rubber, ``t = t0 A0 / A``, from
   the local area element of the (inner) surface against the reference (first) frame. The
   simulator instead thins by ``t0 / (lambda_theta lambda_z)``, which ignores the shear angle;
   the two agree except in a shear band (3 mm band: 1e-5 of the volume), and
   ``model="stretch"`` reproduces the simulator's.

``volume_mm3 = mesh_volume_mm3 + chordal_mm3 - membrane_mm3``.

Each column of a surface is cut at the face planes by Newton iteration on its spline in design
z, so every mesh's end rings lie exactly on the faces (a tilted top cap is handled). The grid's
columns are assumed evenly spaced in theta (as the kit prints them).

On the simulator's synthetic frames the soil volume is exact to ~3e-7 (1e-5 in a shear band,
see above); 0.02 mm noise on every point gives ~5e-5 (mostly the top cap's height).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.interpolate import CubicSpline

from triaxtrack.kit import design_points, surface_by_name

MAX_MISSING_SHARE = 0.2  # default: a frame with more missing membrane dots fails
GHOST_ROWS = 2  # rows extrapolated beyond each end row, for the spline's ends
GHOST_FIT_ROWS = 4  # end rows of the per-column least-squares quadratic that makes the ghosts
REFINE_LEVELS = (2, 4)  # mesh refinements m, 2 m of the smooth surface (Richardson)
NEWTON_ITER = 30
NEWTON_TOL_MM = 1e-10


# ---------------------------------------------------------------- the membrane grid
@dataclass(frozen=True)
class MembraneGrid:
    """One frame's membrane dots on the kit's grid.

    ``xyz`` (R, C, 3) positions in mm (cell frame) on the printed surface, index ``[i, j]`` the
    i-th row from the bottom (increasing design z) and j-th column (increasing theta);
    ``measured`` (R, C) whether the dot was measured (else filled); ``theta`` (C,) design theta
    (rad) and ``z`` (R,) design z (mm) of the columns and rows; ``rows``/``cols`` the kit's 1-based
    row and column numbers per index (row 1 is the top row).
    """

    xyz: np.ndarray
    measured: np.ndarray
    theta: np.ndarray
    z: np.ndarray
    rows: np.ndarray
    cols: np.ndarray

    @property
    def filled(self) -> int:
        """Number of dots filled from their neighbours."""
        return int((~self.measured).sum())


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def _membrane_layout(table: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """Membrane rows of the design table with grid indices ``i, j`` added; design z and theta."""
    mem = table.loc[table["surface"] == "membrane", ["id", "theta_rad", "z_mm", "row", "col"]].copy()
    if mem.empty:
        raise ValueError("the target table has no membrane dots")
    z_of_row = mem.groupby("row")["z_mm"].first().sort_values()
    th_of_col = mem.groupby("col")["theta_rad"].first().sort_values()
    if len(z_of_row) * len(th_of_col) != len(mem):
        raise ValueError("the membrane dots of the target table do not form a full grid")
    mem["i"] = mem["row"].map({r: k for k, r in enumerate(z_of_row.index)})
    mem["j"] = mem["col"].map({c: k for k, c in enumerate(th_of_col.index)})
    return mem, z_of_row, th_of_col


def _kasa_circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Algebraic least-squares circle through (n, 2) points: centre (2,) and radius, mm."""
    a = np.c_[2 * xy, np.ones(len(xy))]
    b = (xy**2).sum(axis=1)
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    centre = sol[:2]
    return centre, float(np.sqrt(max(sol[2] + centre @ centre, 0.0)))


def membrane_grid(
    points: pd.DataFrame, table: pd.DataFrame, max_missing_share: float = MAX_MISSING_SHARE
) -> MembraneGrid:
    """The membrane dots of ONE frame on the kit's grid, missing dots filled.

    ``points`` has columns ``id, x_mm, y_mm, z_mm`` (mm, cell frame; other columns and
    non-membrane IDs are ignored; rows with a NaN coordinate count as missing). A missing dot is
    filled by linear interpolation of the displacement from a reference position -- the design
    position (theta, z) on its row's current best-fit circle -- along its row (periodic in theta),
    or along its column (in design z) when both row neighbours are missing too but both column
    neighbours are measured. Raises ValueError when a whole row is missing, when more than
    ``max_missing_share`` of the dots are missing, or when an ID appears twice.
    """
    mem, z_of_row, th_of_col = _membrane_layout(table)
    n_r, n_c = len(z_of_row), len(th_of_col)
    pts = points.loc[points["id"].isin(mem["id"]), ["id", "x_mm", "y_mm", "z_mm"]]
    pts = pts[np.isfinite(pts[["x_mm", "y_mm", "z_mm"]].to_numpy(float)).all(axis=1)]
    if pts["id"].duplicated().any():
        dup = pts.loc[pts["id"].duplicated(), "id"].tolist()[:5]
        raise ValueError(f"membrane dots measured twice in one frame, e.g. IDs {dup}")
    ij = mem.set_index("id").loc[pts["id"], ["i", "j"]].to_numpy()
    xyz = np.full((n_r, n_c, 3), np.nan)
    xyz[ij[:, 0], ij[:, 1]] = pts[["x_mm", "y_mm", "z_mm"]].to_numpy(float)
    measured = np.isfinite(xyz[..., 0])
    rows = z_of_row.index.to_numpy(np.int64)
    missing_share = 1 - measured.mean()
    if missing_share > max_missing_share:
        raise ValueError(
            f"{missing_share:.1%} of the {n_r * n_c} membrane dots are missing "
            f"(more than the allowed {max_missing_share:.0%})"
        )
    empty = np.flatnonzero(~measured.any(axis=1))
    if empty.size:
        raise ValueError(f"membrane row(s) {rows[empty].tolist()} have no measured dot")
    theta = th_of_col.to_numpy(float)
    z = z_of_row.to_numpy(float)
    if not measured.all():
        xyz = _fill(xyz, measured, theta, z)
    return MembraneGrid(
        _readonly(xyz), _readonly(measured), _readonly(theta), _readonly(z), _readonly(rows),
        _readonly(th_of_col.index.to_numpy(np.int64)),
    )  # fmt: skip


def _fill(xyz: np.ndarray, measured: np.ndarray, theta: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Fill the NaN dots of ``xyz`` (a copy is returned); see :func:`membrane_grid`."""
    n_r, n_c = measured.shape
    all_xy = xyz[measured][:, :2]
    g_centre, g_radius = _kasa_circle(all_xy)
    ref = np.empty_like(xyz)
    for i in range(n_r):
        m = measured[i]
        centre, radius = _kasa_circle(xyz[i, m, :2]) if m.sum() >= 6 else (g_centre, g_radius)
        ref[i, :, 0] = centre[0] + radius * np.cos(theta)
        ref[i, :, 1] = centre[1] + radius * np.sin(theta)
        ref[i, :, 2] = np.mean(xyz[i, m, 2])
    disp = xyz - ref
    out = xyz.copy()
    left, right = np.roll(measured, 1, axis=1), np.roll(measured, -1, axis=1)
    below = np.zeros_like(measured)
    above = np.zeros_like(measured)
    below[1:], above[:-1] = measured[:-1], measured[1:]
    by_column = ~measured & ~(left & right) & below & above
    for i in range(n_r):
        todo = ~measured[i] & ~by_column[i]
        if todo.any():
            m = measured[i]
            for k in range(3):
                out[i, todo, k] = ref[i, todo, k] + np.interp(
                    theta[todo], theta[m], disp[i, m, k], period=2 * np.pi
                )
    for i, j in zip(*np.nonzero(by_column), strict=True):
        w = (z[i] - z[i - 1]) / (z[i + 1] - z[i - 1])
        out[i, j] = ref[i, j] + (1 - w) * disp[i - 1, j] + w * disp[i + 1, j]
    return out


# ---------------------------------------------------------------- the top cap
@dataclass(frozen=True)
class TopCap:
    """Rigid pose of the top cap: ``x = rotation @ X_design + translation`` (mm).

    ``face_point`` (3,) the centre of the specimen's top face (the design face centre mapped),
    ``face_normal`` (3,) its unit normal pointing up (out of the specimen), ``height_mm`` the face
    centre's height above the bottom face z = 0, ``n_targets`` the CTs used, ``rms_mm`` their fit
    residual.
    """

    rotation: np.ndarray
    translation: np.ndarray
    face_point: np.ndarray
    face_normal: np.ndarray
    height_mm: float
    n_targets: int
    rms_mm: float


def rigid_fit(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation R and translation t with ``dst ~ R src + t`` (Kabsch/Umeyama, no
    scale), from (n, 3) point pairs, n >= 3 not collinear."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    u, _, vt = np.linalg.svd((dst - cd).T @ (src - cs))
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1.0, 1.0, d]) @ vt
    return rot, cd - rot @ cs


def top_cap(points: pd.DataFrame, table: pd.DataFrame, design: dict) -> TopCap:
    """The top cap's rigid pose from its coded targets (surface 'pedestal_top') in one frame.

    ``points`` has columns ``id, x_mm, y_mm, z_mm`` (mm, cell frame). The specimen's top face is
    the design plane z = ``pedestal_top`` z_min (the specimen height) carried by the fitted
    transform. Raises ValueError when fewer than 3 of the cap's targets are measured.
    """
    ids = table.loc[table["surface"] == "pedestal_top", "id"]
    des = design_points(design, table).set_index("id").loc[ids, ["x_mm", "y_mm", "z_mm"]]
    meas = points.loc[points["id"].isin(ids), ["id", "x_mm", "y_mm", "z_mm"]].drop_duplicates("id")
    meas = meas[np.isfinite(meas[["x_mm", "y_mm", "z_mm"]].to_numpy(float)).all(axis=1)]
    if len(meas) < 3:
        raise ValueError(f"only {len(meas)} top-cap coded targets measured (3 needed for its pose)")
    src = des.loc[meas["id"]].to_numpy(float)
    dst = meas[["x_mm", "y_mm", "z_mm"]].to_numpy(float)
    rot, trans = rigid_fit(src, dst)
    rms = float(np.sqrt(np.mean(np.sum((src @ rot.T + trans - dst) ** 2, axis=1))))
    z_face = float(surface_by_name(design)["pedestal_top"]["z_min"])
    face = rot @ np.array([0.0, 0.0, z_face]) + trans
    normal = rot @ np.array([0.0, 0.0, 1.0])
    return TopCap(
        _readonly(rot), _readonly(trans), _readonly(face), _readonly(normal), float(face[2]), len(meas), rms
    )


# ---------------------------------------------------------------- the smooth surface
class _ColumnSplines:
    """Cubic splines in design z of a field sampled on (rows, columns): one per column."""

    def __init__(self, z: np.ndarray, values: np.ndarray):  # values (Rg, Cf, k)
        cs = CubicSpline(z, values, axis=0)
        self.x = cs.x
        self.c = cs.c  # (4, Rg - 1, Cf, k)

    def __call__(self, zq: np.ndarray, nu: int = 0) -> np.ndarray:
        """Values (n, Cf, k) (or the z-derivative, nu = 1) at per-column z ``zq`` (n, Cf)."""
        seg = np.clip(np.searchsorted(self.x, zq, side="right") - 1, 0, len(self.x) - 2)
        d = (zq - self.x[seg])[..., None]
        c = self.c[:, seg, np.arange(zq.shape[1])[None, :]]
        if nu == 0:
            return ((c[0] * d + c[1]) * d + c[2]) * d + c[3]
        return (3 * c[0] * d + 2 * c[1]) * d + c[2]


def _ghost_rows(z: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows extended by GHOST_ROWS rows at each end (spacing of the end rows), per column by a
    least-squares quadratic in z over the GHOST_FIT_ROWS end rows. ``values`` (R, C, k)."""
    n_fit = min(GHOST_FIT_ROWS, len(z))
    deg = min(2, n_fit - 1)
    parts_z, parts_v = [], []
    for end in (0, 1):
        zz = z[:n_fit] if end == 0 else z[-n_fit:]
        vv = values[:n_fit] if end == 0 else values[-n_fit:]
        dz = zz[1] - zz[0] if end == 0 else zz[-1] - zz[-2]
        steps = np.arange(GHOST_ROWS, 0, -1) if end == 0 else np.arange(1, GHOST_ROWS + 1)
        zg = zz[0] - steps * dz if end == 0 else zz[-1] + steps * dz
        u = (zz - zz.mean()) / dz
        vand = np.vander(u, deg + 1)
        coef = np.linalg.lstsq(vand, vv.reshape(len(zz), -1), rcond=None)[0]
        vg = np.vander((zg - zz.mean()) / dz, deg + 1) @ coef
        parts_z.append(zg)
        parts_v.append(vg.reshape((len(zg),) + values.shape[1:]))
    return (
        np.concatenate([parts_z[0], z, parts_z[1]]),
        np.concatenate([parts_v[0], values, parts_v[1]], axis=0),
    )


def _periodic(theta: np.ndarray, values: np.ndarray, theta_q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Periodic cubic spline in theta (axis 1) of (Rg, C, k) values: values and d/dtheta at theta_q."""
    th = np.append(theta, theta[0] + 2 * np.pi)
    vals = np.concatenate([values, values[:, :1]], axis=1)
    cs = CubicSpline(th, vals, axis=1, bc_type="periodic")
    return cs(theta_q), cs(theta_q, 1)


def _node_field(
    grid: MembraneGrid, values: np.ndarray, zg: np.ndarray, theta_q: np.ndarray
) -> _ColumnSplines:
    """Tensor spline of an (R, C) field on the dots (constant beyond the end rows) at columns theta_q."""
    v = np.asarray(values, float)
    if v.shape != grid.measured.shape:
        raise ValueError(f"thickness_mm has shape {v.shape}, not the grid's {grid.measured.shape}")
    v = np.concatenate([np.repeat(v[:1], GHOST_ROWS, 0), v, np.repeat(v[-1:], GHOST_ROWS, 0)])
    return _ColumnSplines(zg, _periodic(np.asarray(grid.theta, float), v[..., None], theta_q)[0])


@dataclass
class _Surface:
    """Tensor cubic interpolant of the printed surface (and the thickness) sampled at columns
    ``theta_q``; evaluates the outer or the inner (offset) surface per column at any design z.
    """

    theta_q: np.ndarray
    pos: _ColumnSplines
    d_theta: _ColumnSplines
    thick: _ColumnSplines | None
    t_const: float

    @staticmethod
    def build(grid: MembraneGrid, thickness: float | np.ndarray, refine: int) -> _Surface:
        n_c = len(grid.theta)
        theta_q = grid.theta[0] + 2 * np.pi * np.arange(n_c * refine) / (n_c * refine)
        if refine == 1:
            theta_q = np.asarray(grid.theta, float)
        zg, xg = _ghost_rows(np.asarray(grid.z, float), np.asarray(grid.xyz, float))
        x_q, xt_q = _periodic(np.asarray(grid.theta, float), xg, theta_q)
        thick, t_const = None, 0.0
        if np.ndim(thickness) == 0:
            t_const = float(thickness)
        else:
            thick = _node_field(grid, thickness, zg, theta_q)
        return _Surface(theta_q, _ColumnSplines(zg, x_q), _ColumnSplines(zg, xt_q), thick, t_const)

    def area(self, zq: np.ndarray) -> np.ndarray:
        """(n, Cf, 1) area element |x_theta x x_z| (mm^2 per rad per mm) of the printed surface."""
        return np.linalg.norm(np.cross(self.d_theta(zq), self.pos(zq, 1)), axis=-1, keepdims=True)

    def normal(self, zq: np.ndarray) -> np.ndarray:
        n = np.cross(self.d_theta(zq), self.pos(zq, 1))
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def thickness(self, zq: np.ndarray) -> np.ndarray:
        return np.full(zq.shape + (1,), self.t_const) if self.thick is None else self.thick(zq)

    def points(self, zq: np.ndarray, inner: bool) -> np.ndarray:
        """(n, Cf, 3) points at per-column design z ``zq`` (n, Cf) on the outer/inner surface."""
        x = self.pos(zq)
        if inner:
            x = x - self.thickness(zq) * self.normal(zq)
        return x

    def cut(
        self, plane_point: np.ndarray, plane_normal: np.ndarray, z_start: float, inner: bool
    ) -> np.ndarray:
        """(Cf,) design z where each column meets the plane (Newton; the derivative of the outer
        surface stands in for the inner one's, which converges as fast for thin membranes)."""
        zq = np.full((1, len(self.theta_q)), float(z_start))
        for _ in range(NEWTON_ITER):
            f = (self.points(zq, inner) - plane_point) @ plane_normal
            df = self.pos(zq, 1) @ plane_normal
            step = f / df
            zq = zq - step
            if np.all(np.abs(f) < NEWTON_TOL_MM):
                break
        else:
            if not np.all(np.abs(f) < 1e3 * NEWTON_TOL_MM):
                raise ValueError("the membrane surface does not meet a pedestal face plane (cut diverged)")
        return zq[0]


def _grid_nodes(z_rows: np.ndarray, z_bottom: np.ndarray, z_top: np.ndarray, refine: int) -> np.ndarray:
    """(Nz, Cf) design z of the mesh rings: the face cut, the dot rows and the top cut, each
    interval split into ``refine`` parts."""
    n_c = len(z_bottom)
    if np.any(z_bottom >= z_rows[0]) or np.any(z_top <= z_rows[-1]):
        raise ValueError("a pedestal face plane cuts through the membrane dot rows")
    knots = np.vstack([z_bottom, np.repeat(z_rows[:, None], n_c, axis=1), z_top])  # (R + 2, Cf)
    s = np.arange(refine) / refine
    inner = (knots[:-1, None, :] + s[None, :, None] * (knots[1:] - knots[:-1])[:, None, :]).reshape(-1, n_c)
    return np.vstack([inner, knots[-1:]])


def _lateral_triangles(n_z: int, n_c: int, offset: int = 0) -> np.ndarray:
    """Triangles (outward for rings ordered bottom-up, columns by increasing theta) of a
    periodic (n_z, n_c) vertex grid stored row-major from ``offset``."""
    i, j = np.meshgrid(np.arange(n_z - 1), np.arange(n_c), indexing="ij")
    a = i * n_c + j
    b = i * n_c + (j + 1) % n_c
    c = (i + 1) * n_c + (j + 1) % n_c
    d = (i + 1) * n_c + j
    tri = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return tri + offset


def _closed_from_rings(rings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed outward mesh of (Nz, Cf, 3) rings: lateral triangles plus a fan cap on each end ring
    about its centroid (the end rings lie in the face planes)."""
    n_z, n_c, _ = rings.shape
    verts = np.vstack([rings.reshape(-1, 3), rings[0].mean(axis=0), rings[-1].mean(axis=0)])
    lat = _lateral_triangles(n_z, n_c)
    j = np.arange(n_c)
    cb, ct = n_z * n_c, n_z * n_c + 1
    bottom = np.stack([np.full(n_c, cb), (j + 1) % n_c, j], -1)
    top = np.stack([np.full(n_c, ct), (n_z - 1) * n_c + j, (n_z - 1) * n_c + (j + 1) % n_c], -1)
    return verts, np.vstack([lat, bottom, top]).astype(np.int64)


def signed_volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Signed volume (mm^3) of a closed triangle mesh, positive when oriented outward."""
    v = vertices[triangles]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6)


def _ring_volume(rings: np.ndarray) -> float:
    return signed_volume(*_closed_from_rings(rings))


def _surface_rings(surf: _Surface, grid: MembraneGrid, cap: TopCap, refine: int, inner: bool) -> np.ndarray:
    """(Nz, Cf, 3) rings of the outer/inner surface between the two face planes."""
    z = np.asarray(grid.z, float)
    dz = z[1] - z[0] if len(z) > 1 else 1.0
    z_b = surf.cut(np.zeros(3), np.array([0.0, 0.0, 1.0]), z[0] - dz / 2, inner)
    z_t = surf.cut(np.asarray(cap.face_point), np.asarray(cap.face_normal), z[-1] + dz / 2, inner)
    return surf.points(_grid_nodes(z, z_b, z_t, refine), inner)


# ---------------------------------------------------------------- volume
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
    return MembraneGrid(_readonly(xyz), g.measured, g.theta, g.z, g.rows, g.cols)


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


# ---------------------------------------------------------------- strains
def strain_field(grid: MembraneGrid, grid0: MembraneGrid) -> pd.DataFrame:
    """Green-Lagrange membrane strain per grid cell, tension positive.

    Each cell (between grid rows i, i + 1 and columns j, j + 1, periodic) gets the tangents
    ``x_theta, x_z`` (means of its two edges in each direction) in this frame and in ``grid0``;
    ``F = A M0^-1`` maps the undeformed cell's orthonormal tangent basis (e_theta along the
    undeformed x_theta, e_z completing it in the tangent plane) to the current tangents, and
    ``E = (F^T F - I) / 2``. Columns: ``row, col`` (1-based kit numbers of the cell's upper row
    and of its first column in theta), ``theta_rad, z_mm`` the cell centre in design coordinates,
    ``e_zz, e_tt, e_tz``.
    """

    def tangents(g: MembraneGrid) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(g.xyz, float)
        x1 = np.roll(x, -1, axis=1)
        a_t = 0.5 * ((x1 - x)[:-1] + (x1 - x)[1:])
        a_z = 0.5 * ((x[1:] - x[:-1]) + (x1[1:] - x1[:-1]))
        return a_t, a_z

    if grid.xyz.shape != grid0.xyz.shape:
        raise ValueError("the grid and the reference grid differ in shape")
    a_t, a_z = tangents(grid)
    b_t, b_z = tangents(grid0)
    e1 = b_t / np.linalg.norm(b_t, axis=-1, keepdims=True)
    e2 = b_z - np.sum(b_z * e1, axis=-1, keepdims=True) * e1
    e2 /= np.linalg.norm(e2, axis=-1, keepdims=True)
    basis = np.stack([e1, e2], axis=-1)  # (.., 3, 2)
    m0 = np.swapaxes(basis, -1, -2) @ np.stack([b_t, b_z], axis=-1)  # (.., 2, 2)
    f = np.stack([a_t, a_z], axis=-1) @ np.linalg.inv(m0)  # (.., 3, 2)
    e = 0.5 * (np.swapaxes(f, -1, -2) @ f - np.eye(2))
    n_r, n_c = grid.measured.shape
    theta = np.asarray(grid.theta, float)
    dth = np.diff(np.append(theta, theta[0] + 2 * np.pi))
    z = np.asarray(grid.z, float)
    rows = np.asarray(grid.rows)
    row = np.minimum(rows[:-1], rows[1:])
    return pd.DataFrame({
        "row": np.repeat(row, n_c).astype(np.int64),
        "col": np.tile(np.asarray(grid.cols), n_r - 1).astype(np.int64),
        "theta_rad": np.tile(np.mod(theta + dth / 2, 2 * np.pi), n_r - 1),
        "z_mm": np.repeat(0.5 * (z[:-1] + z[1:]), n_c),
        "e_zz": e[..., 1, 1].ravel(),
        "e_tt": e[..., 0, 0].ravel(),
        "e_tz": e[..., 0, 1].ravel(),
    }).sort_values(["row", "col"], kind="stable").reset_index(drop=True)  # fmt: skip


# ---------------------------------------------------------------- series
def volume_series(
    points: pd.DataFrame,
    table: pd.DataFrame,
    design: dict,
    t0: float | None = None,
    max_missing_share: float = MAX_MISSING_SHARE,
    levels: tuple[int, int] = REFINE_LEVELS,
    check: bool = True,
    thickness_model: str = "area",
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Volume and membrane strains of every frame of ``points`` (columns ``frame, time_s, id,
    x_mm, y_mm, z_mm``; mm, cell frame).

    The reference is the first frame: its height H0 and volume V0, and its dot grid, where the
    membrane has the thickness ``t0`` (mm; default the design's ``specimen.membrane_thickness``).
    Returns ``(volume, strains)``: ``volume`` has the :data:`~triaxtrack.tables.VOLUME` columns
    (``axial_strain = (H0 - H) / H0``, ``volumetric_strain = (V0 - V) / V0``, compression
    positive) then ``height_mm, radial_strain = (volumetric - axial) / 2, volume_change_mm3 =
    V - V0, mesh_volume_mm3, chordal_mm3, membrane_mm3, filled_dots, watertight, reason``;
    ``strains`` has the :data:`~triaxtrack.tables.STRAINS` columns for every frame that
    succeeded. A frame that fails (too many dots missing, too few cap targets...) gets NaN values,
    ``filled_dots`` and ``watertight`` <NA> and its ``reason``; when the first frame fails, every
    frame does. ``check`` runs :func:`check_mesh` on each frame's dot mesh (``watertight``);
    ``thickness_model`` is passed to :func:`membrane_thickness`.
    """
    if t0 is None:
        t0 = float(design["specimen"]["membrane_thickness"])
    frames = sorted(points["frame"].unique())
    rows: list[dict] = []
    strain_parts: list[pd.DataFrame] = []
    ref: tuple[MembraneGrid, float, float] | None = None
    ref_error = ""
    for k, frame in enumerate(frames):
        pf = points[points["frame"] == frame]
        time_s = float(pf["time_s"].iloc[0])
        row = {"frame": int(frame), "time_s": time_s}
        try:
            if k > 0 and ref is None:
                raise ValueError(f"reference frame {frames[0]} failed: {ref_error}")
            grid = membrane_grid(pf, table, max_missing_share)
            cap = top_cap(pf, table, design)
            grid0 = grid if ref is None else ref[0]
            res = specimen_volume(
                grid, cap, membrane_thickness(grid, grid0, t0, model=thickness_model), levels
            )
            if ref is None:
                ref = (grid, res.height_mm, res.volume_mm3)
            watertight = check_mesh(*closed_mesh(grid, cap))["watertight"] if check else pd.NA
            strains = strain_field(grid, ref[0])
        except (ValueError, np.linalg.LinAlgError) as err:
            if k == 0:
                ref_error = str(err)
            rows.append(row | {"reason": str(err)})
            continue
        _, h0, v0 = ref
        axial = (h0 - res.height_mm) / h0
        volumetric = (v0 - res.volume_mm3) / v0
        rows.append(row | {
            "volume_mm3": res.volume_mm3, "axial_strain": axial, "volumetric_strain": volumetric,
            "height_mm": res.height_mm, "radial_strain": (volumetric - axial) / 2,
            "volume_change_mm3": res.volume_mm3 - v0, "mesh_volume_mm3": res.mesh_volume_mm3,
            "chordal_mm3": res.chordal_mm3, "membrane_mm3": res.membrane_mm3,
            "filled_dots": res.filled_dots, "watertight": watertight, "reason": "",
        })  # fmt: skip
        strain_parts.append(strains.assign(frame=int(frame), time_s=time_s))
    columns = [
        "frame", "time_s", "volume_mm3", "axial_strain", "volumetric_strain", "height_mm", "radial_strain",
        "volume_change_mm3", "mesh_volume_mm3", "chordal_mm3", "membrane_mm3", "filled_dots", "watertight",
        "reason",
    ]  # fmt: skip
    vol = pd.DataFrame(rows).reindex(columns=columns)
    vol["frame"] = vol["frame"].astype(np.int64)
    for c in columns[1:11]:
        vol[c] = vol[c].astype(float)
    vol["filled_dots"] = vol["filled_dots"].astype("Int64")
    vol["watertight"] = vol["watertight"].astype("boolean")
    vol["reason"] = vol["reason"].fillna("").astype(object)
    strain_cols = ["frame", "time_s", "row", "col", "theta_rad", "z_mm", "e_zz", "e_tt", "e_tz"]
    strains = pd.concat(strain_parts, ignore_index=True)[strain_cols] if strain_parts else (
        pd.DataFrame({c: pd.Series(dtype="int64" if c in ("frame", "row", "col") else "float64")
                      for c in strain_cols})
    )  # fmt: skip
    return vol, strains.sort_values(["frame", "row", "col"], kind="stable").reset_index(drop=True)


def volume_meshes(
    points: pd.DataFrame,
    table: pd.DataFrame,
    design: dict,
    frames: list[int],
    out_dir: str | Path,
    t0: float | None = None,
    thickness_model: str = "area",
    refine: int = 2,
) -> Iterator[tuple[int, Path]]:
    """Write the soil surface (the membrane's inner surface closed by the pedestal faces, mm,
    cell frame) of each of ``frames`` as ``out_dir/frame_<frame>.ply``; yields ``(frame, path)``.
    The reference for the membrane's thinning is the first frame of ``points``."""
    if t0 is None:
        t0 = float(design["specimen"]["membrane_thickness"])
    first = int(points["frame"].min())
    grid0 = membrane_grid(points[points["frame"] == first], table)
    for frame in frames:
        pf = points[points["frame"] == frame]
        grid = membrane_grid(pf, table)
        thickness = membrane_thickness(grid, grid0, t0, model=thickness_model)
        vertices, triangles = closed_mesh(grid, top_cap(pf, table, design), refine, thickness, inner=True)
        path = Path(out_dir) / f"frame_{int(frame):06d}.ply"
        write_ply(path, vertices, triangles)
        yield int(frame), path
