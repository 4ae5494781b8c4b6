"""The smooth tensor interpolant of the membrane grid, its cuts by the face planes and the
closed ring meshes (mm, cell frame; see :mod:`triaxtrack.volume`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from triaxtrack.volume.cap import TopCap
from triaxtrack.volume.grid import MembraneGrid

GHOST_ROWS = 2  # rows extrapolated beyond each end row, for the spline's ends
GHOST_FIT_ROWS = 4  # end rows of the per-column least-squares quadratic that makes the ghosts
NEWTON_ITER = 30
NEWTON_TOL_MM = 1e-10


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
            thick = _node_field(grid, np.asarray(thickness), zg, theta_q)
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
