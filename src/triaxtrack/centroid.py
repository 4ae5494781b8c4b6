"""Sub-pixel centroids of dark dots on a lighter background.

Pixel coordinates follow OpenCV (the centre of the top-left pixel is (0, 0)).
"""

from __future__ import annotations

import cv2
import numpy as np

BLOB_LEVEL = 0.35  # fraction of the dot's contrast that delimits its blob before dilation


def local_centroid(gray: np.ndarray, uv_px: np.ndarray, half: int = 6) -> np.ndarray:
    """Contrast-weighted centroids of the dark blobs nearest to (N, 2) pixel positions.

    For each position, a ``(2 half + 1)``-pixel window is taken; the background level is the
    median of the window's border; the blob is the connected set of pixels darker than the
    background by ``BLOB_LEVEL`` of the darkest contrast that contains the pixel nearest the
    position, dilated by one pixel so that partly covered edge pixels count; the weights are
    ``background - grey`` clipped at 0. Returns (N, 2) float centroids, NaN where the window
    leaves the image, no blob is found, or the blob touches the window edge (not isolated).
    """
    g = np.asarray(gray, np.float64)
    h, w = g.shape
    uv = np.asarray(uv_px, np.float64).reshape(-1, 2)
    out = np.full((len(uv), 2), np.nan)
    ys, xs = np.mgrid[-half : half + 1, -half : half + 1]
    kernel = np.ones((3, 3), np.uint8)
    for i, (u, v) in enumerate(uv):
        if not np.isfinite(u + v):
            continue
        cu, cv = int(round(u)), int(round(v))
        if cu - half < 0 or cv - half < 0 or cu + half >= w or cv + half >= h:
            continue
        win = g[cv - half : cv + half + 1, cu - half : cu + half + 1]
        border = np.r_[win[0], win[-1], win[1:-1, 0], win[1:-1, -1]]
        bg = np.median(border)
        contrast = np.clip(bg - win, 0, None)
        peak = contrast.max()
        if peak <= 0:
            continue
        mask = (contrast > BLOB_LEVEL * peak).astype(np.uint8)
        n, lab = cv2.connectedComponents(mask, connectivity=4)
        near = lab[half - 1 : half + 2, half - 1 : half + 2]
        labels = near[near > 0]
        if labels.size == 0:
            continue
        blob = cv2.dilate((lab == np.bincount(labels).argmax()).astype(np.uint8), kernel) > 0
        if blob[0].any() or blob[-1].any() or blob[:, 0].any() or blob[:, -1].any():
            continue
        wts = contrast * blob
        s = wts.sum()
        out[i] = (cu + (wts * xs).sum() / s, cv + (wts * ys).sum() / s)
    return out
