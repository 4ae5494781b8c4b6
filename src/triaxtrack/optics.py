"""Camera model and refraction through the acrylic cell.

Cameras follow OpenCV: ``x_cam = R @ x_cell + t``, pinhole ``K`` and Brown-Conrady distortion in
OpenCV's order ``(k1, k2, p1, p2, k3[, k4, k5, k6])``; pixel centres at integer coordinates.
The cell is a coaxial acrylic tube around the z axis (``outer_radius`` > ``inner_radius``),
air outside, water inside. A ray from a camera that reaches the water refracts by Snell's law
at the outer wall (air to acrylic) and at the inner wall (acrylic to water).

Points in the water are projected exactly: :func:`project_water` solves for the camera ray
whose refracted continuation passes through the point (Gauss-Newton on the two normalised image
coordinates, converged to 1e-6 mm) and then applies OpenCV's distortion.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from triaxtrack.config_section import section_from_dict
from triaxtrack.kit_design import KitDesign
from triaxtrack.testfolder import read_cameras_doc, write_cameras_doc

NEWTON_MAX_ITER = 30
NEWTON_TOL_MM = 1e-6  # point-to-ray distance accepted as converged (~3e-6 px at 300 mm)
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

    def transformed(self, scale: float, rotation: np.ndarray, translation: np.ndarray) -> Camera:
        """The same camera after the world moves by the similarity ``x' = s A x + b``.

        Its image of every point is unchanged: ``R' = R A^T`` and ``t' = s t - R' b`` (the camera
        frame is scaled by ``s`` with the world, so ``t`` stays in the new world's units)."""
        A = np.asarray(rotation, float)
        R = self.R @ A.T
        t = scale * self.t - R @ np.asarray(translation, float).reshape(3)
        return Camera(self.name, self.width, self.height, self.K, self.dist, R, t)

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


def read_cameras(path: str | Path) -> dict[str, Camera]:
    """The cameras of a ``cameras.json`` (``test-folder.md``); ValueError naming the file."""
    cams = read_cameras_doc(path)
    try:
        return {k: Camera.from_json(k, v) for k, v in cams.items()}
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{path}: not a cameras.json: {err}") from err


def write_cameras(path: str | Path, cameras: dict[str, Camera]) -> None:
    """Write ``cameras`` (name -> :class:`Camera`, in the order given) as a ``cameras.json``
    (``test-folder.md``), the file :func:`read_cameras` reads."""
    write_cameras_doc(path, {name: cam.to_json() for name, cam in cameras.items()})


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


@dataclass(frozen=True)
class CellConfig:
    """Settings of config section ``cell`` (config/README.md): the acrylic cell and the water,
    each None for the kit's value (``kit.json``: ``cell``, ``water``)."""

    wall_thickness_mm: float | None = None  # None: the kit's (inner radius = fitted outer radius - this)
    n_acrylic: float | None = None  # None: the kit's (PMMA at 589 nm, 20 C: 1.491)
    n_water: float | None = None  # None: the kit's (water at 589 nm, 20 C: 1.333)
    wavelength_nm: float | None = None  # the wavelength the indices hold for; None: the kit's
    temperature_c: float | None = None  # the temperature the indices hold for; None: the kit's

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> CellConfig:
        """From the config's ``cell`` section (ValueError naming an unknown key)."""
        return section_from_dict(CellConfig, d, "cell")


def cell_optics(
    design: KitDesign,
    outer_radius: float | None = None,
    wall_thickness_mm: float | None = None,
    n_acrylic: float | None = None,
    n_water: float | None = None,
) -> CellOptics:
    """The cell of a kit design (``kit.json``: ``cell`` radii, height and acrylic index, ``water``
    index), each value replaced by the argument given for it (``None``: the design's). The inner
    radius is ``outer_radius - wall_thickness_mm``."""
    c = design.cell
    outer = c.outer_radius if outer_radius is None else outer_radius
    wall = c.outer_radius - c.inner_radius if wall_thickness_mm is None else wall_thickness_mm
    return CellOptics(
        outer_radius=float(outer),
        inner_radius=float(outer - wall),
        n_acrylic=float(c.refractive_index if n_acrylic is None else n_acrylic),
        n_water=float(design.water.refractive_index if n_water is None else n_water),
        z_min=c.z_min,
        z_max=c.z_max,
    )


def configured_cell(design: KitDesign, cell: CellConfig, outer_radius: float | None = None) -> CellOptics:
    """:func:`cell_optics` of a kit design with the config's ``cell`` section (``cell``:
    ``wall_thickness_mm``, ``n_acrylic``, ``n_water``, each None for the design's) and, if
    given, a measured ``outer_radius`` (mm)."""
    return cell_optics(
        design,
        outer_radius=outer_radius,
        wall_thickness_mm=cell.wall_thickness_mm,
        n_acrylic=cell.n_acrylic,
        n_water=cell.n_water,
    )


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


# cv2.undistortPoints iterates a fixed-point scheme; its default (5 iterations) leaves up to
# ~1 px at the corners of a k1 = -0.3 lens, so iterate to convergence instead (opencv 5 has
# no undistortPointsIter; undistortPoints takes the criteria)
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
UNDISTORT_TOL_PX = 1e-3  # round-trip error above which a point counts as not undistorted


def pixels_to_normalized(camera: Camera, uv_px: np.ndarray) -> np.ndarray:
    """(N, 2) undistorted normalised coordinates (x / z, y / z) of (N, 2) distorted pixels.

    The inverse of :func:`normalized_to_pixels`, checked point by point: where re-distorting
    the result misses the input by more than ``UNDISTORT_TOL_PX`` (the iteration did not
    converge, e.g. outside the region where the distortion polynomial is invertible) the row
    is NaN.
    """
    uv = np.asarray(uv_px, np.float64).reshape(-1, 2)
    if len(uv) == 0:
        return np.zeros((0, 2))
    K = np.asarray(camera.K, np.float64)
    dist = np.asarray(camera.dist, np.float64)
    xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist, None, None, None, UNDISTORT_CRITERIA)
    xy = xy.reshape(-1, 2)
    back = normalized_to_pixels(camera, xy)
    miss = ~(np.linalg.norm(back - uv, axis=1) <= UNDISTORT_TOL_PX)
    xy[miss] = np.nan
    return xy


def pixels_to_undistorted(camera: Camera, uv_px: np.ndarray) -> np.ndarray:
    """(N, 2) undistorted pixels ``K @ undistort(uv)`` of (N, 2) distorted pixels, in the camera's
    own K: ``cv2.undistortPoints(uv, K, dist, P=K)`` (NaN where :func:`pixels_to_normalized` is)."""
    K = np.asarray(camera.K, np.float64)
    return pixels_to_normalized(camera, uv_px) @ K[:2, :2].T + K[:2, 2]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of two (N, 3) arrays (einsum: several times faster than sum(axis=1))."""
    return np.einsum("ij,ij->i", a, b)


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
    return np.where((disc >= 0) & (a > 0) & (s > 0), s, np.nan)


def refract(dirs: np.ndarray, normals: np.ndarray, n1: float, n2: float) -> np.ndarray:
    """Refract unit ``dirs`` at surfaces with unit ``normals`` (either side), index n1 -> n2.

    Vector Snell's law; NaN rows on total internal reflection.
    """
    cosi = -_dot(dirs, normals)
    nrm = np.where(cosi[:, None] < 0, -normals, normals)
    cosi = np.abs(cosi)
    eta = n1 / n2
    k = 1 - eta**2 * (1 - cosi**2)
    with np.errstate(invalid="ignore"):
        out = eta * dirs + (eta * cosi - np.sqrt(k))[:, None] * nrm
    out[k < 0] = np.nan
    return out / np.sqrt(_dot(out, out))[:, None]


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
    d /= np.sqrt(_dot(d, d))[:, None]
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
    along = _dot(v, path.dir_water)
    return v - along[:, None] * path.dir_water


@dataclass(frozen=True)
class WaterSolution:
    """Refracted rays through points in the water (N rows; NaN where there is none)."""

    xy: np.ndarray  # (N, 2) normalised undistorted image coordinates
    dir_water: np.ndarray  # (N, 3) unit ray direction in the water, away from the camera
    converged: np.ndarray  # (N,) bool
    pinv: np.ndarray  # (N, 2, 3) pseudo-inverse of d(offset)/d(xy): reusable as ``pinv0``


def solve_water_rays(
    camera: Camera,
    points_mm: np.ndarray,
    cell: CellOptics,
    xy0: np.ndarray | None = None,
    pinv0: np.ndarray | None = None,
) -> WaterSolution:
    """Normalised image coordinates of the refracted rays through points in the water.

    Gauss-Newton on the point's offset from the traced ray, with finite-difference Jacobians;
    converged when the point is within ``NEWTON_TOL_MM`` of its refracted ray.
    With ``pinv0`` (the ``pinv`` of a previous solve for nearby points, e.g. the last frame) the
    iteration first takes chord steps with it (one ray trace per step) and recomputes the
    Jacobian only for points that have not converged after two such steps.

    Parameters
    ----------
    points_mm : (N, 3) cell-frame points inside the inner wall.
    xy0 : optional (N, 2) starting guesses; by default (and where NaN) the straight-line pinhole
        projection.
    pinv0 : optional (N, 2, 3) Jacobian pseudo-inverses to start from.
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
    pinv = np.full((n, 2, 3), np.nan) if pinv0 is None else np.array(pinv0, np.float64, copy=True)
    fresh = np.zeros(n, bool)
    chord_steps = np.zeros(n, np.int64)
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
        done = np.sqrt(_dot(r0, r0)) < NEWTON_TOL_MM
        converged[idx[done]] = True
        d2[idx[done]] = path.dir_water[done]
        p2[idx[done]] = path.inner_hit[done]
        idx, q, r0 = idx[~done], q[~done], r0[~done]
        if idx.size == 0:
            break
        stale = ~np.isfinite(pinv[idx]).all(axis=(1, 2)) | (~fresh[idx] & (chord_steps[idx] >= 2))
        if stale.any():
            k, qk, rk = idx[stale], q[stale], r0[stale]
            jx = (_residual(trace_into_water(camera, qk + [FD_STEP, 0.0], cell), pts[k]) - rk) / FD_STEP
            jy = (_residual(trace_into_water(camera, qk + [0.0, FD_STEP], cell), pts[k]) - rk) / FD_STEP
            a11, a12, a22 = _dot(jx, jx), _dot(jx, jy), _dot(jy, jy)
            with np.errstate(invalid="ignore", divide="ignore"):
                inv_det = 1.0 / (a11 * a22 - a12**2)
            # (J^T J)^-1 J^T with J = [jx jy] (3 x 2)
            pinv[k, 0] = (a22 * inv_det)[:, None] * jx - (a12 * inv_det)[:, None] * jy
            pinv[k, 1] = (a11 * inv_det)[:, None] * jy - (a12 * inv_det)[:, None] * jx
            fresh[k] = True
        step = -np.einsum("kij,kj->ki", pinv[idx], r0)
        chord_steps[idx] += 1
        bad = ~np.isfinite(step).all(axis=1)
        active[idx[bad]] = False
        xy[idx[~bad]] += step[~bad]
    # the refracted ray must reach the point going forwards
    converged &= _dot(pts - p2, d2) > 0
    xy[~converged] = np.nan
    d2[~converged] = np.nan
    return WaterSolution(xy, d2, converged, pinv)


def project_water(
    camera: Camera,
    points_mm: np.ndarray,
    cell: CellOptics,
    xy0: np.ndarray | None = None,
    pinv0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, WaterSolution]:
    """Exact distorted pixel coordinates of (N, 3) points in the water.

    Returns ``(uv_px, dir_water, solution)``: (N, 2) pixels (NaN where not imaged), (N, 3) unit
    ray directions in the water at the point (pointing away from the camera), and the
    :class:`WaterSolution` (its ``xy`` and ``pinv`` warm-start the next frame's solve).
    """
    sol = solve_water_rays(camera, points_mm, cell, xy0, pinv0)
    uv = np.full((len(sol.xy), 2), np.nan)
    if sol.converged.any():
        uv[sol.converged] = normalized_to_pixels(camera, sol.xy[sol.converged])
    return uv, sol.dir_water, sol
