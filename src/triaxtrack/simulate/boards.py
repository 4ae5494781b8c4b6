"""Calibration images: seeded checkerboard poses of a careful calibration session
(:func:`board_poses`), rendered exactly (:func:`render_calibration`)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from triaxtrack import footage
from triaxtrack.kit import board_corners_mm, board_polygons_mm
from triaxtrack.kit_design import BoardDesign
from triaxtrack.layout import TEST_FOLDER
from triaxtrack.optics import Camera, project_air
from triaxtrack.raster import paint_into
from triaxtrack.simulate.config import SimulationConfig
from triaxtrack.simulate.render import GREY_BACKGROUND, GREY_INK, GREY_LABEL
from triaxtrack.simulate.scene import load_scene

# calibration-board poses (board_poses). Strong tilts in every direction and boards reaching the
# image edges pin down the focal length and the distortion; but a whole board cannot reach the
# image corners of a wide-angle lens (with k1 = -0.3 no corner of a whole 10 x 7 board came
# closer than 125-235 px to them, and k1, k2, k3 extrapolated there: undistortion map off by
# 0.26 px, median camera, and 0.85 px, worst, on the demo), so some boards run off the image
# across its corners, as a lab photographs them for a wide-angle camera. With these poses (20
# images, the kit's 16 x 11 board) the map is off by 0.018-0.026 px (median camera) and
# 0.039-0.051 px (worst) on the demo and the three validation tests
BOARD_TILT_DEG = (30.0, 55.0)  # tilt about an in-plane axis of random direction
BOARD_ROLL_DEG = 20.0  # in-plane rotation, +-
BOARD_DISTANCE_MM = (180.0, 320.0)  # whole board: its centre from the camera, before it is shifted
BOARD_MAX_VIEW_DEG = 60.0  # largest angle between the board's normal and the line of sight
BOARD_EDGE_PX = 12.0  # gap left between the sheet's image and the image edge it is pushed to
BOARD_SHIFT_STEPS = 4  # shift iterations (the distortion makes one step inexact) ...
BOARD_MAX_SHIFT_STEPS = 20  # ... and more while the anchor is still 1 px or more off (a wider,
# more distorted lens: focal 0.56 x width, k1 -0.4, k2 0.125 left it 4.6-4.9 px off after 4)
# where each whole board goes, in turn: (-1, 0, 1) = left / centre / right, top / centre / bottom
BOARD_ANCHORS = ((-1, -1), (1, 1), (1, -1), (-1, 1), (0, 0), (0, -1), (1, 0), (0, 1), (-1, 0))
# boards across an image corner: BOARD_CORNER_SHARE of the images (a multiple of 4, one per image
# corner in turn, none below 10 images); one inner corner of the board, picked at random, lands
# BOARD_CORNER_INSET_PX from both edges at the image corner, and at least BOARD_CORNER_MIN_SEEN
# inner corners, in BOARD_CORNER_MIN_LINES rows and columns or more, lie BOARD_CORNER_SEEN_PX or
# more inside the image (a thin strip of the board is of little use)
BOARD_CORNER_SHARE = 0.4
BOARD_CORNER_INSET_PX = 10.0
BOARD_CORNER_DISTANCE_MM = (150.0, 260.0)  # anchor corner from the camera, before it is shifted
BOARD_CORNER_MIN_SEEN = 30
BOARD_CORNER_MIN_LINES = 4
BOARD_CORNER_SEEN_PX = 12.0
BOARD_CORNER_ORDER = ((-1, -1), (1, 1), (1, -1), (-1, 1))  # image corners, (left/right, top/bottom)
BOARD_MAX_TRIES = 5000  # random poses tried before giving up


def corner_board_count(n: int) -> int:
    """How many of ``n`` calibration images show a board across an image corner
    (``BOARD_CORNER_SHARE`` of them, a multiple of 4; none below 10 images)."""
    return 4 * int(BOARD_CORNER_SHARE * n / 4 + 0.5) if n >= 10 else 0


def _tilted_rotation(rng: np.random.Generator) -> np.ndarray:
    """A board rotation (board -> camera): tilt ``BOARD_TILT_DEG`` about a random in-plane axis
    after a roll of up to ``BOARD_ROLL_DEG``."""
    azimuth = rng.uniform(0, 2 * np.pi)
    tilt = np.deg2rad(rng.uniform(*BOARD_TILT_DEG))
    roll = np.deg2rad(rng.uniform(-1, 1) * BOARD_ROLL_DEG)
    return (
        cv2.Rodrigues(tilt * np.r_[np.cos(azimuth), np.sin(azimuth), 0])[0]
        @ cv2.Rodrigues(np.r_[0, 0, roll])[0]
    )


def _within_view_angle(R: np.ndarray, t: np.ndarray, centre: np.ndarray) -> bool:
    """True when the board's normal is within ``BOARD_MAX_VIEW_DEG`` of the line of sight to
    ``centre`` (a board point, mm)."""
    to_board = R @ centre + t
    cos_view = abs(R[:, 2] @ to_board) / np.linalg.norm(to_board)
    return bool(cos_view >= np.cos(np.deg2rad(BOARD_MAX_VIEW_DEG)))


def _whole_board_pose(
    rng: np.random.Generator, camera: Camera, sheet_mm: np.ndarray, anchor: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray] | None:
    """One tilted pose of the whole sheet (corners ``sheet_mm``, (M, 3)) pushed to the image
    edges of ``anchor``; None if it does not fit in the image."""
    w, h = camera.width, camera.height
    ax, ay = anchor
    lo_mm, hi_mm = sheet_mm.min(axis=0), sheet_mm.max(axis=0)
    centre = (lo_mm + hi_mm) / 2
    dist = rng.uniform(*BOARD_DISTANCE_MM)
    R = _tilted_rotation(rng)
    t = np.r_[0.0, 0.0, dist] - R @ centre

    def image_of(t: np.ndarray) -> np.ndarray:
        return project_air(Camera("b", w, h, camera.K, camera.dist, R, t), sheet_mm)

    for _ in range(BOARD_SHIFT_STEPS):
        uv = image_of(t)
        if not np.isfinite(uv).all():
            break
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        jitter = rng.uniform(0, 3, 2)
        du = (
            BOARD_EDGE_PX + jitter[0] - lo[0],
            (w - 1 - lo[0] - hi[0]) / 2,
            w - 1 - BOARD_EDGE_PX - jitter[0] - hi[0],
        )[ax + 1]
        dv = (
            BOARD_EDGE_PX + jitter[1] - lo[1],
            (h - 1 - lo[1] - hi[1]) / 2,
            h - 1 - BOARD_EDGE_PX - jitter[1] - hi[1],
        )[ay + 1]
        # pixels to mm at the board centre's depth; 0.9 damps the step (distortion)
        t = t + 0.9 * np.r_[du, dv, 0.0] * dist / camera.K[0, 0]
    uv = image_of(t)
    pc = sheet_mm @ R.T + t
    if (
        (pc[:, 2] > 50).all()
        and _within_view_angle(R, t, centre)
        and np.isfinite(uv).all()
        and (uv >= 10).all()
        and (uv[:, 0] <= w - 11).all()
        and (uv[:, 1] <= h - 11).all()
    ):
        return R, t
    return None


def _corner_board_pose(
    rng: np.random.Generator,
    camera: Camera,
    corners_mm: np.ndarray,
    sheet_mm: np.ndarray,
    corner: tuple[int, int],
) -> tuple[np.ndarray, np.ndarray] | None:
    """One tilted pose of a board running off the image across image ``corner`` ((-1 | 1,
    -1 | 1): left | right, top | bottom): a random inner corner (``corners_mm``, (N, 3)) lands
    ``BOARD_CORNER_INSET_PX`` from both edges there; None if too few corners are seen."""
    w, h = camera.width, camera.height
    target = np.r_[
        (BOARD_CORNER_INSET_PX, w - 1 - BOARD_CORNER_INSET_PX)[(corner[0] + 1) // 2],
        (BOARD_CORNER_INSET_PX, h - 1 - BOARD_CORNER_INSET_PX)[(corner[1] + 1) // 2],
    ]
    anchor = corners_mm[rng.integers(len(corners_mm))]
    R = _tilted_rotation(rng)
    t = np.r_[0.0, 0.0, rng.uniform(*BOARD_CORNER_DISTANCE_MM)] - R @ anchor

    def image_of(t: np.ndarray, pts: np.ndarray) -> np.ndarray:
        return project_air(Camera("b", w, h, camera.K, camera.dist, R, t), pts)

    for step in range(BOARD_MAX_SHIFT_STEPS):  # Newton steps on the board's sideways shift (mm)
        uv = image_of(t, anchor[None])[0]
        if step >= BOARD_SHIFT_STEPS and np.hypot(*(uv - target)) < 1.0:
            break
        shifted = (
            image_of(t + np.r_[1.0, 0, 0], anchor[None])[0],
            image_of(t + np.r_[0, 1.0, 0], anchor[None])[0],
        )
        J = np.c_[shifted[0] - uv, shifted[1] - uv]  # pixels per mm of shift
        if not (np.isfinite(J).all() and np.isfinite(uv).all()) or abs(np.linalg.det(J)) < 1e-9:
            return None
        t = t + np.r_[np.linalg.solve(J, target - uv), 0.0]
    uv = image_of(t, corners_mm)
    seen = (
        np.isfinite(uv).all(axis=1)
        & (uv >= BOARD_CORNER_SEEN_PX).all(axis=1)
        & (uv[:, 0] <= w - 1 - BOARD_CORNER_SEEN_PX)
        & (uv[:, 1] <= h - 1 - BOARD_CORNER_SEEN_PX)
    )
    near = np.hypot(*(image_of(t, anchor[None])[0] - target)) < 1.0
    lines = min(len(np.unique(corners_mm[seen, 0])), len(np.unique(corners_mm[seen, 1])))
    if (
        near
        and seen.sum() >= BOARD_CORNER_MIN_SEEN
        and lines >= BOARD_CORNER_MIN_LINES
        and ((sheet_mm @ R.T + t)[:, 2] > 50).all()
        and _within_view_angle(R, t, anchor)
    ):
        return R, t
    return None


def board_poses(
    cfg: SimulationConfig, camera: Camera, board: BoardDesign, n: int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Seeded board poses (R, t board -> camera, mm) of a careful calibration session for a
    wide-angle camera: ``n - corner_board_count(n)`` whole boards, strongly tilted and pushed
    into every part of the image in turn (``BOARD_ANCHORS``), then boards running off the image
    across each image corner in turn (``BOARD_CORNER_ORDER``).

    Every pose is tilted by ``BOARD_TILT_DEG`` about an in-plane axis of random direction and
    rolled by up to ``BOARD_ROLL_DEG``. A whole board is then shifted until its image touches
    the image edges on its anchor's sides (``BOARD_EDGE_PX``); its whole sheet stays inside the
    image. A corner board is shifted until one of its inner corners, picked at random, lies
    ``BOARD_CORNER_INSET_PX`` from both edges at the image corner; the rest of the board runs
    off the image there, so corners are measured where the distortion is strongest.
    """
    rng = footage.camera_rng(cfg.seed, camera.name, (7,))
    sheet, _ = board_polygons_mm(board)
    sheet_mm = np.c_[sheet, np.zeros(len(sheet))]
    corners_mm = board_corners_mm(board)
    n_corner = corner_board_count(n)
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    tries = 0
    while len(poses) < n and tries < BOARD_MAX_TRIES:
        tries += 1
        k = len(poses)
        if k < n - n_corner:
            pose = _whole_board_pose(rng, camera, sheet_mm, BOARD_ANCHORS[k % len(BOARD_ANCHORS)])
        else:
            corner = BOARD_CORNER_ORDER[(k - n + n_corner) % len(BOARD_CORNER_ORDER)]
            pose = _corner_board_pose(rng, camera, corners_mm, sheet_mm, corner)
        if pose is not None:
            poses.append(pose)
    if len(poses) < n:
        raise RuntimeError(f"could not place {n} calibration boards for {camera.name}")
    return poses


def render_board_image(
    camera: Camera, board: BoardDesign, R: np.ndarray, t: np.ndarray, noise: float, rng
) -> np.ndarray:
    """uint8 image of the checkerboard at pose (R, t) seen by ``camera`` (exact, distorted)."""
    bcam = Camera("b", camera.width, camera.height, camera.K, camera.dist, R, t)
    sheet, squares = board_polygons_mm(board, subdivide=8)
    h, w = camera.height, camera.width
    img = np.full((h, w), GREY_BACKGROUND)

    def project(poly):
        return project_air(bcam, np.c_[poly, np.zeros(len(poly))])

    paint_into(img, project(sheet), [len(sheet)], GREY_LABEL)
    sq = np.vstack(squares)
    paint_into(img, project(sq), [len(s) for s in squares], GREY_INK)
    img = img + rng.normal(0, noise, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def render_calibration(test_dir: str | Path, camera: str, out_dir: str | Path) -> None:
    """Calibration board images of one camera (PNG) and, in truth/, the board poses.

    ``truth/calibration/<camera>.json``: ``{"board_poses": [{"image", "kind", "R", "t",
    "corners_px"}, ...]}``, one per image in order: ``kind`` is ``whole`` or ``corner``
    (:func:`board_poses`), R and t take board millimetres (:func:`triaxtrack.kit.board_corners_mm`
    frame) to the camera frame, and ``corners_px`` is the exact distorted image of every inner
    corner, in the order of ``board_corners_mm``: for a ``corner`` board some lie outside the
    image.
    """
    test_dir, out_dir = Path(test_dir), Path(out_dir)
    scene = load_scene(test_dir)
    cam = scene.cameras[camera]
    board = scene.design.board
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = footage.camera_rng(scene.cfg.seed, camera, (11,))
    n = scene.cfg.calibration_images
    poses = board_poses(scene.cfg, cam, board, n)
    n_whole = n - corner_board_count(n)
    record = []
    for i, (R, t) in enumerate(poses):
        img = render_board_image(cam, board, R, t, scene.cfg.noise_sigma, rng)
        cv2.imwrite(str(out_dir / f"{i + 1:02d}.png"), img)
        uv = project_air(Camera("b", cam.width, cam.height, cam.K, cam.dist, R, t), board_corners_mm(board))
        record.append({
            "image": f"{i + 1:02d}.png",
            "kind": "whole" if i < n_whole else "corner",
            "R": R.tolist(),
            "t": t.tolist(),
            "corners_px": uv.tolist(),
        })  # fmt: skip
    truth = test_dir / TEST_FOLDER.truth.board_poses.format(camera=camera)
    truth.parent.mkdir(parents=True, exist_ok=True)
    truth.write_text(json.dumps({"board_poses": record}))
