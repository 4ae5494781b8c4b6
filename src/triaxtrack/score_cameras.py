"""Scores of estimated cameras against the true ones: intrinsics (focal length, principal
point, undistortion map, ray directions) and poses (:func:`score_cameras`,
:func:`score_calibrations`); rows of :mod:`triaxtrack.score_table`."""

from __future__ import annotations

from collections.abc import Collection

import numpy as np
import pandas as pd

from triaxtrack.layout import RESULTS
from triaxtrack.optics import Camera, pixels_to_normalized, pixels_to_undistorted
from triaxtrack.score_table import COLUMNS, ScoreTolerances, _metric

UNDISTORTION_GRID_PX = 8  # spacing of the pixel grid the undistortion maps are compared on


def rotation_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices, degrees."""
    c = (np.trace(Ra.T @ Rb) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def pixel_grid(width: int, height: int, step_px: int = UNDISTORTION_GRID_PX) -> np.ndarray:
    """(N, 2) pixel positions every ``step_px`` over the whole image, the last row and column
    (``width - 1``, ``height - 1``) included."""
    u = np.unique(np.r_[np.arange(0, width, step_px), width - 1])
    v = np.unique(np.r_[np.arange(0, height, step_px), height - 1])
    uu, vv = np.meshgrid(u, v)
    return np.c_[uu.ravel(), vv.ravel()].astype(np.float64)


def undistortion_map_error(est: Camera, truth: Camera, step_px: int = UNDISTORTION_GRID_PX) -> float:
    """Largest difference, in pixels, between two cameras' undistortion maps over the whole image.

    A camera's undistortion map takes each pixel of its distorted image to where it lies in
    the undistorted image with the same camera matrix: ``K @ undistort(uv)``, i.e.
    ``cv2.undistortPoints(uv, K, dist, P=K)``, the inverse of the map that
    ``cv2.initUndistortRectifyMap(K, dist, None, K)`` builds for ``cv2.remap``. Both maps are
    evaluated at every pixel of :func:`pixel_grid` of the true image (its corners included,
    which a remapped image of the same size would crop), each with its own K and distortion;
    the result is the largest distance between the two undistorted positions. Errors of the
    focal length, principal point and distortion count in it as far as they change where a
    pixel maps to: a principal point shifted by p px (distortion unchanged, k1 = -0.3) moves
    the map by ~0 at the image centre and by up to ~p at the image corners. The direction of
    the ray through each pixel is :func:`ray_direction_error`. ``inf`` where either map
    cannot be inverted (:func:`triaxtrack.optics.pixels_to_normalized`).
    """
    uv = pixel_grid(truth.width, truth.height, step_px)
    err = np.linalg.norm(pixels_to_undistorted(est, uv) - pixels_to_undistorted(truth, uv), axis=1)
    return float(err.max()) if np.isfinite(err).all() else float("inf")


def ray_direction_error(est: Camera, truth: Camera, step_px: int = UNDISTORTION_GRID_PX) -> float:
    """Largest difference between two cameras' ray directions through the pixels of the image,
    in pixels of the true focal length (reported, not a pass limit).

    For every pixel of :func:`pixel_grid` of the true image, the undistorted normalised
    coordinates under the estimated and the true K and distortion are compared; the difference
    is scaled by the true focal lengths (fx for x, fy for y). Unlike
    :func:`undistortion_map_error`, the whole principal-point error counts in it at every
    pixel (and a focal-length error grows towards the image edges), so it is what a pose or a
    triangulation from these intrinsics sees. ``inf`` where either map cannot be inverted.
    """
    uv = pixel_grid(truth.width, truth.height, step_px)
    d = (pixels_to_normalized(est, uv) - pixels_to_normalized(truth, uv)) * [truth.K[0, 0], truth.K[1, 1]]
    err = np.hypot(d[:, 0], d[:, 1])
    return float(err.max()) if np.isfinite(err).all() else float("inf")


def score_cameras(
    result: dict[str, Camera], truth: dict[str, Camera], tol: ScoreTolerances, source: str = RESULTS.cameras,
    left_out: Collection[str] = (),
) -> pd.DataFrame:  # fmt: skip
    """Per-camera intrinsic and pose errors of estimated cameras against the true ones.

    A camera whose pose is the identity (intrinsics only, e.g. after calibration) is scored on
    its intrinsics alone. Cameras missing from, or unknown to, the truth fail.
    """
    rows = []
    for name, cam in sorted(result.items()):
        if name not in truth:
            rows.append(_metric("camera_unknown", name, np.nan, source=source))
            continue
        tr = truth[name]
        f_err = max(abs(cam.K[0, 0] / tr.K[0, 0] - 1), abs(cam.K[1, 1] / tr.K[1, 1] - 1))
        pp = float(np.hypot(cam.K[0, 2] - tr.K[0, 2], cam.K[1, 2] - tr.K[1, 2]))
        rows.append(_metric("focal_rel_error", name, f_err, tol.focal_rel, source=source))
        rows.append(_metric("principal_point_error", name, pp, tol.principal_point_px, "px", source))
        if not (np.allclose(cam.R, np.eye(3)) and np.allclose(cam.t, 0)):
            dc = float(np.linalg.norm(cam.center - tr.center))
            rows.append(_metric("camera_center_error", name, dc, tol.camera_center_mm, "mm", source))
            rot = rotation_angle_deg(cam.R, tr.R)
            rows.append(_metric("camera_rotation_error", name, rot, tol.camera_rotation_deg, "deg", source))
    for name in sorted(set(truth) - set(result)):  # a camera the workflow left out and said so: reported
        if name in left_out:
            why = "why: quality.json"
            rows.append(_metric("camera_left_out", name, 1.0, unit=why, source=RESULTS.quality))
        else:
            rows.append(_metric("camera_missing", name, np.nan, source=source))
    return pd.DataFrame(rows, columns=COLUMNS)


def score_calibrations(
    result: dict[str, Camera], truth: dict[str, Camera], tol: ScoreTolerances,
    left_out: Collection[str] = (),
) -> pd.DataFrame:  # fmt: skip
    """Per-camera errors of calibrated intrinsics (identity poses) against the true cameras:
    ``focal_rel_error``, ``principal_point_error``, ``undistortion_map_error``
    (:func:`undistortion_map_error`, tolerance ``undistortion_px``) and, reported only,
    ``ray_direction_error`` (:func:`ray_direction_error`). A calibration whose image size is not
    the true camera's gets a failing ``image_size_mismatch`` row instead of the two map rows;
    cameras missing from, or unknown to, the truth fail, but for those the workflow left out
    (``left_out``: quality.json ``cameras_left_out``), reported as in :func:`score_cameras`."""
    df = score_cameras(result, truth, tol, left_out=left_out)
    said = df["metric"] == "camera_left_out"
    df.loc[~said, "source"] = [RESULTS.calibration.format(camera=c) for c in df.loc[~said, "item"]]
    rows = []
    for name, cam in sorted(result.items()):
        if name not in truth:
            continue
        tr = truth[name]
        source = f"calibration/{name}.json"
        if (cam.width, cam.height) != (tr.width, tr.height):
            rows.append(_metric("image_size_mismatch", name, np.nan, source=source))
            continue
        err = undistortion_map_error(cam, tr)
        rows.append(_metric("undistortion_map_error", name, err, tol.undistortion_px, "px", source))
        rows.append(
            _metric("ray_direction_error", name, ray_direction_error(cam, tr), unit="px", source=source)
        )
    out = pd.concat([df, pd.DataFrame(rows, columns=COLUMNS)], ignore_index=True)
    order = {"camera_unknown": 0, "focal_rel_error": 1, "principal_point_error": 2}
    key = out.metric.map(order).fillna(3)
    return (
        out.assign(_k=key)
        .sort_values(["item", "_k"], kind="stable")
        .drop(columns="_k")
        .reset_index(drop=True)
    )
