"""The calibration's files: the kit's board.json, a camera's board images, and the result
(turned into a Camera, summarised for the job log; the JSON file itself is read and written by
:mod:`triaxtrack.testfolder`)."""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import cv2
import numpy as np

from triaxtrack.calibrate.config import CalibrationError
from triaxtrack.kit_design import BoardDesign, board_design
from triaxtrack.optics import Camera

IMAGE_SUFFIXES = (".png",)  # board images of test-folder.md: calibration/<camera>/*.png


def read_board(kit_dir: str | Path) -> BoardDesign:
    """The checkerboard of a kit export (``KIT/board.json``: ``target-kit.md`` requires its type,
    squares and square size) as the kit design's ``board`` section; other keys (the export's
    ``inner_corners`` and ``units``, a marker dictionary another printer writes) are not read,
    and a missing ``margin_mm`` (the printed sheet's, which calibration does not use) is 0.
    ValueError naming the file."""
    path = Path(kit_dir) / "board.json"
    try:
        doc = json.loads(path.read_text())
        if doc.get("type", "checkerboard") != "checkerboard":
            raise ValueError(f"board type {doc['type']!r} is not a checkerboard")
        for key in ("squares_x", "squares_y", "square_mm"):
            if key not in doc:
                raise ValueError(f"no {key!r}")
        if min(int(doc["squares_x"]), int(doc["squares_y"])) < 3 or float(doc["square_mm"]) <= 0:
            raise ValueError("needs at least 3 x 3 squares of positive size")
        known = {f.name for f in fields(BoardDesign)}
        return board_design({"margin_mm": 0.0} | {k: v for k, v in doc.items() if k in known})
    except (OSError, ValueError, TypeError) as err:
        raise ValueError(f"{path}: not a usable calibration board: {err}") from err


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
