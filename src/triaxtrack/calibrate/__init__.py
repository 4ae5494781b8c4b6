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

Modules:

* :mod:`~triaxtrack.calibrate.config`: :class:`CalibrationConfig`, the lens ``MODELS`` and
  :class:`CalibrationError`;
* :mod:`~triaxtrack.calibrate.corners`: the point-symmetry corner fit (:func:`refine_corners`,
  :func:`refine_view`) and the corners' grid indices and spacing;
* :mod:`~triaxtrack.calibrate.grid`: a partial board's corner grid, seeded among the image's
  saddle points and grown corner by corner;
* :mod:`~triaxtrack.calibrate.board`: the board in one image, whole or partial
  (:func:`find_board`, :class:`BoardImage`);
* :mod:`~triaxtrack.calibrate.fit`: the two-stage fit and the outlier rejection
  (:func:`fit_views`, :func:`calibrate_views`);
* :mod:`~triaxtrack.calibrate.files`: the kit's board.json, the board images and the result
  (:func:`calibrated_camera`, :func:`format_calibration`; its file:
  :func:`triaxtrack.testfolder.read_calibration`);
* :mod:`~triaxtrack.calibrate.pipeline`: one camera end to end (:func:`calibrate_camera`), and
  the workflow's stage (:func:`run_calibrate_camera`).
"""

from triaxtrack.calibrate.board import (
    PARTIAL_MIN_CORNERS,
    PARTIAL_MIN_LINES,
    SB_FLAGS,
    BoardImage,
    board_pattern,
    canonical_corner_order,
    find_board,
    find_board_corners,
    find_partial_board,
    find_whole_board,
    right_handed,
)
from triaxtrack.calibrate.config import MODELS, CalibrationConfig, CalibrationError
from triaxtrack.calibrate.corners import (
    REFINE_BLUR_SIGMA_PX,
    REFINE_EDGE_PX,
    REFINE_MAX_ASYMMETRY,
    REFINE_MAX_ITER,
    REFINE_MAX_SHIFT,
    REFINE_MIN_CONTRAST,
    REFINE_RADIUS_FRACTION,
    REFINE_RADIUS_PX,
    REFINE_STENCIL,
    REFINE_TOL_PX,
    SmoothedImage,
    grid_indices,
    neighbour_spacing_px,
    refine_corners,
    refine_view,
    smooth_image,
)
from triaxtrack.calibrate.files import (
    IMAGE_SUFFIXES,
    calibrated_camera,
    format_calibration,
    list_board_images,
    read_board,
)
from triaxtrack.calibrate.fit import (
    CALIBRATE_CRITERIA,
    MAD_TO_SIGMA,
    MAX_ROUNDS,
    MIN_WHOLE_BOARDS,
    calibrate_views,
    fit_views,
    outlier_limit_px,
    view_rms_px,
)
from triaxtrack.calibrate.grid import (
    CHECKER_AGREEMENT,
    GRID_REFINE_TOL_PX,
    GRID_TOLERANCE,
    SADDLE_MIN,
    SADDLE_NMS_PX,
    SEED_MAX_POINTS,
    SEED_NEIGHBOURS,
    SEED_RADIUS_PX,
    SEED_TRIES,
    checkered,
    consistent_corners,
    grow_grid,
    saddle_points,
)
from triaxtrack.calibrate.pipeline import calibrate_camera, detect_boards, refine_boards, run_calibrate_camera

__all__ = [
    "BoardImage", "CALIBRATE_CRITERIA", "CHECKER_AGREEMENT", "CalibrationConfig", "CalibrationError",
    "GRID_REFINE_TOL_PX", "GRID_TOLERANCE", "IMAGE_SUFFIXES", "MAD_TO_SIGMA", "MAX_ROUNDS",
    "MIN_WHOLE_BOARDS", "MODELS", "PARTIAL_MIN_CORNERS", "PARTIAL_MIN_LINES", "REFINE_BLUR_SIGMA_PX",
    "REFINE_EDGE_PX", "REFINE_MAX_ASYMMETRY", "REFINE_MAX_ITER", "REFINE_MAX_SHIFT", "REFINE_MIN_CONTRAST",
    "REFINE_RADIUS_FRACTION", "REFINE_RADIUS_PX", "REFINE_STENCIL", "REFINE_TOL_PX", "SADDLE_MIN",
    "SADDLE_NMS_PX", "SB_FLAGS", "SEED_MAX_POINTS", "SEED_NEIGHBOURS", "SEED_RADIUS_PX", "SEED_TRIES",
    "SmoothedImage", "board_pattern", "calibrate_camera", "calibrate_views", "calibrated_camera",
    "canonical_corner_order", "checkered", "consistent_corners", "detect_boards", "find_board",
    "find_board_corners", "find_partial_board", "find_whole_board", "fit_views", "format_calibration",
    "grid_indices", "grow_grid", "list_board_images", "neighbour_spacing_px", "outlier_limit_px",
    "read_board", "refine_boards", "refine_corners", "refine_view", "right_handed",
    "run_calibrate_camera",
    "saddle_points", "smooth_image", "view_rms_px",
]  # fmt: skip
