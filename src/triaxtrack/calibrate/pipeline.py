"""One camera end to end: its boards found, the camera fitted, the corners refined again through
that fit and the camera fitted again (:func:`calibrate_camera`); the workflow's stage, from the
files to the result JSON (:func:`run_calibrate_camera`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from triaxtrack.calibrate.board import BoardImage, _enough, find_board
from triaxtrack.calibrate.config import CalibrationConfig, CalibrationError
from triaxtrack.calibrate.corners import refine_view
from triaxtrack.calibrate.files import _read_gray, format_calibration, list_board_images, read_board
from triaxtrack.calibrate.fit import _object_points, calibrate_views
from triaxtrack.kit_design import BoardDesign
from triaxtrack.testfolder import write_calibration


def detect_boards(
    camera: str, image_paths: Sequence[str | Path], board: BoardDesign
) -> tuple[tuple[int, int], list[BoardImage]]:
    """Read each image (grey) and find the board, whole or partial (:func:`find_board`):
    ``((width, height), [BoardImage, ...])`` in the order of ``image_paths``.

    CalibrationError naming the camera and the file when an image cannot be read or its size
    differs from the first image's.
    """
    if not image_paths:
        raise CalibrationError(f"camera {camera}: no board images given")
    size, first = (0, 0), image_paths[0]  # (the first image's size, set at k = 0)
    found = []
    for k, path in enumerate(image_paths):
        gray = _read_gray(camera, path)
        if k == 0:
            size = (gray.shape[1], gray.shape[0])
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
    board: BoardDesign,
    K: np.ndarray,
    dist: np.ndarray,
) -> list[BoardImage]:
    """The boards of :func:`detect_boards` with their corners refined again, the windows drawn
    in undistorted coordinates through a first calibration ``K``, ``dist`` (:func:`refine_view`):
    a new list, in the same order; a view left with too few corners loses its board."""
    by_name = {Path(p).name: p for p in image_paths}
    out = []
    square = float(board.square_mm)
    for view in found:
        if view.corners_px is None:
            out.append(view)
            continue
        gray = _read_gray(camera, by_name[view.image])
        uv, obj = refine_view(gray, view.corners_px, _object_points(view, board), square, K, dist)
        out.append(_enough(BoardImage(view.image, uv, obj, view.whole), square))
    return out


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


def run_calibrate_camera(
    *, camera: str, folder: str | Path, kit: str | Path, calibration: str | Path, calibration_cfg: dict
) -> None:
    """Rule calibrate_camera: calibrate ``camera`` from its board images in ``folder`` and the
    board of the kit folder ``kit`` (``calibration_cfg``: the config's ``calibration`` section);
    write the result, stamped with the package's version, to ``calibration`` and print its
    summary."""
    from triaxtrack import __version__

    cfg = CalibrationConfig.from_dict(calibration_cfg)
    result = {**calibrate_camera(camera, folder, kit, cfg), "triaxtrack_version": __version__}
    write_calibration(calibration, result)
    print(format_calibration(result))
