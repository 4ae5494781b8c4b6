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
     "rms_px": 0.01,                 # all corners of the images used
     "n_images": 20, "n_images_found": 20, "n_images_used": 19,
     "n_corners_used": 2400,
     "outlier_limit_px": 0.25,       # per-image RMS above this: rejected
     "passes": 2,                    # corner refinements (2: the second in undistorted coordinates)
     "images": [{"image": "01.png", "board": "whole", "n_corners": 150, "rms_px": 0.01,
                 "used": true, "reason": ""}, ...],
     "board": {"squares_x": 16, "squares_y": 11, "square_mm": 12.5}}

Per image, ``board`` is ``whole`` (every inner corner found), ``partial`` (the board runs off
the image: the corners seen), or null (no board found); ``n_corners`` counts the corners kept;
``rms_px`` is measured against the final calibration (for a rejected image, with its pose
re-estimated under the final intrinsics) and is ``null`` when no board was found.

Corners. The whole board is sought with ``cv2.findChessboardCornersSB`` and put in the board's
own order (:func:`canonical_corner_order`); failing that, the part of it the image holds
(:func:`find_partial_board`: a 3 x 3 block of saddle points grown corner by corner), whose
object points are its own grid indices times the square size (each view has its own pose, so
any origin and orientation will do and no markers are needed). Every corner is refined by a
point-symmetry fit (:func:`refine_corners`): two lines crossing at a point look the same after a
half turn about it, under any perspective and any isotropic blur, so the corner is where the
image best matches its own half-turned copy (least squares over a window reaching half-way to
the neighbouring corners, cubic-spline interpolation of the slightly blurred image). Lens
distortion bends the lines and biases this fit towards the image centre by a few thousandths of
a pixel near the image edges, which the distortion fit extrapolates to the image corners; so
the camera is calibrated once, the corners are refined again with the window drawn in
undistorted coordinates through that calibration, and the camera calibrated again
(``CalibrationConfig.passes``). Corners whose window leaves the image, that move too far or
that do not look like a checkerboard corner (asymmetric or without contrast) are dropped.

Fit. ``cv2.calibrateCamera`` on the whole boards first, then on every view from that start
(``CALIB_USE_INTRINSIC_GUESS``; from scratch, the partial boards can pull the fit into a wrong
minimum: :func:`fit_views`); images whose
own RMS is an outlier (above ``max(outlier_floor_px, median + outlier_mad_k * MAD)``, MAD
scaled to a standard deviation) are dropped and the camera recalibrated, until no image is
dropped.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

from triaxtrack.kit import board_corners_mm
from triaxtrack.optics import UNDISTORT_CRITERIA, Camera

#: calibration models: name -> (cv2.calibrateCamera flags, number of distortion coefficients)
MODELS: dict[str, tuple[int, int]] = {
    "standard": (0, 5),
    "rational": (cv2.CALIB_RATIONAL_MODEL, 8),
}
IMAGE_SUFFIXES = (".png",)  # board images of test-folder.md: calibration/<camera>/*.png
# findChessboardCornersSB: ACCURACY up-samples (sub-pixel positions on small boards),
# NORMALIZE_IMAGE equalises exposure, EXHAUSTIVE tries harder on strongly tilted boards
SB_FLAGS = cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE
# a partial board (find_partial_board): the fewest corners, rows and columns a usable view keeps
PARTIAL_MIN_CORNERS = 12
PARTIAL_MIN_LINES = 3
# ... its seeds: saddle points of the blurred image (Hessian determinant below -SADDLE_MIN,
# grey levels^2 / px^4; a corner of contrast C gives about -(0.14 C)^2), local extremes within
# SADDLE_NMS_PX, the SEED_MAX_POINTS strongest, refined with windows up to SEED_RADIUS_PX;
# grids are grown from up to SEED_TRIES of them, and kept if CHECKER_AGREEMENT of their squares
# alternate dark and bright
SADDLE_MIN = 4.0
SADDLE_NMS_PX = 2
SEED_MAX_POINTS = 400
SEED_RADIUS_PX = 5.0
SEED_TRIES = 3
SEED_NEIGHBOURS = 8  # nearest saddle points searched for a seed's two grid directions
CHECKER_AGREEMENT = 0.95
# corner refinement (refine_corners). Measured on rendered 16 x 11 boards (demo cameras, 1.5 DN
# noise, against the exact projections, RMS per coordinate): cornerSubPix (1.5 px blur, window
# 0.3 x spacing) 0.021 px; this fit 0.007 px, and 0.0045 px in its second pass (window drawn
# through the lens); blur 1.0-2.5 px and windows 0.4-0.6 x spacing were no better
REFINE_BLUR_SIGMA_PX = 1.5  # Gaussian blur first: a smooth image interpolates exactly
REFINE_RADIUS_FRACTION = 0.5  # window half-width: this fraction of the nearest neighbour's distance
REFINE_RADIUS_PX = (3.0, 15.0)  # ... within these bounds
REFINE_STENCIL = 10  # samples per half-width of the window (a (2 x 10 + 1)^2 grid over it)
REFINE_EDGE_PX = 3.0  # the window keeps this far inside the image (spline support and blur)
REFINE_MAX_ITER = 30
REFINE_TOL_PX = 1e-4  # converged when no corner moves more than this in an iteration
REFINE_MAX_SHIFT = 0.5  # a corner that moves farther than this times its window half-width is dropped
REFINE_MAX_ASYMMETRY = 0.08  # RMS mismatch with the half-turned window / contrast above this: dropped
REFINE_MIN_CONTRAST = 20.0  # grey levels between the dark and bright squares (5th-95th percentile)
# a partial board's grid: a corner farther than GRID_TOLERANCE times the local spacing from
# where its neighbours put it is dropped; corners are refined to GRID_REFINE_TOL_PX while the
# grid is built (all are refined to REFINE_TOL_PX after)
GRID_TOLERANCE = 0.25
GRID_REFINE_TOL_PX = 0.01
CALIBRATE_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
MIN_WHOLE_BOARDS = 3  # the first fit uses the whole boards alone when there are at least this many
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
    passes: int = 2  # corner refinements: 1, or 2 (again in undistorted coordinates, then refit)

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"calibration model must be one of {sorted(MODELS)}, not {self.model!r}")
        if self.min_images < 3:
            raise ValueError(f"calibration min_images must be at least 3, not {self.min_images}")
        if self.outlier_floor_px <= 0 or self.outlier_mad_k <= 0:
            raise ValueError("calibration outlier_floor_px and outlier_mad_k must be positive")
        if self.passes not in (1, 2):
            raise ValueError(f"calibration passes must be 1 or 2, not {self.passes}")

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
    """The board found in one image: ``corners_px`` (N, 2) float64 and their board points
    ``object_mm`` (N, 3) float64 (z = 0, mm), or both None when no board was found (an
    ``object_mm`` of None with corners means the whole board's :func:`~triaxtrack.kit.board_corners_mm`).
    ``whole``: the whole board was found (``object_mm`` from board_corners_mm, in its order,
    though the refinement may have dropped corners); otherwise a part of it, its object points
    in its own grid's frame."""

    image: str
    corners_px: np.ndarray | None
    object_mm: np.ndarray | None = None
    whole: bool = False

    @property
    def kind(self) -> str | None:
        """``whole``, ``partial``, or None (no board)."""
        return None if self.corners_px is None else ("whole" if self.whole else "partial")


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
    grid = right_handed(np.asarray(corners_px, np.float64).reshape(ny, nx, 2))
    centres = (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:]) / 4
    grey = _sample(gray, centres.reshape(-1, 2)).reshape(ny - 1, nx - 1)
    r, c = np.mgrid[0 : ny - 1, 0 : nx - 1]
    even = (r + c) % 2 == 0
    if grey[even].mean() > grey[~even].mean():
        grid = grid[::-1, ::-1]
    return grid.reshape(-1, 2)


def right_handed(grid_px: np.ndarray) -> np.ndarray:
    """A (rows, cols, 2) corner grid (NaN: missing corners) with its rows reversed if its
    columns and rows run the wrong way round in the image (the board's x and y axes, seen from
    its printed side, keep their sense in the image: x turns clockwise into y, image y down)."""

    def mean_step(axis: int) -> np.ndarray:
        steps = np.diff(grid_px, axis=axis).reshape(-1, 2)
        steps = steps[np.isfinite(steps).all(axis=1)]
        return steps.mean(axis=0) if len(steps) else np.zeros(2)

    along_row, down_cols = mean_step(1), mean_step(0)
    if along_row[0] * down_cols[1] - along_row[1] * down_cols[0] < 0:
        return grid_px[::-1].copy()
    return grid_px.copy()


def grid_indices(object_mm: np.ndarray, square_mm: float) -> np.ndarray:
    """(N, 2) int (column, row) of board points ``object_mm`` (N, 3) on their square grid,
    counted from the smallest present."""
    ij = np.round(np.asarray(object_mm, np.float64)[:, :2] / square_mm).astype(np.int64)
    return ij - ij.min(axis=0)


def neighbour_spacing_px(uv_px: np.ndarray, object_mm: np.ndarray, square_mm: float) -> np.ndarray:
    """(N,) image distance from each corner to its nearest grid neighbour present (the corners
    one square away along the board's rows and columns), pixels; NaN for a corner without one."""
    ij = grid_indices(object_mm, square_mm)
    grid = np.full((ij[:, 1].max() + 1, ij[:, 0].max() + 1, 2), np.nan)
    grid[ij[:, 1], ij[:, 0]] = uv_px
    best = np.full(grid.shape[:2], np.inf)
    along = np.linalg.norm(np.diff(grid, axis=1), axis=2)
    down = np.linalg.norm(np.diff(grid, axis=0), axis=2)
    best[:, :-1] = np.fmin(best[:, :-1], along)
    best[:, 1:] = np.fmin(best[:, 1:], along)
    best[:-1] = np.fmin(best[:-1], down)
    best[1:] = np.fmin(best[1:], down)
    out = best[ij[:, 1], ij[:, 0]]
    return np.where(np.isfinite(out), out, np.nan)


def _symmetry_stencil() -> tuple[np.ndarray, np.ndarray]:
    """Offsets (M, 2) in units of the window half-width, one of each mirror pair (d and -d) of
    a (2 REFINE_STENCIL + 1)^2 grid without its centre, and their Gaussian weights (M,), sigma
    half the half-width."""
    g = np.arange(-REFINE_STENCIL, REFINE_STENCIL + 1) / REFINE_STENCIL
    dx, dy = np.meshgrid(g, g)
    half = (dx > 0) | ((dx == 0) & (dy > 0))
    offsets = np.c_[dx[half], dy[half]]
    return offsets, np.exp(-2.0 * (offsets**2).sum(axis=1))


@dataclass(frozen=True)
class SmoothedImage:
    """A grey image blurred by ``REFINE_BLUR_SIGMA_PX``, ready for :func:`refine_corners`: its
    cubic B-spline coefficients (float64; the values are interpolated from them) and its
    gradients along u and v (float32 central differences, interpolated bilinearly: they only
    steer the iterations, not where they end)."""

    spline: np.ndarray
    grad_u: np.ndarray
    grad_v: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.spline.shape


def smooth_image(gray: np.ndarray) -> SmoothedImage:
    """:class:`SmoothedImage` of a grey image (any numeric dtype)."""
    blurred = cv2.GaussianBlur(np.asarray(gray, np.float64), (0, 0), REFINE_BLUR_SIGMA_PX)
    grad_v, grad_u = np.gradient(blurred)
    return SmoothedImage(
        ndimage.spline_filter(blurred, order=3, output=np.float64),
        grad_u.astype(np.float32),
        grad_v.astype(np.float32),
    )


def _interpolate(image: SmoothedImage, uv: np.ndarray) -> np.ndarray:
    """Spline values at pixel positions ``uv`` (..., 2)."""
    flat = uv.reshape(-1, 2)
    out = ndimage.map_coordinates(
        image.spline, [flat[:, 1], flat[:, 0]], order=3, prefilter=False, mode="nearest"
    )
    return out.reshape(uv.shape[:-1])


def _gradient(image: SmoothedImage, uv: np.ndarray) -> np.ndarray:
    """Gradients (..., 2) at pixel positions ``uv`` (..., 2), bilinear (cv2.remap, whose maps
    must be under 32767 rows: the positions are laid out 1024 to a row)."""
    flat = uv.reshape(-1, 2).astype(np.float32)
    n = len(flat)
    rows = -(-n // 1024)
    maps = np.zeros((rows * 1024, 2), np.float32)
    maps[:n] = flat
    maps = maps.reshape(rows, 1024, 2)
    out = []
    for grad in (image.grad_u, image.grad_v):
        at = cv2.remap(grad, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out.append(at.ravel()[:n])
    return np.stack(out, axis=-1).astype(np.float64).reshape(uv.shape)


def refine_corners(
    image: np.ndarray | SmoothedImage,
    corners_px: np.ndarray,
    radius_px: np.ndarray | float,
    K: np.ndarray | None = None,
    dist: np.ndarray | None = None,
    tol_px: float = REFINE_TOL_PX,
) -> tuple[np.ndarray, np.ndarray]:
    """Checkerboard corners refined by a point-symmetry fit: ``(corners_px (N, 2), ok (N,))``.

    Two straight lines crossing at c look the same after a half turn about c, whatever the
    perspective, and so does the image after any isotropic blur. Each corner moves (Gauss-Newton)
    to the point c that minimises the weighted squared difference between the image at c + d
    and at c - d over a window of half-width ``radius_px`` (scalar or (N,), pixels; Gaussian
    weights, sigma half of it), on the image blurred by ``REFINE_BLUR_SIGMA_PX`` and
    interpolated by cubic splines (``image``: a grey image, or its :func:`smooth_image`),
    until no corner moves by more than ``tol_px`` (or ``REFINE_MAX_ITER`` iterations).

    With ``K`` and ``dist`` (a first calibration), the window is a square in undistorted
    coordinates, ``radius_px`` in pixels of focal length ``K``, mapped into the image through
    the distortion, so that the lens's bending of the lines does not bias the fit.

    ``ok`` is false (and the row NaN) where a corner was NaN, its window (shrunk by up to half
    to fit) left the image, it moved more than ``REFINE_MAX_SHIFT`` times its half-width, or
    the result does not look like a checkerboard corner (contrast below ``REFINE_MIN_CONTRAST``
    or mismatch with its half-turned copy above ``REFINE_MAX_ASYMMETRY`` of it).
    """
    start = np.asarray(corners_px, np.float64).reshape(-1, 2)
    radius = np.broadcast_to(np.asarray(radius_px, np.float64), (len(start),)).copy()
    out = np.full_like(start, np.nan)
    ok = np.isfinite(start).all(axis=1) & np.isfinite(radius) & (radius > 0)
    if not ok.any():
        return out, ok
    image = image if isinstance(image, SmoothedImage) else smooth_image(image)
    h, w = image.shape
    offsets, weights = _symmetry_stencil()
    lens = K is not None
    if lens:
        K = np.asarray(K, np.float64)
        dist = np.zeros(5) if dist is None else np.asarray(dist, np.float64)
        focal = np.array([K[0, 0], K[1, 1]])

    def window(c: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image positions (n, M, 2) of c + d and c - d."""
        d = offsets[None] * r[:, None, None]
        if not lens:
            return c[:, None] + d, c[:, None] - d
        x0 = cv2.undistortPoints(c.reshape(-1, 1, 2), K, dist, None, None, None, UNDISTORT_CRITERIA)
        x0 = x0.reshape(-1, 1, 2)
        pts = np.concatenate([x0 + d / focal, x0 - d / focal], axis=1)
        pts3 = np.concatenate([pts, np.ones(pts.shape[:-1] + (1,))], axis=-1).reshape(-1, 1, 3)
        uv, _ = cv2.projectPoints(pts3, np.zeros(3), np.zeros(3), K, dist)
        uv = uv.reshape(pts.shape)
        return uv[:, : len(offsets)], uv[:, len(offsets) :]

    def inside(plus: np.ndarray, minus: np.ndarray) -> np.ndarray:
        lo = np.minimum(plus.min(axis=1), minus.min(axis=1))
        hi = np.maximum(plus.max(axis=1), minus.max(axis=1))
        return (
            (lo >= REFINE_EDGE_PX).all(axis=1)
            & (hi[:, 0] <= w - 1 - REFINE_EDGE_PX)
            & (hi[:, 1] <= h - 1 - REFINE_EDGE_PX)
        )

    idx = np.flatnonzero(ok)
    c, r = start[idx].copy(), radius[idx]
    fits = inside(*window(c, r))
    for _ in range(3):  # shrink windows that leave the image, by up to half
        if fits.all():
            break
        r = np.where(fits, r, r * 0.8)
        fits = inside(*window(c, r))
    good = np.ones(len(c), bool)
    active = fits.copy()
    for _ in range(REFINE_MAX_ITER):
        if not active.any():
            break
        a = np.flatnonzero(active)
        plus, minus = window(c[a], r[a])
        res = _interpolate(image, plus) - _interpolate(image, minus)
        jac = _gradient(image, plus) - _gradient(image, minus)
        A = np.einsum("m,nmi,nmj->nij", weights, jac, jac)
        b = np.einsum("m,nmi,nm->ni", weights, jac, res)
        det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
        solvable = det > 1e-12 * np.maximum(A[:, 0, 0] * A[:, 1, 1], 1e-300)
        step = np.zeros((len(a), 2))
        step[solvable] = -np.linalg.solve(A[solvable], b[solvable][..., None])[..., 0]
        step = np.clip(step, -1.0, 1.0)
        c[a] += step
        good[a] = solvable
        moved = np.abs(step).max(axis=1) >= tol_px
        active[a] = solvable & moved & (np.linalg.norm(c[a] - start[idx][a], axis=1) <= 2 * r[a])
    plus, minus = window(c, r)
    vp, vm = _interpolate(image, plus), _interpolate(image, minus)
    both = np.concatenate([vp, vm], axis=1)
    contrast = np.percentile(both, 95, axis=1) - np.percentile(both, 5, axis=1)
    mismatch = np.sqrt((weights * (vp - vm) ** 2).sum(axis=1) / weights.sum())
    keep = (
        fits
        & good
        & inside(plus, minus)
        & (np.linalg.norm(c - start[idx], axis=1) <= REFINE_MAX_SHIFT * r)
        & (contrast >= REFINE_MIN_CONTRAST)
        & (mismatch <= REFINE_MAX_ASYMMETRY * contrast)
    )
    ok[idx] = keep
    out[idx[keep]] = c[keep]
    return out, ok


def refine_view(
    image: np.ndarray | SmoothedImage,
    corners_px: np.ndarray,
    object_mm: np.ndarray,
    square_mm: float,
    K: np.ndarray | None = None,
    dist: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The corners of one view refined (:func:`refine_corners`) with windows reaching
    ``REFINE_RADIUS_FRACTION`` of the way to the nearest neighbouring corner (measured in
    undistorted pixels when ``K`` and ``dist`` are given), within ``REFINE_RADIUS_PX``:
    ``(corners_px (n, 2), object_mm (n, 3))`` of the corners kept, in the input order."""
    uv = np.asarray(corners_px, np.float64).reshape(-1, 2)
    obj = np.asarray(object_mm, np.float64).reshape(-1, 3)
    if len(uv) == 0:
        return uv.copy(), obj.copy()
    at = uv
    if K is not None:
        xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist, None, None, None, UNDISTORT_CRITERIA)
        at = xy.reshape(-1, 2) * [K[0, 0], K[1, 1]]
    spacing = neighbour_spacing_px(at, obj, square_mm)
    radius = np.clip(REFINE_RADIUS_FRACTION * spacing, *REFINE_RADIUS_PX)
    refined, ok = refine_corners(image, uv, radius, K, dist)
    return refined[ok], obj[ok]


def find_whole_board(gray: np.ndarray, board: dict, image: SmoothedImage | None = None) -> BoardImage:
    """The whole board in a uint8 grey image (``findChessboardCornersSB``, the board's own order,
    refined by :func:`refine_view`; ``image``: the :func:`smooth_image` of ``gray`` if at hand):
    a BoardImage named '' with ``whole`` true, or without corners when the board is not found."""
    pattern = board_pattern(board)
    found, corners = cv2.findChessboardCornersSB(gray, pattern, SB_FLAGS)
    if not found or corners is None or len(corners) != pattern[0] * pattern[1]:
        return BoardImage("", None)
    corners = canonical_corner_order(gray, corners.reshape(-1, 2), pattern)
    image = smooth_image(gray) if image is None else image
    uv, obj = refine_view(image, corners, board_corners_mm(board), float(board["square_mm"]))
    return BoardImage("", uv, obj, whole=True)


def _grid_predictions(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each cell of a (rows, cols, 2) corner grid (NaN: empty) should lie, seen from its
    neighbours: (rows, cols, P, 2) predictions, NaN where a neighbour is missing, and the
    (rows, cols, P) corner spacing each is based on, pixels. Along each of the grid's four
    directions the next corner lies at ``3 a - 3 b + c`` (a, b, c the next three in that
    direction: quadratic extrapolation, exact for smoothly varying spacing) or ``2 a - b``;
    between its two neighbours in a row or column at their mean; and, from each diagonal
    neighbour d and the two corners a, b beside both, at ``a + b - d``."""
    rows, cols = grid.shape[:2]
    pad = np.full((rows + 6, cols + 6, 2), np.nan)
    pad[3:-3, 3:-3] = grid

    def at(dr: int, dc: int) -> np.ndarray:
        return pad[3 + dr : 3 + dr + rows, 3 + dc : 3 + dc + cols]

    preds, scales = [], []
    for dr, dc in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        a, b, c = at(dr, dc), at(2 * dr, 2 * dc), at(3 * dr, 3 * dc)
        quad = 3 * a - 3 * b + c
        preds.append(np.where(np.isfinite(quad), quad, 2 * a - b))
        scales.append(np.linalg.norm(a - b, axis=2))
    for dr, dc in ((0, 1), (1, 0)):
        a, b = at(dr, dc), at(-dr, -dc)
        preds.append((a + b) / 2)
        scales.append(np.linalg.norm(a - b, axis=2) / 2)
    for dr, dc in ((1, 1), (1, -1), (-1, 1), (-1, -1)):  # parallelograms: a + b - d
        a, b, d = at(dr, 0), at(0, dc), at(dr, dc)
        preds.append(a + b - d)
        scales.append(np.minimum(np.linalg.norm(a - d, axis=2), np.linalg.norm(b - d, axis=2)))
    return np.stack(preds, axis=2), np.stack(scales, axis=2)


def consistent_corners(grid_px: np.ndarray, tolerance: float = GRID_TOLERANCE) -> np.ndarray:
    """(rows, cols) bool: the corners of a (rows, cols, 2) grid (NaN: empty) that lie within
    ``tolerance`` times the local spacing of where at least one of their neighbour predictions
    (:func:`_grid_predictions`) puts them. A corner given the wrong grid index is a whole
    spacing off every prediction; its neighbours still agree with other ones."""
    preds, scales = _grid_predictions(grid_px)
    with np.errstate(invalid="ignore", divide="ignore"):
        miss = np.linalg.norm(preds - grid_px[:, :, None], axis=3) / scales
    return np.isfinite(grid_px[..., 0]) & (np.nan_to_num(miss, nan=np.inf) <= tolerance).any(axis=2)


def _crop(grid: np.ndarray) -> tuple[np.ndarray, tuple[int, int]]:
    """The grid without its empty outer rows and columns (at least one cell must be filled),
    and the (row, column) of the input where it starts."""
    filled = np.isfinite(grid[..., 0])
    rows, cols = np.flatnonzero(filled.any(axis=1)), np.flatnonzero(filled.any(axis=0))
    return grid[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1].copy(), (int(rows[0]), int(cols[0]))


def grow_grid(image: SmoothedImage, grid_px: np.ndarray, max_cells: int) -> np.ndarray:
    """The corner grid (rows, cols, 2; NaN: empty) grown to every corner of the board it can
    reach: each empty cell next to the grid is predicted from its neighbours
    (:func:`_grid_predictions`, averaged), refined (:func:`refine_corners`, window half-width
    ``REFINE_RADIUS_FRACTION`` of the local spacing, to ``GRID_REFINE_TOL_PX``) and kept if the
    fit accepts it within ``GRID_TOLERANCE`` of the spacing from the prediction and away from
    every corner already there; until nothing is added (a cell that failed is tried again only
    when more neighbours predict it). The grid never exceeds ``max_cells`` rows or columns.
    Growth stops by itself at the board's edge (the white margin holds no corner) and at the
    image's (the window must fit inside). A new grid is returned."""
    grid, _ = _crop(np.asarray(grid_px, np.float64))
    origin = np.zeros(2, np.int64)  # index of grid[0, 0] in the seed's frame
    failed: dict[tuple[int, int], int] = {}  # cell -> number of predictions when it failed
    for _ in range(4 * max_cells):
        grid = np.pad(grid, ((1, 1), (1, 1), (0, 0)), constant_values=np.nan)
        origin -= 1
        preds, scales = _grid_predictions(grid)
        have = np.isfinite(preds).all(axis=3)
        n = have.sum(axis=2)
        with np.errstate(invalid="ignore", divide="ignore"):
            guess = np.where(have[..., None], preds, 0.0).sum(axis=2) / n[..., None]
            scale = np.where(have, scales, 0.0).sum(axis=2) / n
        cand = ~np.isfinite(grid[..., 0]) & (n > 0)
        if grid.shape[0] - 2 >= max_cells:  # no room for another row
            cand[[0, -1]] = False
        if grid.shape[1] - 2 >= max_cells:
            cand[:, [0, -1]] = False
        for (fr, fc), fn in failed.items():
            r_, c_ = fr - origin[0], fc - origin[1]
            if 0 <= r_ < grid.shape[0] and 0 <= c_ < grid.shape[1] and n[r_, c_] <= fn:
                cand[r_, c_] = False
        if not cand.any():
            break
        r, c = np.nonzero(cand)
        start, spacing = guess[r, c], scale[r, c]
        radius = np.clip(REFINE_RADIUS_FRACTION * spacing, *REFINE_RADIUS_PX)
        refined, ok = refine_corners(image, start, radius, tol_px=GRID_REFINE_TOL_PX)
        ok &= np.linalg.norm(refined - start, axis=1) <= GRID_TOLERANCE * spacing
        existing = grid[np.isfinite(grid[..., 0])]
        for k in np.flatnonzero(ok):
            crowded = np.linalg.norm(existing - refined[k], axis=1).min() < 0.5 * spacing[k]
            crowded |= (np.linalg.norm(refined[ok] - refined[k], axis=1) < 0.5 * spacing[k]).sum() > 1
            ok[k] = not crowded
        for k in np.flatnonzero(~ok):
            failed[(int(r[k] + origin[0]), int(c[k] + origin[1]))] = int(n[r[k], c[k]])
        grid[r[ok], c[ok]] = refined[ok]
        grid, (dr, dc) = _crop(grid)
        origin += (dr, dc)
    return grid


def saddle_points(image: SmoothedImage) -> tuple[np.ndarray, np.ndarray]:
    """Candidate checkerboard corners of a smoothed image: ``(uv_px (N, 2), strength (N,))``,
    strongest first. At a corner the blurred image is a saddle: its Hessian determinant is
    strongly negative (about -(0.14 contrast)^2 per px^4 at 1.5 px blur); the candidates are the
    local maxima (``SADDLE_NMS_PX``) of ``-det`` above ``SADDLE_MIN``, with pixel positions."""
    g_uu = np.gradient(image.grad_u, axis=1)
    g_uv = np.gradient(image.grad_u, axis=0)
    g_vv = np.gradient(image.grad_v, axis=0)
    saddle = g_uv**2 - g_uu * g_vv
    peak = cv2.dilate(saddle, np.ones((2 * SADDLE_NMS_PX + 1,) * 2, np.uint8))
    v, u = np.nonzero((saddle >= peak) & (saddle > SADDLE_MIN))
    strength = saddle[v, u].astype(np.float64)
    order = np.argsort(-strength, kind="stable")
    return np.c_[u, v][order].astype(np.float64), strength[order]


def _seed_grids(image: SmoothedImage) -> list[np.ndarray]:
    """3 x 3 corner grids (3, 3, 2) found around the strongest saddle points
    (:func:`saddle_points`, refined by :func:`refine_corners`): a point whose four nearest
    neighbours form two opposite pairs, with corners at the four diagonal predictions too, and
    the four squares between them alternately dark and bright. At most ``SEED_TRIES``, best
    first."""
    from scipy.spatial import cKDTree

    cand, _ = saddle_points(image)
    if len(cand) < 9:
        return []
    cand = cand[:SEED_MAX_POINTS]
    near = cKDTree(cand).query(cand, k=2)[0][:, 1]
    refined, ok = refine_corners(image, cand, np.clip(0.5 * near, 2.0, SEED_RADIUS_PX), tol_px=0.01)
    pts = refined[ok]
    if len(pts) < 9:
        return []
    tree = cKDTree(pts)
    seeds = []
    for p in pts:
        grid = _seed_around(image, tree, pts, p)
        if grid is not None:
            seeds.append(grid)
            if len(seeds) >= SEED_TRIES:
                break
    return seeds


def _seed_around(image: SmoothedImage, tree, pts: np.ndarray, p: np.ndarray) -> np.ndarray | None:
    """The 3 x 3 grid (3, 3, 2) of corners ``pts`` centred on corner ``p``, or None: two pairs
    of opposite neighbours among its ``SEED_NEIGHBOURS`` nearest (on a sheared grid a diagonal
    neighbour can be nearer than a side one, so every non-collinear choice is tried, shortest
    first) whose four diagonal predictions are corners too, with the four squares between them
    alternately dark and bright (which a basis along a diagonal fails)."""
    k = min(SEED_NEIGHBOURS + 1, len(pts))
    d, idx = tree.query(p, k=k)
    v = pts[idx[1:]] - p
    n = len(v)
    pairs = [(v[i] - v[j]) / 2 for i in range(n) for j in range(i + 1, n)
             if np.linalg.norm(v[i] + v[j]) < GRID_TOLERANCE * min(d[i + 1], d[j + 1])]  # fmt: skip
    bases = [
        (e1, e2)
        for i, e1 in enumerate(pairs)
        for e2 in pairs[i + 1 :]
        if abs(e1[0] * e2[1] - e1[1] * e2[0]) >= 0.3 * np.linalg.norm(e1) * np.linalg.norm(e2)
    ]
    bases.sort(key=lambda e: np.linalg.norm(e[0]) + np.linalg.norm(e[1]))
    for e1, e2 in bases:
        grid = p + np.arange(-1, 2)[:, None, None] * e2 + np.arange(-1, 2)[None, :, None] * e1
        dd, ii = tree.query(grid.reshape(-1, 2))
        if (dd > GRID_TOLERANCE * min(np.linalg.norm(e1), np.linalg.norm(e2))).any():
            continue
        grid = pts[ii].reshape(3, 3, 2)
        centres = (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:]) / 4
        grey = _interpolate(image, centres)
        dark_bright = grey[0, 0] + grey[1, 1] - grey[0, 1] - grey[1, 0]
        spread = max(abs(grey[0, 0] - grey[1, 1]), abs(grey[0, 1] - grey[1, 0]))
        if abs(dark_bright) / 2 >= REFINE_MIN_CONTRAST and spread <= 0.25 * abs(dark_bright):
            return grid
    return None


def checkered(image: SmoothedImage, grid_px: np.ndarray) -> bool:
    """True when the squares between the corners of a (rows, cols, 2) grid (NaN: empty) are
    alternately dark and bright, as on a checkerboard, for at least ``CHECKER_AGREEMENT`` of
    the squares with four corners (a grid that skips corners, or runs along diagonals, has grey
    corners at its squares' centres)."""
    centres = (grid_px[:-1, :-1] + grid_px[:-1, 1:] + grid_px[1:, :-1] + grid_px[1:, 1:]) / 4
    have = np.isfinite(centres[..., 0])
    if not have.any():
        return False
    grey = _interpolate(image, centres[have])
    r, c = np.nonzero(have)
    parity = (r + c) % 2 == 0
    if parity.all() or not parity.any():
        return False
    gap = grey[parity].mean() - grey[~parity].mean()
    if abs(gap) < REFINE_MIN_CONTRAST:
        return False
    mid = (grey[parity].mean() + grey[~parity].mean()) / 2
    right = np.where(parity, grey > mid, grey < mid) if gap > 0 else np.where(parity, grey < mid, grey > mid)
    return bool(right.mean() >= CHECKER_AGREEMENT)


def find_partial_board(gray: np.ndarray, board: dict, image: SmoothedImage | None = None) -> BoardImage:
    """The part of a board seen in an image it runs off: a BoardImage named '' (``whole`` false),
    without corners if fewer than ``PARTIAL_MIN_CORNERS`` corners in at least
    ``PARTIAL_MIN_LINES`` rows and columns are found.

    A 3 x 3 block of corners is found among the image's saddle points (:func:`_seed_grids`) and
    grown to every corner of the board in the image (:func:`grow_grid`); a grid whose squares
    are not alternately dark and bright (:func:`checkered`) is discarded, and of the grids grown
    from up to ``SEED_TRIES`` seeds the largest is kept, its corners checked against their
    neighbours (:func:`consistent_corners`) and refined once more (:func:`refine_view`).
    Object points are the grid's own (column, row) times the square size, z = 0, the grid
    turned right-handed (:func:`right_handed`): for the intrinsics each view has its own pose,
    so no marker is needed to tell which part of the board is seen.
    (``cv2.findChessboardCornersSBWithMeta`` with ``CALIB_CB_LARGER`` was tried for this: on
    rendered corner boards it found no grid, or a grid along the diagonals or of every other
    corner, in a third of the images, and invents corners up to ~50 px off.) ``image``: the
    :func:`smooth_image` of ``gray`` if at hand.
    """
    image = smooth_image(gray) if image is None else image
    best = None
    for seed in _seed_grids(image):
        if best is not None:
            known = best[np.isfinite(best[..., 0])]
            if np.linalg.norm(known - seed[1, 1], axis=1).min() < 0.5 * np.linalg.norm(
                seed[1, 1] - seed[1, 0]
            ):
                continue  # already part of the grid grown
        grid = grow_grid(image, seed, max(board_pattern(board)))
        if checkered(image, grid) and (
            best is None or np.isfinite(grid[..., 0]).sum() > np.isfinite(best[..., 0]).sum()
        ):
            best = grid
    if best is None:
        return BoardImage("", None)
    grid = right_handed(best)
    grid[~consistent_corners(grid)] = np.nan
    r, c = np.nonzero(np.isfinite(grid[..., 0]))
    square = float(board["square_mm"])
    uv, obj = refine_view(image, grid[r, c], np.c_[c * square, r * square, np.zeros(len(r))], square)
    return _enough(BoardImage("", uv, obj, whole=False), square)


def _enough(view: BoardImage, square_mm: float) -> BoardImage:
    """The view, or one without corners if it keeps fewer than ``PARTIAL_MIN_CORNERS`` corners
    or spans fewer than ``PARTIAL_MIN_LINES`` rows or columns."""
    if view.corners_px is None or len(view.corners_px) < PARTIAL_MIN_CORNERS:
        return BoardImage(view.image, None)
    ij = grid_indices(view.object_mm, square_mm)
    if min(len(np.unique(ij[:, 0])), len(np.unique(ij[:, 1]))) < PARTIAL_MIN_LINES:
        return BoardImage(view.image, None)
    return view


def find_board(gray: np.ndarray, board: dict, name: str = "") -> BoardImage:
    """The board in a uint8 grey image: whole (:func:`find_whole_board`), else the part of it
    that is seen (:func:`find_partial_board`), else a BoardImage without corners; named
    ``name``."""
    image = smooth_image(gray)
    view = _enough(find_whole_board(gray, board, image), float(board["square_mm"]))
    if view.corners_px is None:
        view = find_partial_board(gray, board, image)
    return replace(view, image=name)


def find_board_corners(gray: np.ndarray, board: dict) -> np.ndarray | None:
    """(N, 2) float64 inner corners of the whole board in a uint8 grey image, in the order of
    :func:`triaxtrack.kit.board_corners_mm`, refined; None unless every corner is found."""
    view = find_whole_board(gray, board)
    nx, ny = board_pattern(board)
    if view.corners_px is None or len(view.corners_px) != nx * ny:
        return None
    return view.corners_px


def list_board_images(camera: str, folder: str | Path) -> list[Path]:
    """The board images of one camera (``folder/*.png``, sorted); CalibrationError if none."""
    folder = Path(folder)
    if not folder.is_dir():
        raise CalibrationError(f"camera {camera}: calibration folder {folder} not found")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not paths:
        raise CalibrationError(f"camera {camera}: no board images (*.png) in {folder}")
    return paths


def _read_gray(camera: str, path: str | Path) -> np.ndarray:
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if gray is None:
        raise CalibrationError(f"camera {camera}: cannot read board image {path}")
    return gray


def detect_boards(
    camera: str, image_paths: Sequence[str | Path], board: dict
) -> tuple[tuple[int, int], list[BoardImage]]:
    """Read each image (grey) and find the board, whole or partial (:func:`find_board`):
    ``((width, height), [BoardImage, ...])`` in the order of ``image_paths``.

    CalibrationError naming the camera and the file when an image cannot be read or its size
    differs from the first image's.
    """
    if not image_paths:
        raise CalibrationError(f"camera {camera}: no board images given")
    size = None
    found = []
    for path in image_paths:
        gray = _read_gray(camera, path)
        if size is None:
            size = (gray.shape[1], gray.shape[0])
            first = path
        elif (gray.shape[1], gray.shape[0]) != size:
            raise CalibrationError(
                f"camera {camera}: board image {path} is {gray.shape[1]}x{gray.shape[0]} px, "
                f"but {first} is {size[0]}x{size[1]} px"
            )
        found.append(find_board(gray, board, Path(path).name))
    return size, found


def refine_boards(
    camera: str,
    image_paths: Sequence[str | Path],
    found: Sequence[BoardImage],
    board: dict,
    K: np.ndarray,
    dist: np.ndarray,
) -> list[BoardImage]:
    """The boards of :func:`detect_boards` with their corners refined again, the windows drawn
    in undistorted coordinates through a first calibration ``K``, ``dist`` (:func:`refine_view`):
    a new list, in the same order; a view left with too few corners loses its board."""
    by_name = {Path(p).name: p for p in image_paths}
    out = []
    square = float(board["square_mm"])
    for view in found:
        if view.corners_px is None:
            out.append(view)
            continue
        gray = _read_gray(camera, by_name[view.image])
        uv, obj = refine_view(gray, view.corners_px, _object_points(view, board), square, K, dist)
        out.append(_enough(BoardImage(view.image, uv, obj, view.whole), square))
    return out


# ---------------------------------------------------------------- calibration


def _object_points(view: BoardImage, board: dict) -> np.ndarray:
    return board_corners_mm(board) if view.object_mm is None else view.object_mm


def _fit(
    views: Sequence[BoardImage],
    board: dict,
    size: tuple[int, int],
    model: str,
    guess: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """calibrateCamera on the views (from ``guess`` = (K, dist) if given):
    ``(rms_px, K, dist (all OpenCV returns), per-view rms_px)``."""
    flags = MODELS[model][0]
    obj = [_object_points(v, board).astype(np.float32) for v in views]
    img = [v.corners_px.astype(np.float32).reshape(-1, 1, 2) for v in views]
    K0, d0 = (None, None) if guess is None else (guess[0].copy(), guess[1].copy())
    if guess is not None:
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    out = cv2.calibrateCameraExtended(obj, img, size, K0, d0, flags=flags, criteria=CALIBRATE_CRITERIA)
    rms, K, dist, per_view = out[0], out[1], out[2], out[7]
    return float(rms), K, dist.ravel().copy(), per_view.ravel().astype(np.float64)


def fit_views(
    views: Sequence[BoardImage], board: dict, size: tuple[int, int], model: str
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Two-stage calibration: ``(rms_px, K, dist, per-view rms_px)``, dist with the model's
    coefficients only. With at least ``MIN_WHOLE_BOARDS`` whole boards and some partial ones,
    the whole boards are fitted first and every view is then fitted from that start; otherwise
    every view is fitted from scratch. (Partial boards crowd into the image corners, where the
    distortion is strongest; fitted from scratch with the others, one demo camera of 13 settled
    1.3 px off in principal point and 2.2 px in its undistortion map, against 0.04 and 0.18 px
    from the whole boards' start, first-pass corners.)"""
    whole = [v for v in views if v.whole]
    guess = None
    if MIN_WHOLE_BOARDS <= len(whole) < len(views):
        _, K0, d0, _ = _fit(whole, board, size, model)
        guess = (K0, d0)
    rms, K, dist, per_view = _fit(views, board, size, model, guess)
    return rms, K, dist[: MODELS[model][1]].copy(), per_view


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
    """Calibrate one camera from its detected boards (:func:`fit_views`, outlier images dropped
    until none is left); returns the result mapping (module docstring) without ``passes``.
    ``folder`` only names where the images came from in errors.

    CalibrationError naming the camera (and ``folder``) when fewer than ``cfg.min_images``
    images are usable: no board found, or rejected as outliers.
    """
    where = f" in {folder}" if str(folder) else ""
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
            rms, K, dist, per_view = fit_views(used, board, size, cfg.model)
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
            r = view_rms_px(_object_points(b, board), b.corners_px, K, dist)
        images.append({
            "image": b.image,
            "board": b.kind,
            "n_corners": 0 if b.corners_px is None else len(b.corners_px),
            "rms_px": r,
            "used": b.image in used_rms,
            "reason": reason[b.image],
        })  # fmt: skip
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
        "n_corners_used": int(sum(len(b.corners_px) for b in used)),
        "outlier_limit_px": float(limit),
        "images": images,
        "board": {k: board[k] for k in ("squares_x", "squares_y", "square_mm")},
    }


def calibrate_camera(camera: str, folder: str | Path, kit_dir: str | Path, cfg: CalibrationConfig) -> dict:
    """Calibrate one camera from its board images ``folder/*.png`` and the kit's board.json.

    Boards are found and their corners refined (:func:`detect_boards`), the camera calibrated
    (:func:`calibrate_views`); with ``cfg.passes`` 2 the corners are then refined again through
    that calibration (:func:`refine_boards`) and the camera calibrated again from them.
    The result mapping is described in the module docstring. CalibrationError naming the camera
    and the folder or file when the images are missing, unreadable, or too few are usable.
    """
    board = read_board(kit_dir)
    paths = list_board_images(camera, folder)
    size, found = detect_boards(camera, paths, board)
    result = calibrate_views(camera, found, size, board, cfg, folder)
    if cfg.passes == 2:
        K, dist = np.array(result["K"]), np.array(result["dist"])
        found = refine_boards(camera, paths, found, board, K, dist)
        result = calibrate_views(camera, found, size, board, cfg, folder)
    return {**result, "passes": cfg.passes}


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
    kinds = [im.get("board") for im in result["images"] if im["used"]]
    lines = [
        f"{result['camera']}: {result['model']} model, fx {K[0][0]:.2f} fy {K[1][1]:.2f} "
        f"cx {K[0][2]:.2f} cy {K[1][2]:.2f} px, dist {[round(d, 5) for d in result['dist']]}",
        f"rms {result['rms_px']:.4f} px over {result['n_images_used']} images "
        f"({kinds.count('whole')} whole boards, {kinds.count('partial')} partial; "
        f"{result.get('n_corners_used', '?')} corners; "
        f"{result['n_images_found']} of {result['n_images']} with a board found; "
        f"outlier limit {result['outlier_limit_px']:.3f} px; corner passes {result.get('passes', 1)})",
    ]
    for im in result["images"]:
        if not im["used"]:
            rms = "" if im["rms_px"] is None else f" (rms {im['rms_px']:.3f} px)"
            lines.append(f"  not used: {im['image']}{rms}: {im['reason']}")
    return "\n".join(lines)
