"""The cell's frames: the similarity that maps reconstructed points onto their design
positions, the cylinder fitted to the cell wall's targets, and the rigid motion that puts its
axis on the z axis (steps 3 and 4 of :mod:`triaxtrack.sfm`). Pure geometry, millimetres."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd
from scipy.optimize import least_squares


@dataclass(frozen=True)
class Cylinder:
    """A fitted cylinder: a point on its axis and the axis direction (unit), mm."""

    point: np.ndarray  # (3,)
    direction: np.ndarray  # (3,)
    radius: float
    rms_mm: float  # RMS distance of the points from the surface


def similarity_transform(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity ``dst ~ s A src + b`` of two (N, 3) point sets (Umeyama 1991).
    Returns ``(s, A, b)``, ``A`` a proper rotation."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - ms, dst - md
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    A = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / (a**2).sum(axis=1).mean())
    return s, A, md - s * A @ ms


def transform_points(
    points: pd.DataFrame, scale: float, rotation: np.ndarray, translation: np.ndarray
) -> pd.DataFrame:
    """A copy of ``points`` (columns ``x_mm, y_mm, z_mm``) moved by ``x' = s A x + b``."""
    xyz = points[["x_mm", "y_mm", "z_mm"]].to_numpy(float)
    new = scale * xyz @ np.asarray(rotation, float).T + np.asarray(translation, float).reshape(3)
    return points.assign(x_mm=new[:, 0], y_mm=new[:, 1], z_mm=new[:, 2])


def fit_cylinder(points_mm: np.ndarray, direction0: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> Cylinder:
    """Least-squares cylinder through (N, 3) points, axis near ``direction0``.

    The axis is parametrised by its point in the plane through the centroid normal to
    ``direction0`` and two small tilts; residuals are distances to the surface, mm.
    """
    pts = np.asarray(points_mm, float)
    d0 = np.asarray(direction0, float) / np.linalg.norm(direction0)
    e1 = np.cross(d0, [1.0, 0.0, 0.0] if abs(d0[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d0, e1)
    c0 = pts.mean(axis=0)

    def axis(p):
        d = d0 + p[2] * e1 + p[3] * e2
        return c0 + p[0] * e1 + p[1] * e2, d / np.linalg.norm(d)

    def resid(p):
        o, d = axis(p)
        v = pts - o
        radial = v - np.outer(v @ d, d)
        return np.sqrt((radial**2).sum(axis=1)) - p[4]

    v = pts - c0
    r0 = float(np.sqrt(((v - np.outer(v @ d0, d0)) ** 2).sum(axis=1)).mean())
    sol = least_squares(resid, np.array([0.0, 0.0, 0.0, 0.0, r0]), x_scale=[1.0, 1.0, 1e-3, 1e-3, 1.0])
    o, d = axis(sol.x)
    return Cylinder(o, d, float(sol.x[4]), float(np.sqrt(np.mean(sol.fun**2))))


def axis_frame(
    cylinder: Cylinder, origin_near: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """The rigid motion ``x' = A x + b`` that puts the cylinder's axis on the z axis (keeping its
    sense) with the point of the axis nearest ``origin_near`` at the origin, by the smallest
    rotation. Returns ``(A, b)``."""
    d = cylinder.direction / np.linalg.norm(cylinder.direction)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(d, z)
    s, c = np.linalg.norm(axis), float(d @ z)
    A = np.eye(3) if s < 1e-15 else cv2.Rodrigues(axis / s * np.arctan2(s, c))[0]
    foot = cylinder.point + ((np.asarray(origin_near, float) - cylinder.point) @ d) * d
    return A, -A @ foot
