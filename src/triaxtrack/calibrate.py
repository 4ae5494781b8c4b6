"""Camera calibration from checkerboard images, one camera at a time.

Units and conventions:

* pixels in OpenCV's convention (the centre of the top-left pixel is (0, 0)), distorted image
  coordinates; ``K`` (3 x 3) in pixels; ``dist`` dimensionless, OpenCV's order
  ``(k1, k2, p1, p2, k3)`` (``standard`` model) or ``(k1, k2, p1, p2, k3, k4, k5, k6)``
  (``rational`` model), acting on normalised coordinates ``x / z, y / z``;
* board points in millimetres in the board's own frame (:func:`triaxtrack.kit.board_corners_mm`:
  origin at the outer corner of the top-left square, x along the ``squares_x`` side, y down,
  inner corners row-major from the top-left one; the top-left square is black);
* ``rms_px``: root mean square over corners of the distance between detected and reprojected
  corners, pixels.

The result (``results/<test>/calibration/<camera>.json``)::

    {"camera": "cam01", "width": 1280, "height": 720, "model": "standard",
     "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "dist": [k1, k2, p1, p2, k3],
     "rms_px": 0.03,                 # all corners of the images used
     "n_images": 15, "n_images_found": 15, "n_images_used": 14,
     "outlier_limit_px": 0.25,       # per-image RMS above this: rejected
     "images": [{"image": "01.png", "rms_px": 0.03, "used": true, "reason": ""}, ...],
     "board": {"squares_x": 10, "squares_y": 7, "square_mm": 20.0}}

Per image, ``rms_px`` is measured against the final calibration (for a rejected image, with
its pose re-estimated under the final intrinsics) and is ``null`` when the board was not found.

Corners are found with ``cv2.findChessboardCornersSB``, put in the board's own order (see
:func:`canonical_corner_order`) and refined with ``cv2.cornerSubPix`` on a slightly blurred
image (:func:`refine_corners`). The camera is calibrated with ``cv2.calibrateCamera``; images
whose own RMS is an outlier (above ``max(outlier_floor_px, median + outlier_mad_k * MAD)``,
MAD scaled to a standard deviation) are dropped and the camera recalibrated, until no image is
dropped.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import cv2
import numpy as np

from triaxtrack.kit import board_corners_mm
from triaxtrack.optics import Camera

#: calibration models: name -> (cv2.calibrateCamera flags, number of distortion coefficients)
MODELS: dict[str, tuple[int, int]] = {
    "standard": (0, 5),
    "rational": (cv2.CALIB_RATIONAL_MODEL, 8),
}
IMAGE_SUFFIXES = (".png",)  # board images of test-folder.md: calibration/<camera>/*.png
# findChessboardCornersSB: ACCURACY up-samples (sub-pixel positions on small boards),
# NORMALIZE_IMAGE equalises exposure, EXHAUSTIVE tries harder on strongly tilted boards
SB_FLAGS = cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE
# cornerSubPix is biased by the pixel aliasing of sharp edges (0.05 px RMS on exact-area renders
# of the board, SB alone 0.09 px with outliers of 0.5 px); a 1.5 px Gaussian blur first brings
# it to 0.015 px (1280x720 and 1920x1080 renders, 1.5 DN noise)
REFINE_BLUR_SIGMA_PX = 1.5
# cornerSubPix half-window: this fraction of the shortest corner spacing in the image, so the
# window never reaches a neighbouring corner, within REFINE_WINDOW_PX
REFINE_WINDOW_FRACTION = 0.3
REFINE_WINDOW_PX = (3, 15)
REFINE_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
CALIBRATE_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
MAD_TO_SIGMA = 1.4826  # MAD of a normal distribution times this is its standard deviation
MAX_ROUNDS = 10  # outlier rejection rounds (each drops at least one image)


class CalibrationError(ValueError):
    """A camera cannot be calibrated from its board images (the message names camera and files)."""


@dataclass(frozen=True)
class CalibrationConfig:
    """Settings of config ``calibration`` (config/README.md)."""

    model: str = "standard"  # standard (5 coefficients) | rational (8)
    min_images: int = 8  # fewer usable board images: error
    outlier_floor_px: float = 0.25  # an image is never rejected at or below this RMS
    outlier_mad_k: float = 5.0  # rejected above median + k * MAD (scaled) of the per-image RMS

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"calibration model must be one of {sorted(MODELS)}, not {self.model!r}")
        if self.min_images < 3:
            raise ValueError(f"calibration min_images must be at least 3, not {self.min_images}")
        if self.outlier_floor_px <= 0 or self.outlier_mad_k <= 0:
            raise ValueError("calibration outlier_floor_px and outlier_mad_k must be positive")

    @staticmethod
    def from_dict(d: dict | None) -> CalibrationConfig:
        d = dict(d or {})
        known = {f.name for f in fields(CalibrationConfig)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown calibration settings: {sorted(unknown)}; known: {sorted(known)}")
        return CalibrationConfig(**d)


@dataclass(frozen=True)
class BoardImage:
    """The board found in one image: ``corners_px`` (N, 2) float64 in the order of
    :func:`triaxtrack.kit.board_corners_mm`, or None when the board was not found."""

    image: str
    corners_px: np.ndarray | None


# ---------------------------------------------------------------- the board


def read_board(kit_dir: str | Path) -> dict:
    """The checkerboard of a kit export (``KIT/board.json``); ValueError naming the file."""
    path = Path(kit_dir) / "board.json"
    try:
        board = json.loads(path.read_text())
        if board.get("type", "checkerboard") != "checkerboard":
            raise ValueError(f"board type {board['type']!r} is not a checkerboard")
        for key in ("squares_x", "squares_y", "square_mm"):
            if key not in board:
                raise ValueError(f"no {key!r}")
        if min(int(board["squares_x"]), int(board["squares_y"])) < 3 or float(board["square_mm"]) <= 0:
            raise ValueError("needs at least 3 x 3 squares of positive size")
    except (OSError, ValueError, TypeError) as err:
        raise ValueError(f"{path}: not a usable calibration board: {err}") from err
    return board


def board_pattern(board: dict) -> tuple[int, int]:
    """(columns, rows) of inner corners: ``(squares_x - 1, squares_y - 1)``."""
    return int(board["squares_x"]) - 1, int(board["squares_y"]) - 1


# ---------------------------------------------------------------- corners


def _sample(gray: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Grey values at (N, 2) pixel positions (nearest pixel, clipped to the image)."""
    u = np.clip(np.round(uv[:, 0]).astype(int), 0, gray.shape[1] - 1)
    v = np.clip(np.round(uv[:, 1]).astype(int), 0, gray.shape[0] - 1)
    return gray[v, u].astype(np.float64)


def canonical_corner_order(gray: np.ndarray, corners_px: np.ndarray, pattern: tuple[int, int]) -> np.ndarray:
    """The detected inner corners re-ordered as :func:`triaxtrack.kit.board_corners_mm` lists them.

    ``corners_px``: (N, 2) as ``findChessboardCornersSB`` returns them for ``pattern``
    (rows of ``pattern[0]`` corners), in any of the grid's four orientations that keep rows
    along the long side. Two checks fix the order: handedness (the board is seen from its
    printed side, so its x and y axes keep their sense in the image: rows are reversed if not)
    and colour (the square diagonally between corners (r, c) and (r + 1, c + 1) is black when
    r + c is even; if those squares are the brighter ones, the board is read rotated by 180
    degrees and the list is reversed). A board whose squares_x and squares_y have the same
    parity looks the same after 180 degrees; its order then stays ambiguous, which does not
    affect the intrinsics (the reversed point set is a rigid motion of the board).
    """
    nx, ny = pattern
    grid = np.asarray(corners_px, np.float64).reshape(ny, nx, 2)
    along_row = grid[0, -1] - grid[0, 0]
    down_cols = grid[-1, 0] - grid[0, 0]
    if along_row[0] * down_cols[1] - along_row[1] * down_cols[0] < 0:
        grid = grid[::-1]
    centres = (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:]) / 4
    grey = _sample(gray, centres.reshape(-1, 2)).reshape(ny - 1, nx - 1)
    r, c = np.mgrid[0 : ny - 1, 0 : nx - 1]
    even = (r + c) % 2 == 0
    if grey[even].mean() > grey[~even].mean():
        grid = grid[::-1, ::-1]
    return grid.reshape(-1, 2)


def refine_corners(gray: np.ndarray, corners_px: np.ndarray, pattern: tuple[int, int]) -> np.ndarray:
    """(N, 2) corners refined by ``cv2.cornerSubPix`` on the image blurred by
    ``REFINE_BLUR_SIGMA_PX``, with a window scaled to the corner spacing (``pattern`` as in
    :func:`canonical_corner_order`; the input order is kept)."""
    nx, ny = pattern
    grid = np.asarray(corners_px, np.float64).reshape(ny, nx, 2)
    spacing = min(
        np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
        np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
    )
    half = int(np.clip(REFINE_WINDOW_FRACTION * spacing, *REFINE_WINDOW_PX))
    blurred = cv2.GaussianBlur(gray.astype(np.float32), (0, 0), REFINE_BLUR_SIGMA_PX)
    start = np.asarray(corners_px, np.float32).reshape(-1, 1, 2).copy()
    out = cv2.cornerSubPix(blurred, start, (half, half), (-1, -1), REFINE_CRITERIA)
    return out.reshape(-1, 2).astype(np.float64)


def find_board_corners(gray: np.ndarray, board: dict) -> np.ndarray | None:
    """(N, 2) float64 inner corners of the board in a uint8 grey image, in the order of
    :func:`triaxtrack.kit.board_corners_mm`, refined; None when the board is not found."""
    pattern = board_pattern(board)
    found, corners = cv2.findChessboardCornersSB(gray, pattern, SB_FLAGS)
    if not found or corners is None or len(corners) != pattern[0] * pattern[1]:
        return None
    corners = canonical_corner_order(gray, corners.reshape(-1, 2), pattern)
    return refine_corners(gray, corners, pattern)


def list_board_images(camera: str, folder: str | Path) -> list[Path]:
    """The board images of one camera (``folder/*.png``, sorted); CalibrationError if none."""
    folder = Path(folder)
    if not folder.is_dir():
        raise CalibrationError(f"camera {camera}: calibration folder {folder} not found")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not paths:
        raise CalibrationError(f"camera {camera}: no board images (*.png) in {folder}")
    return paths


def detect_boards(
    camera: str, image_paths: Sequence[str | Path], board: dict
) -> tuple[tuple[int, int], list[BoardImage]]:
    """Read each image (grey) and find the board: ``((width, height), [BoardImage, ...])``.

    CalibrationError naming the camera and the file when an image cannot be read or its size
    differs from the first image's.
    """
    if not image_paths:
        raise CalibrationError(f"camera {camera}: no board images given")
    size = None
    found = []
    for path in image_paths:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise CalibrationError(f"camera {camera}: cannot read board image {path}")
        if size is None:
            size = (gray.shape[1], gray.shape[0])
            first = path
        elif (gray.shape[1], gray.shape[0]) != size:
            raise CalibrationError(
                f"camera {camera}: board image {path} is {gray.shape[1]}x{gray.shape[0]} px, "
                f"but {first} is {size[0]}x{size[1]} px"
            )
        found.append(BoardImage(Path(path).name, find_board_corners(gray, board)))
    return size, found


# ---------------------------------------------------------------- calibration


def _fit(
    object_mm: np.ndarray, views: list[np.ndarray], size: tuple[int, int], model: str
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """calibrateCamera on the views: (rms_px, K, dist, per-view rms_px)."""
    flags, n_dist = MODELS[model]
    obj = [object_mm.astype(np.float32)] * len(views)
    img = [v.astype(np.float32).reshape(-1, 1, 2) for v in views]
    out = cv2.calibrateCameraExtended(obj, img, size, None, None, flags=flags, criteria=CALIBRATE_CRITERIA)
    rms, K, dist, per_view = out[0], out[1], out[2], out[7]
    return float(rms), K, dist.ravel()[:n_dist].copy(), per_view.ravel().astype(np.float64)


def view_rms_px(object_mm: np.ndarray, corners_px: np.ndarray, K: np.ndarray, dist: np.ndarray) -> float:
    """RMS reprojection error (px) of one view under fixed intrinsics, its pose fitted
    (planar IPPE start, then Levenberg-Marquardt)."""
    obj = object_mm.astype(np.float64).reshape(-1, 1, 3)
    img = corners_px.astype(np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return float("inf")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec)
    uv, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    return float(np.sqrt(np.mean(np.sum((uv.reshape(-1, 2) - img.reshape(-1, 2)) ** 2, axis=1))))


def outlier_limit_px(rms_px: np.ndarray, cfg: CalibrationConfig) -> float:
    """Per-image RMS above which an image is an outlier: max(floor, median + k * scaled MAD)."""
    med = float(np.median(rms_px))
    mad = float(np.median(np.abs(rms_px - med))) * MAD_TO_SIGMA
    return max(cfg.outlier_floor_px, med + cfg.outlier_mad_k * mad)


def calibrate_views(
    camera: str,
    found: Sequence[BoardImage],
    size: tuple[int, int],
    board: dict,
    cfg: CalibrationConfig,
    folder: str | Path = "",
) -> dict:
    """Calibrate one camera from its detected boards; returns the result mapping (module
    docstring). ``folder`` only names where the images came from in errors.

    CalibrationError naming the camera (and ``folder``) when fewer than ``cfg.min_images``
    images are usable: boards not found, or rejected as outliers.
    """
    where = f" in {folder}" if str(folder) else ""
    object_mm = board_corners_mm(board)
    reason = {b.image: "" if b.corners_px is not None else "board not found" for b in found}
    missing = [b.image for b in found if b.corners_px is None]
    usable = [b for b in found if b.corners_px is not None]

    def too_few(n: int) -> CalibrationError:
        notes = []
        if missing:
            notes.append(f"board not found in {missing}")
        dropped = {k: v for k, v in reason.items() if v and k not in missing}
        if dropped:
            notes.append(f"rejected: {dropped}")
        detail = f" ({'; '.join(notes)})" if notes else ""
        return CalibrationError(
            f"camera {camera}: {n} usable board images of {len(found)}{where}, "
            f"at least {cfg.min_images} needed{detail}"
        )

    if len(usable) < cfg.min_images:
        raise too_few(len(usable))
    used = list(usable)
    limit = np.inf
    for _ in range(MAX_ROUNDS):
        try:
            rms, K, dist, per_view = _fit(object_mm, [b.corners_px for b in used], size, cfg.model)
        except cv2.error as err:
            raise CalibrationError(f"camera {camera}: calibration failed{where}: {err}") from err
        limit = outlier_limit_px(per_view, cfg)
        bad = per_view > limit
        if not bad.any():
            break
        med = float(np.median(per_view))
        for b, r, is_bad in zip(used, per_view, bad, strict=True):
            if is_bad:
                reason[b.image] = (
                    f"outlier: reprojection RMS {r:.3f} px > limit {limit:.3f} px "
                    f"(median {med:.3f} px over {len(used)} images)"
                )
        used = [b for b, is_bad in zip(used, bad, strict=True) if not is_bad]
        if len(used) < cfg.min_images:
            raise too_few(len(used))
    else:
        raise CalibrationError(f"camera {camera}: outlier rejection did not settle in {MAX_ROUNDS} rounds")

    used_rms = dict(zip([b.image for b in used], per_view, strict=True))
    images = []
    for b in found:
        if b.corners_px is None:
            r = None
        elif b.image in used_rms:
            r = float(used_rms[b.image])
        else:
            r = view_rms_px(object_mm, b.corners_px, K, dist)
        images.append({"image": b.image, "rms_px": r, "used": b.image in used_rms, "reason": reason[b.image]})
    return {
        "camera": camera,
        "width": int(size[0]),
        "height": int(size[1]),
        "model": cfg.model,
        "K": np.asarray(K, float).tolist(),
        "dist": np.asarray(dist, float).tolist(),
        "rms_px": rms,
        "n_images": len(found),
        "n_images_found": len(usable),
        "n_images_used": len(used),
        "outlier_limit_px": float(limit),
        "images": images,
        "board": {k: board[k] for k in ("squares_x", "squares_y", "square_mm")},
    }


def calibrate_camera(camera: str, folder: str | Path, kit_dir: str | Path, cfg: CalibrationConfig) -> dict:
    """Calibrate one camera from its board images ``folder/*.png`` and the kit's board.json.

    The result mapping is described in the module docstring. CalibrationError naming the camera
    and the folder or file when the images are missing, unreadable, or too few are usable.
    """
    board = read_board(kit_dir)
    paths = list_board_images(camera, folder)
    size, found = detect_boards(camera, paths, board)
    return calibrate_views(camera, found, size, board, cfg, folder)


def read_calibration(path: str | Path) -> dict:
    """A calibration result (module docstring); ValueError naming the file if it is not one."""
    path = Path(path)
    try:
        cal = json.loads(path.read_text())
        for key in ("camera", "width", "height", "K", "dist"):
            if key not in cal:
                raise ValueError(f"no {key!r}")
        K = np.asarray(cal["K"], float)
        dist = np.asarray(cal["dist"], float)
        if K.shape != (3, 3) or dist.ndim != 1 or len(dist) < 4:
            raise ValueError(f"K must be 3 x 3 and dist 4+ coefficients, not {K.shape} and {dist.shape}")
    except (OSError, ValueError, TypeError) as err:
        raise ValueError(f"{path}: not a calibration result: {err}") from err
    return cal


def calibrated_camera(cal: dict) -> Camera:
    """The :class:`~triaxtrack.optics.Camera` of a calibration result: its intrinsics and
    distortion, with the identity pose (the pose is found later, by :mod:`triaxtrack.sfm`)."""
    return Camera.from_json(str(cal["camera"]), {**cal, "R": np.eye(3), "t": np.zeros(3)})


def format_calibration(result: dict) -> str:
    """A few lines summarising a calibration result (for the job log)."""
    K = result["K"]
    lines = [
        f"{result['camera']}: {result['model']} model, fx {K[0][0]:.2f} fy {K[1][1]:.2f} "
        f"cx {K[0][2]:.2f} cy {K[1][2]:.2f} px, dist {[round(d, 5) for d in result['dist']]}",
        f"rms {result['rms_px']:.4f} px over {result['n_images_used']} images "
        f"({result['n_images_found']} of {result['n_images']} with the board found; "
        f"outlier limit {result['outlier_limit_px']:.3f} px)",
    ]
    for im in result["images"]:
        if not im["used"]:
            rms = "" if im["rms_px"] is None else f" (rms {im['rms_px']:.3f} px)"
            lines.append(f"  not used: {im['image']}{rms}: {im['reason']}")
    return "\n".join(lines)
