"""Fitting one camera to its boards: two-stage ``cv2.calibrateCamera`` (:func:`fit_views`) and
the rejection of outlier images (:func:`calibrate_views`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from triaxtrack.calibrate.board import BoardImage
from triaxtrack.calibrate.config import MODELS, CalibrationConfig, CalibrationError
from triaxtrack.kit import board_corners_mm
from triaxtrack.kit_design import BoardDesign

CALIBRATE_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
MIN_WHOLE_BOARDS = 3  # the first fit uses the whole boards alone when there are at least this many
MAD_TO_SIGMA = 1.4826  # MAD of a normal distribution times this is its standard deviation
MAX_ROUNDS = 10  # outlier rejection rounds (each drops at least one image)


def _object_points(view: BoardImage, board: BoardDesign) -> np.ndarray:
    return board_corners_mm(board) if view.object_mm is None else view.object_mm


def _fit(
    views: Sequence[BoardImage],
    board: BoardDesign,
    size: tuple[int, int],
    model: str,
    guess: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """calibrateCamera on the views (from ``guess`` = (K, dist) if given):
    ``(rms_px, K, dist (all OpenCV returns), per-view rms_px)``."""
    flags = MODELS[model][0]
    obj = [_object_points(v, board).astype(np.float32) for v in views]
    img = [v.found_corners().astype(np.float32).reshape(-1, 1, 2) for v in views]
    K0, d0 = (None, None) if guess is None else (guess[0].copy(), guess[1].copy())
    if guess is not None:
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    # (OpenCV takes None for K and dist without a guess, as outputs only; its stub leaves None out)
    out = cv2.calibrateCameraExtended(obj, img, size, K0, d0,  # type: ignore[arg-type]
                                      flags=flags, criteria=CALIBRATE_CRITERIA)  # fmt: skip
    rms, K, dist, per_view = out[0], out[1], out[2], out[7]
    return float(rms), K, dist.ravel().copy(), per_view.ravel().astype(np.float64)


def fit_views(
    views: Sequence[BoardImage], board: BoardDesign, size: tuple[int, int], model: str
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


def _too_few(
    camera: str, found: Sequence[BoardImage], reason: dict[str, str], n: int, min_images: int, where: str
) -> CalibrationError:
    """The error for ``n`` usable images of ``found`` (fewer than ``min_images``), naming the
    images without a board and those rejected (``reason``: image -> why it is not used)."""
    missing = [b.image for b in found if b.corners_px is None]
    notes = []
    if missing:
        notes.append(f"board not found in {missing}")
    dropped = {k: v for k, v in reason.items() if v and k not in missing}
    if dropped:
        notes.append(f"rejected: {dropped}")
    detail = f" ({'; '.join(notes)})" if notes else ""
    return CalibrationError(
        f"camera {camera}: {n} usable board images of {len(found)}{where}, "
        f"at least {min_images} needed{detail}"
    )


def _fit_without_outliers(
    camera: str,
    found: Sequence[BoardImage],
    reason: dict[str, str],
    size: tuple[int, int],
    board: BoardDesign,
    cfg: CalibrationConfig,
    where: str,
) -> tuple[list[BoardImage], tuple[float, np.ndarray, np.ndarray, np.ndarray], float, dict[str, str]]:
    """:func:`fit_views` on the boards found, dropping the outlier images (:func:`outlier_limit_px`)
    and fitting again until none is left: ``(views used, (rms_px, K, dist, per-view rms_px),
    outlier limit px, reason)``, ``reason`` a copy of the input's (image -> why it is not used)
    with the outliers' reasons added. CalibrationError when fewer than ``cfg.min_images`` are
    left, the fit fails, or the rejection does not settle in ``MAX_ROUNDS`` rounds."""
    reason = dict(reason)
    used = [b for b in found if b.corners_px is not None]
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
            raise _too_few(camera, found, reason, len(used), cfg.min_images, where)
    else:
        raise CalibrationError(f"camera {camera}: outlier rejection did not settle in {MAX_ROUNDS} rounds")
    return used, (rms, K, dist, per_view), limit, reason


def _image_records(
    found: Sequence[BoardImage],
    used_rms: dict[str, float],
    reason: dict[str, str],
    board: BoardDesign,
    K: np.ndarray,
    dist: np.ndarray,
) -> list[dict]:
    """The result's ``images`` list (package docstring), one per image of ``found``; ``used_rms``:
    image -> its RMS in the fit, for the images used (the others' is measured under ``K``,
    ``dist`` by :func:`view_rms_px`)."""
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
    return images


def calibrate_views(
    camera: str,
    found: Sequence[BoardImage],
    size: tuple[int, int],
    board: BoardDesign,
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
    usable = [b for b in found if b.corners_px is not None]
    if len(usable) < cfg.min_images:
        raise _too_few(camera, found, reason, len(usable), cfg.min_images, where)
    used, (rms, K, dist, per_view), limit, reason = _fit_without_outliers(
        camera, found, reason, size, board, cfg, where
    )
    used_rms = dict(zip([b.image for b in used], per_view, strict=True))
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
        "n_corners_used": int(sum(len(b.found_corners()) for b in used)),
        "outlier_limit_px": float(limit),
        "images": _image_records(found, used_rms, reason, board, K, dist),
        "board": {"squares_x": board.squares_x, "squares_y": board.squares_y, "square_mm": board.square_mm},
    }
