"""Finding the board in an image: the whole board (``cv2.findChessboardCornersSB``, put in the
board's own order), else the part of it the image holds (a grid grown from saddle points)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from triaxtrack.calibrate.corners import SmoothedImage, grid_indices, refine_view, smooth_image
from triaxtrack.calibrate.grid import _seed_grids, checkered, consistent_corners, grow_grid
from triaxtrack.kit import board_corners_mm
from triaxtrack.kit_design import BoardDesign

# findChessboardCornersSB: ACCURACY up-samples (sub-pixel positions on small boards),
# NORMALIZE_IMAGE equalises exposure, EXHAUSTIVE tries harder on strongly tilted boards
SB_FLAGS = cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE
# a partial board (find_partial_board): the fewest corners, rows and columns a usable view keeps
PARTIAL_MIN_CORNERS = 12
PARTIAL_MIN_LINES = 3


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

    def found_corners(self) -> np.ndarray:
        """``corners_px`` of a view in which the board was found (ValueError naming the image if not)."""
        if self.corners_px is None:
            raise ValueError(f"board image {self.image}: no board found, so no corners")
        return self.corners_px

    @property
    def kind(self) -> str | None:
        """``whole``, ``partial``, or None (no board)."""
        return None if self.corners_px is None else ("whole" if self.whole else "partial")


def board_pattern(board: BoardDesign) -> tuple[int, int]:
    """(columns, rows) of inner corners: ``(squares_x - 1, squares_y - 1)``."""
    return int(board.squares_x) - 1, int(board.squares_y) - 1


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


def find_whole_board(gray: np.ndarray, board: BoardDesign, image: SmoothedImage | None = None) -> BoardImage:
    """The whole board in a uint8 grey image (``findChessboardCornersSB``, the board's own order,
    refined by :func:`refine_view`; ``image``: the :func:`smooth_image` of ``gray`` if at hand):
    a BoardImage named '' with ``whole`` true, or without corners when the board is not found."""
    pattern = board_pattern(board)
    # flags 0: SB_FLAGS were passed as the third positional argument, which is OpenCV's
    # ``corners`` output, and so never applied; applying them finds other boards and moves the
    # corners by ~0.1 px (before refinement), a change of results left to its own commit
    found, corners = cv2.findChessboardCornersSB(gray, pattern, flags=0)
    if not found or corners is None or len(corners) != pattern[0] * pattern[1]:
        return BoardImage("", None)
    corners = canonical_corner_order(gray, corners.reshape(-1, 2), pattern)
    image = smooth_image(gray) if image is None else image
    uv, obj = refine_view(image, corners, board_corners_mm(board), float(board.square_mm))
    return BoardImage("", uv, obj, whole=True)


def find_partial_board(
    gray: np.ndarray, board: BoardDesign, image: SmoothedImage | None = None
) -> BoardImage:
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
    square = float(board.square_mm)
    uv, obj = refine_view(image, grid[r, c], np.c_[c * square, r * square, np.zeros(len(r))], square)
    return _enough(BoardImage("", uv, obj, whole=False), square)


def _enough(view: BoardImage, square_mm: float) -> BoardImage:
    """The view, or one without corners if it keeps fewer than ``PARTIAL_MIN_CORNERS`` corners
    or spans fewer than ``PARTIAL_MIN_LINES`` rows or columns."""
    if view.corners_px is None or len(view.corners_px) < PARTIAL_MIN_CORNERS:
        return BoardImage(view.image, None)
    if view.object_mm is None:
        raise ValueError(f"board image {view.image}: corners without their object points")
    ij = grid_indices(view.object_mm, square_mm)
    if min(len(np.unique(ij[:, 0])), len(np.unique(ij[:, 1]))) < PARTIAL_MIN_LINES:
        return BoardImage(view.image, None)
    return view


def find_board(gray: np.ndarray, board: BoardDesign, name: str = "") -> BoardImage:
    """The board in a uint8 grey image: whole (:func:`find_whole_board`), else the part of it
    that is seen (:func:`find_partial_board`), else a BoardImage without corners; named
    ``name``."""
    image = smooth_image(gray)
    view = _enough(find_whole_board(gray, board, image), float(board.square_mm))
    if view.corners_px is None:
        view = find_partial_board(gray, board, image)
    return replace(view, image=name)


def find_board_corners(gray: np.ndarray, board: BoardDesign) -> np.ndarray | None:
    """(N, 2) float64 inner corners of the whole board in a uint8 grey image, in the order of
    :func:`triaxtrack.kit.board_corners_mm`, refined; None unless every corner is found."""
    view = find_whole_board(gray, board)
    nx, ny = board_pattern(board)
    if view.corners_px is None or len(view.corners_px) != nx * ny:
        return None
    return view.corners_px
