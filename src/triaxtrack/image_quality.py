"""What a frame's footage is like: its pixel noise and its lens blur, measured from the frame.

Detection (:mod:`triaxtrack.detect`) sets its smoothing and its splitting of touching dots from
them, and identification the reach of a blurred edge. Grey levels and pixels (OpenCV's
convention: the centre of the top-left pixel is (0, 0)).
"""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd


def noise_sigma(gray: np.ndarray) -> float:
    """Standard deviation of the pixel noise of a grey frame, grey levels (Immerkaer's
    Laplacian-difference operator, made robust to edges by the median of its magnitude). Where a
    codec has flattened the noise (H.265 at crf 28 leaves most flat areas flat) it reads far
    below the sensor's: callers keep a floor of their own."""
    g = np.asarray(gray, np.float32)
    if min(g.shape) < 3:
        return 0.0
    kernel = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    r = cv2.filter2D(g, cv2.CV_32F, kernel, borderType=cv2.BORDER_REPLICATE)[1:-1, 1:-1]
    # the operator's gain on white noise is sqrt(36) = 6; 1.4826 MAD = sigma for a Gaussian
    return float(1.4826 * np.median(np.abs(r)) / 6.0)


# Lens blur from the steepest edge of the round dots large enough to hold a plateau: a dark disc
# of contrast C blurred by a Gaussian of sigma s has its steepest edge slope C / (sqrt(2 pi) s).
# The slope is read on the EDGE_SMOOTH_PX-smoothed frame with a normalised Sobel operator, whose
# own spread (with a sharp render's anti-aliasing) is EDGE_OPERATOR_PX (measured: 1.03 px on
# sharp renders at 720p and 1080p; 1.42-1.48 px with a 1 px lens blur), removed in quadrature.
EDGE_OPERATOR_PX = 1.03
EDGE_SMOOTH_PX = 0.7  # against noise on the slope
EDGE_MIN_AREA_PX = 40  # dots with a plateau (CT centre dots, large cell dots)


def blur_sigma(gray: np.ndarray, blobs: pd.DataFrame) -> float:
    """The frame's lens blur (Gaussian sigma, pixels) from the edges of its large round blobs
    (``blobs``: :func:`triaxtrack.detect.detect_blobs` columns, unsplit); 0 when it has none."""
    big = blobs[(blobs.area_px >= EDGE_MIN_AREA_PX) & (blobs.roundness > 0.7) & (blobs.fill > 0.8)]
    if len(big) == 0:
        return 0.0
    g = cv2.GaussianBlur(np.asarray(gray, np.float32), (0, 0), EDGE_SMOOTH_PX)
    grad = np.hypot(cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)) / 8
    h, w = grad.shape
    spread = []
    for r in big.itertuples():
        reach = int(np.ceil(r.major_px / 2 + 3))
        u, v = int(round(r.u_px)), int(round(r.v_px))
        win = grad[max(v - reach, 0) : min(v + reach + 1, h), max(u - reach, 0) : min(u + reach + 1, w)]
        if win.size and win.max() > 0:
            spread.append(r.contrast / (np.sqrt(2 * np.pi) * win.max()))
    if not spread:
        return 0.0
    return float(np.sqrt(max(np.median(spread) ** 2 - EDGE_OPERATOR_PX**2, 0.0)))
