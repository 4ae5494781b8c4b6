"""Camera model and refraction through the acrylic cell.

Cameras follow OpenCV: ``x_cam = R @ x_cell + t``, pinhole ``K`` and Brown-Conrady distortion in
OpenCV's order ``(k1, k2, p1, p2, k3[, k4, k5, k6])``; pixel centres at integer coordinates.
The cell is a coaxial acrylic tube around the z axis (``outer_radius`` > ``inner_radius``),
air outside, water inside. A ray from a camera that reaches the water refracts by Snell's law
at the outer wall (air to acrylic) and at the inner wall (acrylic to water).

Points in the water are projected exactly: :func:`project_water` solves for the camera ray
whose refracted continuation passes through the point (Gauss-Newton on the two normalised image
coordinates, converged to 1e-8 mm) and then applies OpenCV's distortion.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

NEWTON_MAX_ITER = 30
NEWTON_TOL_MM = 1e-8  # point-to-ray distance accepted as converged (~3e-8 px at 300 mm)
FD_STEP = 1e-7  # finite-difference step in normalised image coordinates


@dataclass(frozen=True)
class Camera:
    """One calibrated camera (OpenCV conventions, millimetres, cell frame)."""

    name: str
    width: int
    height: int
    K: np.ndarray  # (3, 3)
    dist: np.ndarray  # (5,) or more, OpenCV order
    R: np.ndarray  # (3, 3) cell -> camera rotation
    t: np.ndarray  # (3,) translation, mm

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in the cell frame, mm."""
        return -self.R.T @ self.t

    def to_json(self) -> dict:
        return {
            "width": int(self.width),
            "height": int(self.height),
            "K": np.asarray(self.K, float).tolist(),
            "dist": np.asarray(self.dist, float).tolist(),
            "R": np.asarray(self.R, float).tolist(),
            "t": np.asarray(self.t, float).reshape(3).tolist(),
        }

    @staticmethod
    def from_json(name: str, d: dict) -> Camera:
        return Camera(
            name=name,
            width=int(d["width"]),
            height=int(d["height"]),
            K=np.array(d["K"], float),
            dist=np.array(d["dist"], float),
            R=np.array(d["R"], float),
            t=np.array(d["t"], float).reshape(3),
        )


@dataclass(frozen=True)
class CellOptics:
    """The refracting cell: radii in mm, refractive indices (dimensionless)."""

    outer_radius: float
    inner_radius: float
    n_acrylic: float
    n_water: float
    z_min: float = -np.inf
    z_max: float = np.inf
    n_air: float = field(default=1.0)


def project_air(camera: Camera, points_mm: np.ndarray) -> np.ndarray:
    """(N, 2) distorted pixel coordinates of (N, 3) cell-frame points seen in air."""
    pts = np.asarray(points_mm, np.float64).reshape(-1, 1, 3)
    if len(pts) == 0:
        return np.zeros((0, 2))
    rvec, _ = cv2.Rodrigues(camera.R)
    uv, _ = cv2.projectPoints(pts, rvec, camera.t.astype(np.float64), camera.K, camera.dist)
    return uv.reshape(-1, 2)


def normalized_to_pixels(camera: Camera, xy: np.ndarray) -> np.ndarray:
    """(N, 2) pixels of (N, 2) undistorted normalised coordinates (x / z, y / z)."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if len(xy) == 0:
        return np.zeros((0, 2))
    pts = np.c_[xy, np.ones(len(xy))].reshape(-1, 1, 3)
    uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), camera.K, camera.dist)
    return uv.reshape(-1, 2)


def intersect_cylinder(origins: np.ndarray, dirs: np.ndarray, radius: float, entering: bool) -> np.ndarray:
    """Ray parameter s > 0 where ``origins + s dirs`` meets the z-axis cylinder of ``radius``.

    ``entering`` picks the first crossing (from outside) or the second (leaving from inside).
    NaN where the ray misses. ``dirs`` need not be unit length.
    """
    a = dirs[:, 0] * dirs[:, 0] + dirs[:, 1] * dirs[:, 1]
    b = 2 * (origins[:, 0] * dirs[:, 0] + origins[:, 1] * dirs[:, 1])
    c = origins[:, 0] ** 2 + origins[:, 1] ** 2 - radius**2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(disc)
        s = (-b - sq) / (2 * a) if entering else (-b + sq) / (2 * a)
    return np.where((disc >= 0) & (a > 0), s, np.nan)


def refract(dirs: np.ndarray, normals: np.ndarray, n1: float, n2: float) -> np.ndarray:
    """Refract unit ``dirs`` at surfaces with unit ``normals`` (either side), index n1 -> n2.

    Vector Snell's law; NaN rows on total internal reflection.
    """
    cosi = -(dirs * normals).sum(axis=1)
    nrm = np.where(cosi[:, None] < 0, -normals, normals)
    cosi = np.abs(cosi)
    eta = n1 / n2
    k = 1 - eta**2 * (1 - cosi**2)
    with np.errstate(invalid="ignore"):
        out = eta * dirs + (eta * cosi - np.sqrt(k))[:, None] * nrm
    out[k < 0] = np.nan
    return out / np.sqrt((out * out).sum(axis=1))[:, None]


@dataclass(frozen=True)
class WaterPath:
    """A camera ray traced into the water (all arrays have N rows, NaN where invalid)."""

    outer_hit: np.ndarray  # (N, 3) point on the outer wall
    inner_hit: np.ndarray  # (N, 3) point on the inner wall (origin of the ray in water)
    dir_air: np.ndarray  # (N, 3) unit direction in air
    dir_acrylic: np.ndarray  # (N, 3)
    dir_water: np.ndarray  # (N, 3)


def _radial_normals(p: np.ndarray) -> np.ndarray:
    r = np.sqrt(p[:, 0] ** 2 + p[:, 1] ** 2)
    return np.stack([p[:, 0] / r, p[:, 1] / r, np.zeros(len(p))], axis=1)


def trace_into_water(camera: Camera, xy: np.ndarray, cell: CellOptics) -> WaterPath:
    """Trace rays through normalised undistorted image coordinates ``xy`` (N, 2) into the water."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    R = camera.R
    # d = R.T @ (x, y, 1), normalised
    d = xy[:, :1] * R[0] + xy[:, 1:2] * R[1] + R[2]
    d /= np.sqrt((d * d).sum(axis=1))[:, None]
    c = np.broadcast_to(camera.center, d.shape)
    s1 = intersect_cylinder(c, d, cell.outer_radius, entering=True)
    p1 = c + s1[:, None] * d
    outside_cell = (p1[:, 2] < cell.z_min) | (p1[:, 2] > cell.z_max)
    p1[outside_cell] = np.nan
    d1 = refract(d, _radial_normals(p1), cell.n_air, cell.n_acrylic)
    s2 = intersect_cylinder(p1, d1, cell.inner_radius, entering=True)
    p2 = p1 + s2[:, None] * d1
    d2 = refract(d1, _radial_normals(p2), cell.n_acrylic, cell.n_water)
    return WaterPath(p1, p2, d, d1, d2)


def _residual(path: WaterPath, points: np.ndarray) -> np.ndarray:
    """Offset (N, 3) of each point from its ray in the water, perpendicular to the ray."""
    v = points - path.inner_hit
    along = (v * path.dir_water).sum(axis=1)
    return v - along[:, None] * path.dir_water


def solve_water_rays(
    camera: Camera,
    points_mm: np.ndarray,
    cell: CellOptics,
    xy0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised image coordinates of the refracted rays through points in the water.

    Parameters
    ----------
    points_mm : (N, 3) cell-frame points inside the inner wall.
    xy0 : optional (N, 2) starting guesses (e.g. last frame's solution); by default the
        straight-line pinhole projection.

    Returns
    -------
    xy : (N, 2) normalised undistorted coordinates, NaN where no refracted path exists
        (outside the cell's z range, behind the camera, total internal reflection).
    dir_water : (N, 3) unit direction of each ray in the water (NaN where none).
    converged : (N,) bool.
    """
    pts = np.asarray(points_mm, np.float64).reshape(-1, 3)
    n = len(pts)
    pc = pts @ camera.R.T + camera.t
    with np.errstate(invalid="ignore", divide="ignore"):
        guess = pc[:, :2] / pc[:, 2:3]
    guess[pc[:, 2] <= 0] = np.nan
    if xy0 is None:
        xy = guess
    else:
        xy = np.array(xy0, np.float64, copy=True).reshape(-1, 2)
        cold = ~np.isfinite(xy).all(axis=1)
        xy[cold] = guess[cold]
    active = np.isfinite(xy).all(axis=1)
    converged = np.zeros(n, bool)
    d2 = np.full((n, 3), np.nan)
    p2 = np.full((n, 3), np.nan)
    for _ in range(NEWTON_MAX_ITER):
        idx = np.flatnonzero(active & ~converged)
        if idx.size == 0:
            break
        q = xy[idx]
        path = trace_into_water(camera, q, cell)
        r0 = _residual(path, pts[idx])
        res = np.sqrt((r0 * r0).sum(axis=1))
        done = res < NEWTON_TOL_MM
        converged[idx[done]] = True
        d2[idx[done]] = path.dir_water[done]
        p2[idx[done]] = path.inner_hit[done]
        idx, q, r0 = idx[~done], q[~done], r0[~done]
        if idx.size == 0:
            break
        jx = (_residual(trace_into_water(camera, q + [FD_STEP, 0.0], cell), pts[idx]) - r0) / FD_STEP
        jy = (_residual(trace_into_water(camera, q + [0.0, FD_STEP], cell), pts[idx]) - r0) / FD_STEP
        a11 = (jx * jx).sum(axis=1)
        a12 = (jx * jy).sum(axis=1)
        a22 = (jy * jy).sum(axis=1)
        b1 = -(jx * r0).sum(axis=1)
        b2 = -(jy * r0).sum(axis=1)
        det = a11 * a22 - a12**2
        with np.errstate(invalid="ignore", divide="ignore"):
            dx = (a22 * b1 - a12 * b2) / det
            dy = (a11 * b2 - a12 * b1) / det
        bad = ~np.isfinite(dx) | ~np.isfinite(dy) | ~np.isfinite(r0).all(axis=1)
        active[idx[bad]] = False
        ok = ~bad
        xy[idx[ok]] += np.c_[dx[ok], dy[ok]]
    # the refracted ray must reach the point going forwards
    ahead = ((pts - p2) * d2).sum(axis=1) > 0
    converged &= ahead
    xy[~converged] = np.nan
    d2[~converged] = np.nan
    return xy, d2, converged


def project_water(
    camera: Camera,
    points_mm: np.ndarray,
    cell: CellOptics,
    xy0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact distorted pixel coordinates of (N, 3) points in the water.

    Returns ``(uv_px, dir_water, xy)``: (N, 2) pixels (NaN where not imaged), (N, 3) unit ray
    directions in the water at the point (pointing away from the camera), and the (N, 2)
    normalised coordinates (usable as ``xy0`` for the next frame).
    """
    xy, d2, ok = solve_water_rays(camera, points_mm, cell, xy0)
    uv = np.full((len(xy), 2), np.nan)
    if ok.any():
        uv[ok] = normalized_to_pixels(camera, xy[ok])
    return uv, d2, xy
