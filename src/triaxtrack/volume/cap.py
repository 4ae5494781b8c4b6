"""The top cap's rigid pose from its coded targets (mm, cell frame)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd

from triaxtrack.kit import design_points, surface_by_name
from triaxtrack.kit_design import KitDesign


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
    source: str = "coded targets"  # or "membrane top rows" (:func:`top_cap_from_membrane`)


def rigid_fit(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation R and translation t with ``dst ~ R src + t`` (Kabsch/Umeyama, no
    scale), from (n, 3) point pairs, n >= 3 not collinear."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    u, _, vt = np.linalg.svd((dst - cd).T @ (src - cs))
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1.0, 1.0, d]) @ vt
    return rot, cd - rot @ cs


def top_cap(points: pd.DataFrame, table: pd.DataFrame, design: KitDesign) -> TopCap:
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


MIN_CAP_COLUMNS = 8  # membrane columns with their two top rows measured, for a cap from them


def top_cap_from_membrane(points: pd.DataFrame, table: pd.DataFrame, design: KitDesign) -> TopCap:
    """The top cap's face from the membrane's topmost measured rows, where its coded targets are
    in no picture (a camera ring low down). The topmost row ``r`` with at least
    ``MIN_CAP_COLUMNS`` columns measured in it and in the row below gives, per such column, the
    face ``k = r - top + 0.5`` current row pitches above row ``r`` (the design puts the face half a
    pitch above the top row); a plane fitted to those points is the face. The cap is taken
    centred on the axis, its rotation the smallest that tilts z to the plane's normal.
    ``n_targets``: the columns used; ``rms_mm``: the plane's residual combined with the unknown
    strain over those ``k`` pitches (taken as large as the pitch's own change from the design),
    so that the volume's uncertainty carries it. ValueError when no row pair has enough columns."""
    mem = table[table["surface"] == "membrane"]
    xyz = points.dropna(subset=["x_mm", "y_mm", "z_mm"]).drop_duplicates("id").set_index("id")
    got = mem.assign(x=xyz["x_mm"].reindex(mem["id"]).to_numpy(), y=xyz["y_mm"].reindex(mem["id"]).to_numpy(),
                     z=xyz["z_mm"].reindex(mem["id"]).to_numpy()).dropna(subset=["z"])  # fmt: skip
    by_row = {int(r): g.set_index("col")[["x", "y", "z"]] for r, g in got.groupby("row")}
    design_z = mem.groupby("row")["z_mm"].first()
    top = int(mem["row"].min())
    for r in sorted(by_row):
        both = by_row[r].index.intersection(by_row[r + 1].index) if r + 1 in by_row else []
        if len(both) >= MIN_CAP_COLUMNS:
            break
    else:
        raise ValueError("fewer than 3 top-cap coded targets and no two membrane rows measured on "
                         f"{MIN_CAP_COLUMNS} columns: no top cap")  # fmt: skip
    p1, p2 = by_row[r].loc[both].to_numpy(float), by_row[r + 1].loc[both].to_numpy(float)
    k = r - top + 0.5
    face_pts = p1 + k * (p1 - p2)
    a = np.c_[np.ones(len(face_pts)), face_pts[:, :2]]
    coef, *_ = np.linalg.lstsq(a, face_pts[:, 2], rcond=None)
    plane_rms = float(np.sqrt(np.mean((a @ coef - face_pts[:, 2]) ** 2)))
    normal = np.array([-coef[1], -coef[2], 1.0]) / np.hypot(1.0, np.hypot(coef[1], coef[2]))
    axis = np.cross([0.0, 0.0, 1.0], normal)
    sin, cos = float(np.linalg.norm(axis)), float(normal[2])
    rot = np.eye(3) if sin < 1e-15 else cv2.Rodrigues(axis / sin * np.arctan2(sin, cos))[0]
    face = np.array([0.0, 0.0, coef[0]])
    z_face = float(surface_by_name(design)["pedestal_top"]["z_min"])
    trans = face - rot @ np.array([0.0, 0.0, z_face])
    pitch = float(np.median(p1[:, 2] - p2[:, 2]))
    dof = max(3 * len(both) - 6, 1)
    unknown = k * abs(pitch - float(design_z[r] - design_z[r + 1]))
    rms = float(np.hypot(plane_rms, unknown * np.sqrt(dof)))
    return TopCap(_readonly(rot), _readonly(trans), _readonly(face), _readonly(normal), float(face[2]),
                  len(both), rms, "membrane top rows")  # fmt: skip
