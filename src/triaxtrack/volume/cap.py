"""The top cap's rigid pose from its coded targets (mm, cell frame)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from triaxtrack.kit import design_points, surface_by_name


def _readonly(a: np.ndarray) -> np.ndarray:
    """A read-only copy of ``a``."""
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


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
