"""Camera poses from targets in the water, through the refractive cell wall.

A camera that labels too few cell-wall targets (printed on the outside of the cell, seen in air)
for :func:`triaxtrack.sfm.initial_poses` is posed here from every target it labelled whose
position is known: the cell-wall targets it has (seen in air) and the targets in the water (the
pedestals' coded targets and the membrane dots at their design positions: at the reference frame
the specimen is undeformed), seen through the wall of a given cell
(:class:`triaxtrack.optics.CellOptics`, coaxial with the z axis of the frame of the design
positions):

1. a first pose by PnP (RANSAC with a loose threshold, ``INITIAL_RANSAC_PX``) as if every target
   were in air: the wall bends the rays by a few degrees at most, so the straight-line pose is
   near the refractive one (:func:`straight_line_pose`);
2. the pose refined by minimising the exact reprojection error (air: OpenCV projection; water:
   :func:`triaxtrack.optics.project_water`, Snell's law at both walls) with scipy's
   ``least_squares``, first with a robust loss, then, after dropping the observations whose
   residual exceeds ``ransac_px``, by plain least squares (:func:`refine_pose`).

A camera is posed when at least ``min_targets`` targets remain and they are well spread in the
image (:func:`image_spread_px`). Millimetres in the frame of the design positions; pixels in
OpenCV's convention (the centre of the top-left pixel is (0, 0)); ``x_cam = R x + t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from triaxtrack.optics import Camera, CellOptics, pixels_to_normalized, project_air, project_water

INITIAL_RANSAC_PX = 40.0  # straight-line PnP inlier threshold: the wall shifts images by up to tens of px
MIN_SPREAD_FRACTION = 0.05  # targets must spread over >= this x the image's shorter side (smallest std)
MAX_FIT_POINTS = 400  # observations used by the iterative refinement (spread over the IDs): speed
UNPROJECTED_PX = 50.0  # residual of an observation whose point no longer projects through the wall
DIFF_STEP = 1e-6  # relative finite-difference step (project_water converges to ~3e-6 px)
ROBUST_ROUNDS = 2  # refinement rounds: soft-L1 loss first, then plain least squares on the inliers


@dataclass(frozen=True)
class PoseObservations:
    """What a camera labelled with known positions: ``xyz`` (N, 3) mm, ``uv`` (N, 2) distorted
    pixels, ``in_water`` (N,) bool (False: seen in air), ``ids`` (N,) target IDs."""

    ids: np.ndarray
    xyz: np.ndarray
    uv: np.ndarray
    in_water: np.ndarray


@dataclass(frozen=True)
class RefractivePose:
    """A camera posed by :func:`pose_camera`: the camera, its residuals (N, 2; projection minus
    observation, NaN where the point does not project), which observations were used, and their
    RMS residual, px."""

    camera: Camera
    residuals: np.ndarray
    used: np.ndarray
    rms_px: float


def image_spread_px(uv: np.ndarray) -> float:
    """The spread of (N, 2) image points: the standard deviation along their narrowest
    direction, px (0 for fewer than three points). Collinear or clumped targets fix a pose badly."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    if len(uv) < 3:
        return 0.0
    return float(np.sqrt(max(np.linalg.eigvalsh(np.cov(uv.T))[0], 0.0)))


def min_spread_px(camera: Camera) -> float:
    """The smallest :func:`image_spread_px` accepted for a pose of ``camera``, px."""
    return MIN_SPREAD_FRACTION * min(camera.width, camera.height)


def with_pose(camera: Camera, rvec: np.ndarray, tvec: np.ndarray) -> Camera:
    """``camera`` with the pose of a Rodrigues vector and a translation (mm)."""
    R = cv2.Rodrigues(np.asarray(rvec, float).reshape(3))[0]
    return Camera(
        camera.name, camera.width, camera.height, camera.K, camera.dist, R, np.asarray(tvec, float).reshape(3)
    )


def project(
    camera: Camera, obs: PoseObservations, cell: CellOptics, xy0: np.ndarray | None = None
) -> np.ndarray:
    """(N, 2) pixels of the observed targets: in air straight, in water through the wall (NaN
    where the point does not project). ``xy0``: (N, 2) normalised starting guesses of the water
    rays (e.g. the undistorted observations)."""
    uv = np.full((len(obs.ids), 2), np.nan)
    air = ~obs.in_water
    if air.any():
        uv[air] = project_air(camera, obs.xyz[air])
    if obs.in_water.any():
        guess = None if xy0 is None else xy0[obs.in_water]
        uv[obs.in_water] = project_water(camera, obs.xyz[obs.in_water], cell, xy0=guess)[0]
    return uv


def pnp_pose(
    camera: Camera, xyz: np.ndarray, uv: np.ndarray, ransac_px: float
) -> tuple[Camera, np.ndarray] | None:
    """``camera`` posed by PnP on (N, 3) points (mm) and their (N, 2) pixels: RANSAC (SQPnP,
    inliers within ``ransac_px``), then Levenberg-Marquardt on the inliers; returns the camera
    and the inlier mask, or None when PnP fails or keeps fewer than 4 points."""
    if len(xyz) < 4:
        return None
    ok, rvec, tvec, inl = cv2.solvePnPRansac(
        xyz, uv, camera.K, camera.dist, reprojectionError=ransac_px, flags=cv2.SOLVEPNP_SQPNP
    )
    if not ok or inl is None or len(inl) < 4:
        return None
    inlier = np.zeros(len(xyz), bool)
    inlier[inl.ravel()] = True
    rvec, tvec = cv2.solvePnPRefineLM(xyz[inlier], uv[inlier], camera.K, camera.dist, rvec, tvec)
    return with_pose(camera, rvec, tvec), inlier


def straight_line_pose(camera: Camera, obs: PoseObservations) -> tuple[Camera, np.ndarray] | None:
    """A first pose by :func:`pnp_pose` ignoring the refraction (``INITIAL_RANSAC_PX``)."""
    return pnp_pose(camera, obs.xyz, obs.uv, INITIAL_RANSAC_PX)


def _subset(obs: PoseObservations, keep: np.ndarray) -> PoseObservations:
    return PoseObservations(obs.ids[keep], obs.xyz[keep], obs.uv[keep], obs.in_water[keep])


def _spread_sample(n: int, keep: np.ndarray, limit: int) -> np.ndarray:
    """``keep`` with at most ``limit`` True entries, evenly spaced over the True ones."""
    idx = np.flatnonzero(keep)
    if len(idx) <= limit:
        return keep
    out = np.zeros(n, bool)
    out[idx[np.linspace(0, len(idx) - 1, limit).round().astype(int)]] = True
    return out


def refine_pose(
    camera: Camera, obs: PoseObservations, cell: CellOptics, use: np.ndarray, robust_px: float | None
) -> Camera:
    """The pose of ``camera`` minimising the exact reprojection error of observations ``use``
    (at most ``MAX_FIT_POINTS`` of them, spread over the list); with ``robust_px`` a soft-L1
    loss of that scale. The intrinsics are held."""
    sel = _spread_sample(len(obs.ids), use, MAX_FIT_POINTS)
    sub = _subset(obs, sel)
    xy0 = pixels_to_normalized(camera, sub.uv)

    def resid(p: np.ndarray) -> np.ndarray:
        r = project(with_pose(camera, p[:3], p[3:]), sub, cell, xy0) - sub.uv
        return np.where(np.isfinite(r), r, UNPROJECTED_PX).ravel()

    p0 = np.r_[cv2.Rodrigues(camera.R)[0].ravel(), camera.t]
    sol = least_squares(
        resid,
        p0,
        diff_step=DIFF_STEP,
        loss="linear" if robust_px is None else "soft_l1",
        f_scale=1.0 if robust_px is None else robust_px,
        x_scale="jac",
    )
    return with_pose(camera, sol.x[:3], sol.x[3:])


def pose_camera(
    camera: Camera, obs: PoseObservations, cell: CellOptics, min_targets: int, inlier_px: float
) -> RefractivePose | str:
    """Pose ``camera`` (intrinsics as calibrated; its pose is ignored) from ``obs`` through the
    cell (module docstring). Returns the :class:`RefractivePose`, or why it could not be posed."""
    first = straight_line_pose(camera, obs)
    if first is None:
        return f"straight-line PnP failed on {len(obs.ids)} targets"
    cam, use = first
    if use.sum() < min_targets:
        return f"straight-line PnP found {int(use.sum())} consistent targets of {len(obs.ids)}"
    for k in range(ROBUST_ROUNDS):  # at least one
        cam = refine_pose(cam, obs, cell, use, robust_px=inlier_px if k == 0 else None)
        r = project(cam, obs, cell, pixels_to_normalized(cam, obs.uv)) - obs.uv
        err = np.hypot(r[:, 0], r[:, 1])
        use = err <= inlier_px
        if use.sum() < min_targets:
            return f"{int(use.sum())} of {len(obs.ids)} targets within {inlier_px} px after refraction"
    spread = image_spread_px(obs.uv[use])
    if spread < min_spread_px(cam):
        return f"targets not well spread: {spread:.1f} px across, fewer than {min_spread_px(cam):.1f}"
    return RefractivePose(cam, r, use, float(np.sqrt(np.mean(err[use] ** 2))))
