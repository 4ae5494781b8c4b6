"""Per-target window measurement for tracking (``triaxtrack.track``): the dark blob nearest a
predicted position, measured against the window's own white level and noise.

In a square window around each prediction (all targets with the same window size at once, as
``(m, h, w)`` arrays):

* the **white level** ``W`` is the mean of the window's pixels between its 70th and 90th
  percentiles (the surface around the dot: dots cover well under 30 % of a window), and the
  **noise** ``sigma`` 1.4826 x the median deviation above ``W`` of the annulus's pixels (those
  farther than the blob's disc plus one pixel from the window centre), held between the frame's
  noise (the median over its windows: a codec flattens some) and ``STRUCTURE_K`` times it (the
  dark beyond an edge fills others), at least the 8-bit quantisation noise;
* a pixel is **ink** when its contrast ``W - grey`` exceeds ``ink_fraction`` x ``W`` and
  ``INK_NOISE_K`` x ``sigma``: both scale with a uniform change of brightness, unlike a fixed
  number of grey levels;
* the blob is the ink at the mean-shifted centre grown through connected ink within its disc;
  its **centroid** is contrast-weighted over the blob grown by one pixel (other ink excluded);
* its **normalised mass** ``m = sum(W - grey) / W`` over those pixels (in pixels: the area of an
  equally dark fully black dot) does not change when the whole window is brightened or dimmed;
  its standard uncertainty propagated from the pixel noise and the white level's is
  ``sigma_m^2 = n sigma^2 / W^2 + ((n - m) / W)^2 sigma_W^2`` (n pixels summed; ``sigma_W``
  the white level's uncertainty, ``sigma / sqrt(pixels averaged)``);
* the **centroid uncertainty** per axis, for ``c = sum(w x) / sum(w)`` with ``w = W - grey``:
  ``sigma_c^2 = (sigma^2 sum((x - c)^2) + sigma_W^2 (sum(x - c))^2) / (sum w)^2``, scaled by
  ``SIGMA_CALIBRATION`` (measured); ``sigma_px`` is the RMS of the two axes' (the standard
  uncertainty of either coordinate).

Pixels in OpenCV's convention (the centre of the top-left pixel is (0, 0)); grey levels of the
8-bit frame.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

MEAN_SHIFT_STEPS = 3  # re-centring steps of the disc; motion left after prediction is sub-pixel
INK_NOISE_K = 3.5  # ink: darker than the white level by at least this x the noise (one-sided
# Gaussian tail 2e-4: a stray ink pixel in one window in about twenty, and it must touch the blob)
QUANTISATION_NOISE = 1 / np.sqrt(12)  # grey levels: the noise floor of an 8-bit frame
MAD_TO_SIGMA = 1.4826  # median absolute deviation to standard deviation (normal noise)
WHITE_BAND = (70.0, 90.0)  # the white level's percentiles (dots cover well under 30 % of a window)
# the annulus's spread above the white level over the pixel noise: 0.647 for the half of normal
# noise above its mean (the trimmed white level sits a little above the surface's mean, and the
# dots' fringes widen the spread: noise 4 reads 5.2 on blurred synthetic dots, an overestimate)
ABOVE_WHITE_SPREAD = 0.647
ANNULUS_GAP_PX = 1.0  # the annulus starts this far beyond the disc (the blob's blurred fringe)
# The centroid's uncertainty propagated from the pixel noise misses the noise of which pixels
# cross the ink threshold at a blurred edge: on blurred, noisy synthetic dots (5-8 px, blur 1 px,
# noise 4, read as 5.2; tests/test_track.py) the RMS of error / propagated sigma is 1.55, so the
# propagated sigma is scaled by that
SIGMA_CALIBRATION = 1.55
GROW_PX = 1  # the centroid's weights: the blob grown by this (other ink excluded), as detection
MIN_WHITE = 10.0  # grey levels: a window whose white is darker is under-exposed (a blank or
# black frame): its noise is clipped at black, so no dot can be told from it ('lost')


class WindowMeasure(NamedTuple):
    """Per target (N rows): what :func:`measure_windows` found; NaN/0 where ``reason`` != ''."""

    uv: np.ndarray  # (N, 2) contrast-weighted centroid, pixels
    area: np.ndarray  # (N,) the blob's ink area, pixels
    mass: np.ndarray  # (N,) normalised mass: summed contrast / white level, pixels
    sigma_mass: np.ndarray  # (N,) its standard uncertainty from the pixel noise, pixels
    sigma_px: np.ndarray  # (N,) standard uncertainty of each centroid coordinate, pixels
    white: np.ndarray  # (N,) the window's white level, grey levels
    noise: np.ndarray  # (N,) the window's pixel noise (standard deviation), grey levels
    reason: np.ndarray  # (N,) object: '', 'edge', 'lost' or 'merged'


def _dilate(mask: np.ndarray) -> np.ndarray:
    """3x3 dilation of a stack of (m, h, w) masks (separable: rows, then columns)."""
    out = mask.copy()
    out[:, 1:] |= mask[:, :-1]
    out[:, :-1] |= mask[:, 1:]
    rows = out.copy()
    out[:, :, 1:] |= rows[:, :, :-1]
    out[:, :, :-1] |= rows[:, :, 1:]
    return out


def _dist2(xs: np.ndarray, ys: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(m, h, w) squared distances of window pixels from (m, 2) window-relative centres."""
    return (xs - c[:, 0, None, None]) ** 2 + (ys - c[:, 1, None, None]) ** 2


def _masked_median(values: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Median of each row of (m, p) ``values`` over its ``use`` entries (NaN where none)."""
    srt = np.sort(np.where(use, values, np.inf), axis=1)
    cnt = use.sum(axis=1)
    rows = np.arange(len(values))
    lo = srt[rows, np.maximum(cnt - 1, 0) // 2]
    hi = srt[rows, np.minimum(cnt // 2, values.shape[1] - 1)]
    return np.where(cnt > 0, (lo + hi) / 2, np.nan)


def window_levels(patch: np.ndarray, annulus: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The white level and pixel noise of (m, h, w) windows. The white level is the mean of each
    window's pixels between its ``WHITE_BAND`` percentiles (a plane fitted to the ``annulus``,
    an (m, h, w) mask, fails in a dense grid, whose annulus is mostly the neighbours' edges); the
    noise is the spread of the annulus's pixels above it, over ``ABOVE_WHITE_SPREAD``, at least
    the quantisation noise. Returns ``(white (m,), noise (m,), sigma_white (m,))``: the white
    level, the noise, and the white level's standard uncertainty."""
    m = len(patch)
    g = patch.reshape(m, -1)
    ring = np.broadcast_to(annulus, patch.shape).reshape(m, -1)
    lo, hi = np.percentile(g, WHITE_BAND, axis=1)  # a trimmed mean: no 8-bit steps
    band = (g >= lo[:, None]) & (g <= hi[:, None])
    white = (g * band).sum(axis=1) / np.maximum(band.sum(axis=1), 1)
    above = ring & (g >= white[:, None])
    noise = MAD_TO_SIGMA * _masked_median(g - white[:, None], above) / ABOVE_WHITE_SPREAD
    noise = np.maximum(np.nan_to_num(noise), QUANTISATION_NOISE)
    count = np.maximum(band.sum(axis=1), 3)
    return white, noise, noise / np.sqrt(count)


STRUCTURE_K = 3.0  # a window's spread above this x the frame's noise is structure, not noise


def measure_windows(
    gray: np.ndarray, uv_px: np.ndarray, radius_px: np.ndarray, ink_fraction: float, disc_margin_px: float
) -> WindowMeasure:
    """The dark blobs nearest (N, 2) predicted pixel positions (NaN rows: 'lost').

    ``radius_px`` (N,): the disc that holds a blob (its semi-major axis plus ``disc_margin_px``).
    See the module docstring for the rule; ``reason`` is 'edge' where the window leaves the image,
    'lost' where there is no ink at the centre, 'merged' where the blob runs on beyond its disc.
    """
    g = np.asarray(gray)
    H, W = g.shape
    uv_px = np.asarray(uv_px, np.float64).reshape(-1, 2)
    radius_px = np.asarray(radius_px, np.float64).reshape(-1)
    n = len(uv_px)
    out = np.full((n, 2), np.nan)
    area, mass, smass, spx = np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, np.nan)
    white_all, noise_all = np.full(n, np.nan), np.full(n, np.nan)
    reason = np.full(n, "", dtype=object)
    finite = np.isfinite(uv_px).all(axis=1) & np.isfinite(radius_px)
    reason[~finite] = "lost"
    half = np.where(finite, np.ceil(np.nan_to_num(radius_px)).astype(np.int64) + 2, 0)
    # the windows, grouped by size, and their levels first: the frame's noise is their median
    groups = []
    for h in np.unique(half[finite]):
        sel = np.nonzero(finite & (half == h))[0]
        cu = np.rint(uv_px[sel, 0]).astype(np.int64)
        cv = np.rint(uv_px[sel, 1]).astype(np.int64)
        inside = (cu - h >= 0) & (cv - h >= 0) & (cu + h < W) & (cv + h < H)
        reason[sel[~inside]] = "edge"
        sel, cu, cv = sel[inside], cu[inside], cv[inside]
        if len(sel) == 0:
            continue
        off = np.arange(-h, h + 1)
        patch = g[(cv[:, None, None] + off[None, :, None]), (cu[:, None, None] + off[None, None, :])]
        patch = patch.astype(np.float64)
        xs = off[None, None, :].astype(np.float64)
        ys = off[None, :, None].astype(np.float64)
        annulus = xs**2 + ys**2 > ((radius_px[sel] + ANNULUS_GAP_PX) ** 2)[:, None, None]
        groups.append((sel, cu, cv, patch, xs, ys, *window_levels(patch, annulus)))
    if not groups:
        return WindowMeasure(out, area, mass, smass, spx, white_all, noise_all, reason)
    frame_noise = max(float(np.median(np.concatenate([grp[7] for grp in groups]))), QUANTISATION_NOISE)
    for sel, cu, cv, patch, xs, ys, white, noise, s_white in groups:
        rad = radius_px[sel]
        # the codec flattens some windows' white (their spread reads below the noise) and the
        # dark beyond an edge fills others' (far above it): each is held to the frame's noise
        noise = np.clip(noise, frame_noise, STRUCTURE_K * frame_noise)
        contrast = white[:, None, None] - patch
        level = np.maximum(INK_NOISE_K * noise, ink_fraction * white)[:, None, None]
        ink = contrast > level
        sure = contrast > level + INK_NOISE_K * noise[:, None, None]  # ink beyond the noise
        wts = np.clip(contrast, 0, None)
        c = uv_px[sel] - np.c_[cu, cv]  # prediction relative to the window centre

        core = (rad - disc_margin_px)[:, None, None] ** 2
        for _ in range(MEAN_SHIFT_STEPS):  # ink within the blob's own size of the estimate
            w = wts * (ink & (_dist2(xs, ys, c) <= core))
            s = w.sum(axis=(1, 2))
            ok = s > 0
            c = np.where(ok[:, None], np.c_[(w * xs).sum(axis=(1, 2)), (w * ys).sum(axis=(1, 2))]
                         / np.where(ok, s, 1)[:, None], c)  # fmt: skip
        disc = _dist2(xs, ys, c) <= (rad**2)[:, None, None]
        blob = ink & (_dist2(xs, ys, c) <= 2.0)  # the ink at the centre ...
        for _ in range(int(h) + 1):  # ... grown through connected ink within the disc
            blob = _dilate(blob) & ink & disc
        grown = _dilate(blob)
        # beyond the disc only ink beyond doubt shows a merge (not noise at the blurred edge)
        runs_on = (grown & sure & ~disc).any(axis=(1, 2))
        for _ in range(GROW_PX - 1):
            grown = _dilate(grown)
        grown &= ~_dilate(ink & ~blob)  # other ink and its fringe
        w = wts * grown
        s = w.sum(axis=(1, 2))
        npx = np.where(white >= MIN_WHITE, blob.sum(axis=(1, 2)), 0)
        r = np.where(npx == 0, "lost", np.where(runs_on, "merged", ""))
        reason[sel] = r
        keep = r == ""
        safe = np.where(s > 0, s, 1.0)
        cen = np.c_[(w * xs).sum(axis=(1, 2)), (w * ys).sum(axis=(1, 2))] / safe[:, None]
        dx = np.where(grown, xs - cen[:, 0, None, None], 0.0)
        dy = np.where(grown, ys - cen[:, 1, None, None], 0.0)
        var_u = (noise**2 * (dx**2).sum(axis=(1, 2)) + s_white**2 * dx.sum(axis=(1, 2)) ** 2) / safe**2
        var_v = (noise**2 * (dy**2).sum(axis=(1, 2)) + s_white**2 * dy.sum(axis=(1, 2)) ** 2) / safe**2
        n_px = grown.sum(axis=(1, 2))
        wl = np.maximum(white, MIN_WHITE)
        m_norm = s / wl
        var_m = n_px * noise**2 / wl**2 + ((n_px - m_norm) / wl) ** 2 * s_white**2
        out[sel[keep]] = cen[keep] + np.c_[cu, cv][keep]
        area[sel] = npx
        mass[sel] = m_norm
        smass[sel] = np.sqrt(var_m)
        spx[sel] = np.where(keep, SIGMA_CALIBRATION * np.sqrt((var_u + var_v) / 2), np.nan)
        white_all[sel], noise_all[sel] = white, noise
    return WindowMeasure(out, area, mass, smass, spx, white_all, noise_all, reason)
