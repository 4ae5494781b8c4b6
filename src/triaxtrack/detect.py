"""Detection in one grey frame: dark blobs (solid dots) and ring-coded targets (CTs).

The paper's section 2.3, first half: binarise, keep blobs by area and roundness, measure
sub-pixel centroids, decode the CTs. Pixel coordinates follow OpenCV: the centre of the
top-left pixel is (0, 0); ``u`` to the right, ``v`` down; distorted (as recorded) unless a column
says ``undist`` (ideal pinhole pixels of the same camera matrix, see :func:`undistort_px`).

* Binarisation is robust to uneven light: each pixel is compared with a local background (a
  morphological closing, which removes every dark feature smaller than ``background_px``), and
  a pixel is ink when it is darker than that background by ``ink_fraction`` of it.
* Centroids are contrast-weighted (``background - grey``) over the blob grown by one pixel, so
  partly covered edge pixels count. On soft footage, where the ink mask is thresholded smoothed,
  the dots' centroids are then measured on the raw pixels in each dot's own window, as the
  tracker measures them (:func:`detect_blobs`). A dot of a stripe that runs along a dark edge
  can be re-centred against the background measured in the stripe's gaps, which holds the
  edge's blurred fringe too (:func:`gap_background_centroids`).
* ``contrast`` is the blob's darkest depth below the background; ``background`` the local white
  level at its centre (the surface it is printed on: label, band, membrane).
* Shape from second moments: ``major_px``/``minor_px`` are the full axes of the ellipse with the
  blob's moments, ``roundness = minor / major`` (1 for a circle seen head-on; a dot seen at an
  angle ``a`` off its normal has ``cos a``), ``fill = area / (pi major minor / 4)`` (about 1 for a
  filled ellipse, lower for rings, arcs and merged blobs).
* Coded targets (CTs) are decoded around their centre dots by :mod:`triaxtrack.coded_targets`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
import pandas as pd

from triaxtrack.image_quality import blur_sigma, noise_sigma


@dataclass(frozen=True)
class DetectParams:
    """Thresholds of :func:`detect_blobs` and :func:`decode_coded_targets` (pixels unless stated).

    ``background_px`` 0 means ``image width / 80`` (16 px at 1280, 48 px at 3840): the local
    background is measured over this size, so it must exceed the largest dark feature (a CT's
    centre dot) but stay below the size of the white labels and bands.
    """

    background_px: int = 0
    ink_fraction: float = 0.35
    min_contrast: float = 25.0  # grey levels at a normal exposure: fainter blobs are noise (see
    # exposure_params: scaled with the frame's white level where that is below NORMAL_WHITE)
    min_area_px: int = 4
    max_area_px: int = 40000
    min_roundness: float = 0.2
    min_fill: float = 0.7
    max_fill: float = 1.3
    ct_min_area_px: int = 12
    # a ring read more than about 63 degrees off the CT's normal: on two tests at 10 % strain,
    # three pedestal CTs (centre roundness 0.35-0.42) were misread as valid codes 115-160 px away
    ct_min_roundness: float = 0.45
    ct_min_confidence: float = 0.3  # each sector at least 15 % of the contrast from the mid-level
    ct_min_white: float = 0.6  # normalised level the white gap and surround must reach
    ct_max_corrected: int = 0  # sectors a code may be corrected by (0: exact matches only)
    ct_outer_white_fraction: float = 0.7  # share of the surround that must be white


EDGE_RADIUS_PX = 3  # a dot with non-dot dark ink this close (L2, pixel centres) is beside an edge
BLOB_COLUMNS = [
    "u_px", "v_px", "area_px", "major_px", "minor_px", "angle_rad", "roundness", "fill",
    "contrast", "background", "cov_uu", "cov_uv", "cov_vv", "beside_edge", "at_border",
    "split", "blur",
]  # fmt: skip


# A frame's white level (the 99th percentile of its local background: the membrane, labels and
# bands) at a normal exposure or brighter. An under-exposed frame (a dim lab, a camera closed
# down) has every contrast scaled down with its white: the grey-level floors (min_contrast) are
# scaled with it, so that the same scene is detected the same at any exposure.
NORMAL_WHITE = 160.0


def exposure_params(gray: np.ndarray, params: DetectParams | None = None) -> DetectParams:
    """``params`` (default :class:`DetectParams`) for this frame's exposure: ``min_contrast`` times
    the frame's white level over :data:`NORMAL_WHITE` where that is below 1 (unchanged at a
    normal exposure)."""
    p = params or DetectParams()
    g = np.asarray(gray)
    step = max(1, g.shape[1] // 640)  # a sample is enough for a percentile
    white = float(np.percentile(background(g, background_size_px(g.shape[1], p))[::step, ::step], 99))
    scale = min(1.0, white / NORMAL_WHITE)
    return p if scale >= 1.0 else replace(p, min_contrast=p.min_contrast * scale)


def background_size_px(width: int, params: DetectParams | None = None) -> int:
    """The size over which :func:`background` measures the white level in a frame ``width``
    pixels wide (``DetectParams.background_px``, or its default ``width / 80``)."""
    return (params or DetectParams()).background_px or max(8, int(width) // 80)


def background(gray: np.ndarray, size_px: int) -> np.ndarray:
    """Local white level: the closing of ``gray`` by a disc of ``size_px`` (float32, same shape).

    Computed on a max-pooled copy (a closing is a dilation then an erosion, and max-pooling is a
    dilation), then interpolated back, so it costs little at 4K. Never darker than the pixel.
    """
    g = np.asarray(gray)
    h, w = g.shape
    f = max(1, int(size_px) // 6)
    hp, wp = -(-h // f) * f, -(-w // f) * f
    pad = np.pad(g, ((0, hp - h), (0, wp - w)), mode="edge")
    small = pad.reshape(hp // f, f, wp // f, f).max(axis=(1, 3))
    k = max(3, int(round(size_px / f)) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    small = cv2.erode(cv2.dilate(small, kernel), kernel)
    bg = cv2.resize(small.astype(np.float32), (wp, hp), interpolation=cv2.INTER_LINEAR)[:h, :w]
    # the pooled grid is offset by half a cell: shift back
    if f > 1:
        m = np.array([[1, 0, (f - 1) / 2], [0, 1, (f - 1) / 2]], np.float32)
        bg = cv2.warpAffine(bg, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return np.maximum(bg, g.astype(np.float32))


def _ink(contrast: np.ndarray, white, p: DetectParams) -> np.ndarray:
    """uint8 mask of the pixels darker than the white level ``white`` (a map or a number) by
    ``ink_fraction`` of it and by ``min_contrast`` (``contrast``: white level - grey)."""
    return (contrast > np.maximum(p.min_contrast, p.ink_fraction * white)).astype(np.uint8)


def _label_sums(labels: np.ndarray, n: int, weights: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per-label zeroth, first and second moments over the pixels of each label (label 0 skipped)."""
    ys, xs = np.nonzero(labels)
    lab = labels[ys, xs]
    w = np.ones(len(lab)) if weights is None else weights[ys, xs].astype(np.float64)
    xs = xs.astype(np.float64)
    ys = ys.astype(np.float64)

    def s(v):
        return np.bincount(lab, weights=v, minlength=n)

    return {
        "m0": s(w), "x": s(w * xs), "y": s(w * ys),
        "xx": s(w * xs * xs), "yy": s(w * ys * ys), "xy": s(w * xs * ys),
    }  # fmt: skip


# Real footage is soft (a fixed-focus lens, blur sigma 0.7-1.2 px) and noisy (3-5 grey levels,
# H.265 blocks): faint dots break into fragments and neighbours touch. From a lens blur of
# BLUR_SMOOTH_REL x the dots' median minor axis on (the gaps between dots are about a dot wide),
# the ink mask is thresholded on the contrast smoothed by SMOOTH_PER_BLUR x the blur (which adds a
# fifth to the blur: sqrt(1 + 0.7^2) = 1.22, and cuts white noise 2.5x at 1 px) and touching dots
# are cut apart. Sharp renders (measured blur 0-0.16 px) are detected as they are: there,
# smoothing and cutting lost 1-5 % of the labels at 10 % strain; so is a 1 px blur at 4K (dots
# 12 px across; threshold 1.8 px), where they lowered the worst camera's coverage 0.964 -> 0.928.
# At 720p (dots 4 px: 0.6 px) and 1080p (6 px: 0.9 px) a 1 px blur is soft.
BLUR_SMOOTH_REL = 0.15
SMOOTH_PER_BLUR = 0.7
# Two dots whose blurred images touch are one ink component with two maxima of the smoothed
# contrast. A maximum is a dot of its own when it rises above the saddle towards every higher
# one by this many standard deviations of the smoothed noise and by this fraction of its own
# contrast (h-maxima); the component is then cut along the valleys between them (watershed). On
# compressed footage the measured noise reads low (noise_sigma) and the fraction governs.
SPLIT_NOISE_K = 4.0
SPLIT_DIP_FRACTION = 0.1
# Which components are split: those up to this many times the median blob's area, and, however
# large, those no thicker than SPLIT_MAX_THICKNESS x the median blob's thickness (the largest
# distance from a pixel to the component's edge). Rows of dots whose blurred images touch stay one
# dot thick however long they grow (a membrane column compressed to a 5 px row pitch at 720p at 10 %
# strain is one component hundreds of dots long); edges, labels and bands are thicker.
SPLIT_MAX_AREA_FACTOR = 8.0
SPLIT_MAX_THICKNESS = 1.5
# The smoothed mask finds and cuts the dots; their centroids are then measured on the raw pixels,
# each in its own disc as the tracker measures it (the disc: the blob's semi-major axis plus this,
# the tracker's default disc_margin_px). The smoothed mask's pieces of touching dots put the
# valley between them by the smoothed contrast, and its wider blobs take in the neighbours'
# fringes: on the chunk starts of the eight realistic 720p and 1080p tests the labels came
# 0.048-0.103 px from their true images at the median and 0.101-0.220 px at the 90th percentile,
# measured again 0.044-0.097 and 0.087-0.210 (at 10 % strain 0.094 and 0.209 -> 0.079 and 0.158),
# and the tracker, which measures them so, left out 0.8-8.8 % of the labelled membrane dots at the
# first frame for disagreeing with them by more than first_agreement_px (0.0-6.1 % since)
WINDOW_MARGIN_PX = 1.0
# The windows are measured twice, the second time from the first's centroids (each dot's and its
# touching neighbours'), as the tracker measures a label, so that a dot divided from a touching
# one more often has the valley the tracker will find. Measured once (from the smoothed mask's
# centroids), the two valley lines differed by about 0.3 px for the divided dots at 10 % strain
# (720p), and the tracker left 1-2 % of a camera's membrane dots out at the chunk start
# (disagrees); measured twice, that test's last chunk start's share fell only from 2.8 to 2.65 %
WINDOW_PASSES = 2


def _split_touching(cs: np.ndarray, components: np.ndarray, area: np.ndarray, sigma: float,
                    smooth_px: float, p: DetectParams) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Cut ink components holding several significant maxima of the smoothed contrast ``cs``
    along the valleys between them. Returns (label image, per-label bool: a piece of a cut
    component). Labels of components left whole are unchanged; pieces get new labels after them."""
    from skimage.morphology import h_maxima
    from skimage.segmentation import watershed

    n = len(area)
    sized = area >= p.min_area_px
    sized[0] = False
    if not sized.any():
        return components, np.zeros(n, bool)
    small = sized & (area <= SPLIT_MAX_AREA_FACTOR * float(np.median(area[sized])))
    thick = _thickness(components, n)
    thin = thick <= SPLIT_MAX_THICKNESS * float(np.median(thick[small]))
    cand = (area >= 2 * p.min_area_px) & (small | thin)
    cand[0] = False
    if not cand.any():
        return components, np.zeros(n, bool)
    sel = cand[components]
    ys, xs = np.nonzero(sel)
    y0, y1, x0, x1 = ys.min(), ys.max() + 2, xs.min(), xs.max() + 2
    sub = np.where(sel[y0:y1, x0:x1], cs[y0:y1, x0:x1], 0).astype(np.float64)
    # a maximum must rise above its saddle by the noise and by a share of its own height
    peak = np.zeros(n)
    np.maximum.at(peak, components[sel], cs[sel])
    gain = 1.0 / (2.0 * np.sqrt(np.pi) * smooth_px)  # smoothed over raw white noise
    h = max(SPLIT_NOISE_K * sigma * gain, SPLIT_DIP_FRACTION * float(np.median(peak[cand])))
    maxima = h_maxima(sub, h) > 0
    comp_sub = np.where(sel[y0:y1, x0:x1], components[y0:y1, x0:x1], 0)
    nmax, marker_lab = cv2.connectedComponents(maxima.astype(np.uint8), connectivity=8)
    per_comp = np.zeros(n, np.int64)
    first = np.zeros(nmax, np.int64)
    np.maximum.at(first, marker_lab.ravel(), comp_sub.ravel())
    np.add.at(per_comp, first[1:], 1)
    multi = per_comp >= 2
    multi[0] = False
    if not multi.any():
        return components, np.zeros(n, bool)
    keep_marker = np.r_[False, multi[first[1:]]]
    markers = np.where(keep_marker[marker_lab], marker_lab, 0)
    mask = multi[comp_sub]
    pieces = watershed(-sub, markers, mask=mask)
    # new labels after the existing ones; a cut component's pixels no maximum reached keep its label
    relabel = np.zeros(nmax, np.int64)
    kept = np.nonzero(keep_marker)[0]
    relabel[kept] = n + np.arange(len(kept))
    out = components.copy()
    window = out[y0:y1, x0:x1]
    cut = mask & (pieces > 0)
    window[cut] = relabel[pieces[cut]]
    piece = np.r_[np.zeros(n, bool), np.ones(len(kept), bool)]
    return out, piece


def _thickness(components: np.ndarray, n: int) -> np.ndarray:
    """Per label of ``components`` (``n`` labels), its largest distance from a pixel to the label's
    edge (L2, pixels; 0 for label 0)."""
    from scipy import ndimage

    dist = cv2.distanceTransform((components > 0).astype(np.uint8), cv2.DIST_L2, 3)
    thick = np.asarray(ndimage.maximum(dist, components, np.arange(n)), np.float64)
    thick[0] = 0.0
    return thick


def detect_blobs(gray: np.ndarray, params: DetectParams | None = None) -> pd.DataFrame:
    """Every dark blob of a grey frame, with sub-pixel centroid and shape (columns BLOB_COLUMNS).

    Sharp footage is thresholded as it is. The frame's lens blur is then measured from its large
    dots (:func:`blur_sigma`, column ``blur``); on soft footage (blur at least ``BLUR_SMOOTH_REL``
    of the dots' median minor axis) the frame is detected again with the ink mask thresholded on the
    contrast smoothed by ``SMOOTH_PER_BLUR`` x the blur (noise-proof at little cost in
    resolution: the image is already that soft), and blobs holding several significant maxima
    (touching dots) cut apart at the valleys between them (``split`` True); each dot's centroid
    is then measured again on the raw pixels in its own window (:func:`_window_centroids`).
    Centroids and masses are always weighted by the raw contrast. No filtering by shape here
    beyond ``min_area_px``/``max_area_px``; see :func:`dot_mask`.
    """
    p = params or DetectParams()
    g = np.asarray(gray)
    if g.ndim != 2:
        raise ValueError(f"detect_blobs: expected a 2-D grey image, got shape {g.shape}")
    blobs = _detect(g, p, 0.0)
    blur = blur_sigma(g, blobs)
    dots = dot_mask(blobs, p)
    if dots.any() and blur >= BLUR_SMOOTH_REL * float(np.median(blobs.minor_px.to_numpy()[dots])):
        blobs = _detect(g, p, SMOOTH_PER_BLUR * blur, noise_sigma(g))
        blobs = _window_centroids(g, blobs, p)
    return blobs.assign(blur=blur)


def _window_centroids(g: np.ndarray, blobs: pd.DataFrame, p: DetectParams) -> pd.DataFrame:
    """Soft footage: the dots' centroids measured again on the raw pixels, each in its own window
    as the tracker measures it (:func:`triaxtrack.window.measure_windows`: the ink at the raw
    contrast threshold, in a disc of the blob's semi-major axis plus ``WINDOW_MARGIN_PX``
    re-centred on it, against the window's own white level; a dot touching another is measured on
    its side of the valley between them), where that finds the blob clear and within half its
    minor axis of where the smoothed mask put it; elsewhere (an edge, no valley) the smoothed
    mask's centroid stays. ``WINDOW_PASSES`` passes, each from the last one's centroids. Other
    columns unchanged."""
    from triaxtrack.window import disc_radius, measure_windows

    dots = np.nonzero(dot_mask(blobs, p))[0]
    if len(dots) == 0:
        return blobs
    mask_uv = blobs[["u_px", "v_px"]].to_numpy(np.float64)
    radius = disc_radius(blobs.area_px.to_numpy()[dots], blobs.roundness.to_numpy()[dots], WINDOW_MARGIN_PX)
    reach = 0.5 * blobs.minor_px.to_numpy()[dots]
    uv = mask_uv.copy()
    for _ in range(WINDOW_PASSES):
        m = measure_windows(g, uv[dots], radius, p.ink_fraction, WINDOW_MARGIN_PX)
        good = (m.code == 0) & (np.hypot(*(m.uv - mask_uv[dots]).T) <= reach)  # NaN: False
        uv = mask_uv.copy()
        uv[dots[good]] = m.uv[good]
    return blobs.assign(u_px=uv[:, 0], v_px=uv[:, 1])


def _detect(g: np.ndarray, p: DetectParams, smooth_px: float, sigma: float = 0.0) -> pd.DataFrame:
    """:func:`detect_blobs` at a given smoothing of the ink mask (0: none, no splitting), with
    the frame's pixel noise ``sigma`` (grey levels) for the splitting."""
    size = background_size_px(g.shape[1], p)
    gf = g.astype(np.float32)
    bg = background(cv2.GaussianBlur(gf, (0, 0), smooth_px) if smooth_px > 0 else g, size)
    contrast = bg - gf
    cs = cv2.GaussianBlur(contrast, (0, 0), smooth_px) if smooth_px > 0 else contrast
    ink = _ink(cs, bg, p)
    _, components, stats, _ = cv2.connectedComponentsWithStats(ink, connectivity=8)
    area0 = stats[:, cv2.CC_STAT_AREA].astype(np.float64)
    if smooth_px > 0:
        components, piece = _split_touching(cs, components, area0, sigma, smooth_px, p)
    else:
        piece = np.zeros(len(area0), bool)
    n = len(piece)
    area = np.bincount(components.ravel(), minlength=n).astype(np.float64)
    keep = (area >= p.min_area_px) & (area <= p.max_area_px)
    keep[0] = False
    lut = np.where(keep, np.arange(n), 0).astype(np.int32)
    labels = lut[components]
    geo = _label_sums(components, n)
    # contrast-weighted centroid over the blob grown by one pixel (edge pixels partly covered)
    grown = cv2.dilate(labels.astype(np.float32), np.ones((3, 3), np.uint8)).astype(np.int32)
    grown = np.where(labels > 0, labels, grown)
    # a blob whose grown pixels reach the image border is cut by it: its centroid is biased
    rim = np.concatenate([grown[0], grown[-1], grown[:, 0], grown[:, -1]])
    at_border = np.zeros(n, bool)
    at_border[rim] = True
    wts = np.clip(contrast, 0, None)
    cen = _label_sums(grown, n, wts)
    idx = np.nonzero(keep)[0]
    m0 = geo["m0"][idx]
    mx, my = geo["x"][idx] / m0, geo["y"][idx] / m0
    cuu, cuv, cvv, major, minor = _ellipse(geo, idx)
    w0 = cen["m0"][idx]
    peak = np.zeros(n)
    np.maximum.at(peak, labels[labels > 0], contrast[labels > 0])
    return pd.DataFrame({
        "u_px": cen["x"][idx] / w0,
        "v_px": cen["y"][idx] / w0,
        "area_px": area[idx],
        "major_px": major,
        "minor_px": minor,
        "angle_rad": 0.5 * np.arctan2(2 * cuv, cuu - cvv),
        "roundness": minor / major,
        "fill": area[idx] / (np.pi * major * minor / 4),
        "contrast": peak[idx],
        "background": bg[_pixel(my, g.shape[0]), _pixel(mx, g.shape[1])],
        "cov_uu": cuu,
        "cov_uv": cuv,
        "cov_vv": cvv,
        "beside_edge": _beside_edge(components, area, geo, p)[idx],
        "at_border": at_border[idx],
        "split": piece[idx],
    })  # fmt: skip


def _ellipse(sums: dict[str, np.ndarray], idx: np.ndarray) -> tuple[np.ndarray, ...]:
    """Second moments (cov_uu, cov_uv, cov_vv, px^2) and moment-ellipse axes (major, minor, px)
    of components ``idx`` from their :func:`_label_sums` (union of unit pixels: the point moments
    plus 1/12 per axis)."""
    m0 = np.maximum(sums["m0"][idx], 1e-12)
    mx, my = sums["x"][idx] / m0, sums["y"][idx] / m0
    cuu = sums["xx"][idx] / m0 - mx**2 + 1 / 12
    cvv = sums["yy"][idx] / m0 - my**2 + 1 / 12
    cuv = sums["xy"][idx] / m0 - mx * my
    tr, det = cuu + cvv, cuu * cvv - cuv**2
    disc = np.sqrt(np.maximum(tr**2 / 4 - det, 0))
    l1, l2 = tr / 2 + disc, np.maximum(tr / 2 - disc, 1e-12)
    return cuu, cuv, cvv, 4 * np.sqrt(l1), 4 * np.sqrt(l2)


def _beside_edge(components: np.ndarray, area: np.ndarray, sums: dict, p: DetectParams) -> np.ndarray:
    """Per ink component (``components``: the label image; ``area`` and ``sums``
    (:func:`_label_sums`) per label): whether dark ink that is not dot-like lies within
    ``EDGE_RADIUS_PX`` of it: a region too large, too thin or too ragged for a dot (the dark
    background beyond a silhouette, a pedestal edge). Such a dot has the edge's blurred fringe in
    its centroid window. Components smaller than ``min_area_px`` (noise) are never edges; an edge
    component is beside itself."""
    n = len(area)
    *_, major, minor = _ellipse(sums, np.arange(n))
    fill = area / (np.pi * major * minor / 4)
    not_round = (minor / major < p.min_roundness) | (fill < p.min_fill) | (fill > p.max_fill)
    edge = (area > p.max_area_px) | ((area >= p.min_area_px) & not_round)
    edge[0] = False
    if not edge.any():
        return np.zeros(n, bool)
    k = 2 * EDGE_RADIUS_PX + 1
    near = cv2.dilate(edge[components].astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    hit = components[(near > 0) & (components > 0)]
    return np.bincount(hit, minlength=n) > 0


def _pixel(x: np.ndarray, size: int) -> np.ndarray:
    """Nearest pixel index of sub-pixel coordinates, clipped to the image."""
    return np.clip(np.rint(x), 0, size - 1).astype(int)


GAP_ITERATIONS = 3  # re-centrings of the window in gap_background_centroids
GAP_BRIGHT = 0.6  # window pixels whose gap background is darker than this of the window's brightest
# are beyond the band's edge (the dark background): left out


def gap_background_centroids(
    gray: np.ndarray, uv: np.ndarray, prev_uv: np.ndarray, next_uv: np.ndarray, half_across: np.ndarray
) -> np.ndarray:
    """(N, 2) centroids of dots in a row of evenly spaced dots (a stripe), each weighted by its
    darkness below the background measured in the gaps beside it.

    A dot beside a dark edge that runs along its stripe (a longitudinal band seen edge-on, the
    dark beyond it) has the edge's blurred fringe in its window, and the contrast-weighted
    centroid of :func:`detect_blobs` leans towards the edge (0.1-0.3 px). Here the background of
    a window pixel is the mean grey at its place across the stripe in the two gaps, half-way to
    the neighbouring dots ``prev_uv``/``next_uv`` (distorted pixels): the edge's fringe is in it
    too and cancels. The window reaches half-way to the neighbours along the stripe and
    ``half_across`` pixels across it. NaN where the window leaves the image or holds no ink.
    """
    img = np.asarray(gray, np.float32)
    h, w = img.shape
    out = np.asarray(uv, np.float64).copy()

    def sample(xy: np.ndarray) -> np.ndarray:  # bilinear
        m = xy.astype(np.float32).reshape(-1, 1, 2)
        return cv2.remap(img, m[..., 0], m[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel()

    for k, (p, a, b, half) in enumerate(zip(out.copy(), prev_uv, next_uv, half_across, strict=True)):
        t = np.asarray(b, float) - np.asarray(a, float)
        s = np.linalg.norm(t) / 2
        if not np.isfinite(s) or s <= 0:
            out[k] = np.nan
            continue
        t /= 2 * s
        n = np.array([-t[1], t[0]])
        gaps = (0.5 * (p + a), 0.5 * (p + b))
        c = p.copy()
        r = int(np.ceil(max(s, half))) + 1
        for _ in range(GAP_ITERATIONS):
            u0, v0 = int(round(c[0])), int(round(c[1]))
            if not (r <= u0 < w - r and r <= v0 < h - r):
                out[k] = np.nan
                break
            vv, uu = np.mgrid[v0 - r : v0 + r + 1, u0 - r : u0 + r + 1]
            x = np.c_[uu.ravel(), vv.ravel()].astype(np.float64)
            win = (np.abs((x - c) @ t) <= 0.5 * s) & (np.abs((x - c) @ n) <= half)
            x = x[win]
            # each pixel's background: the grey at its own place across, in either gap
            bg = np.mean([sample(x + ((g - x) @ t)[:, None] * t) for g in gaps], axis=0)
            wt = np.clip(bg - img[x[:, 1].astype(int), x[:, 0].astype(int)], 0, None)
            wt *= bg > GAP_BRIGHT * bg.max()
            if wt.sum() <= 0:
                out[k] = np.nan
                break
            c = (wt[:, None] * x).sum(axis=0) / wt.sum()
        else:
            out[k] = c
    return out


PAIR_PAD_PX = 3  # the window of merged_pair_centroids reaches this far beyond the two dots


def merged_pair_centroids(
    gray: np.ndarray,
    a_uv: np.ndarray,
    b_uv: np.ndarray,
    white: float,
    fixed_uv: np.ndarray,
    params: DetectParams | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Centroids of two dots whose images merged into one blob, by a fit of two Gaussians.

    ``a_uv``/``b_uv``: where the two dots are expected (distorted pixels); ``white``: the local
    white level (the blob's ``background``); ``fixed_uv``: (K, 2) neighbouring dots whose blurred
    tails reach the blob, fitted at their own centroids. The blob is the ink (the rule of
    :func:`detect_blobs`) at the midpoint; it must hold the pixels of both expected places and
    stay within the window (not a dark edge). Its pixels, grown by one, are fitted with one
    Gaussian per dot (free centre and height, one shared covariance) plus one per fixed neighbour
    (free height): the dots are alike, and where they merge each is seen only in part.

    Returns ((2, 2) centroids of the two dots, (4,) [height a, height b, residual RMS over the
    largest contrast, roundness of the fitted Gaussian]); NaN where there is no such blob.
    """
    from scipy.optimize import least_squares

    p = params or DetectParams()
    nan = (np.full((2, 2), np.nan), np.full(4, np.nan))
    g = np.asarray(gray)
    a, b = np.asarray(a_uv, np.float64), np.asarray(b_uv, np.float64)
    mid = 0.5 * (a + b)
    r = int(np.ceil(np.linalg.norm(b - a))) + PAIR_PAD_PX
    u0, v0 = int(round(mid[0])) - r, int(round(mid[1])) - r
    if not np.isfinite(mid).all() or u0 < 0 or v0 < 0 or u0 + 2 * r >= g.shape[1] or v0 + 2 * r >= g.shape[0]:
        return nan
    contrast = np.float32(white) - g[v0 : v0 + 2 * r + 1, u0 : u0 + 2 * r + 1].astype(np.float32)
    ink = _ink(contrast, white, p)
    _, comp = cv2.connectedComponents(ink, connectivity=8)
    at = [comp[int(round(q[1])) - v0, int(round(q[0])) - u0] for q in (a, mid, b)]
    if at[0] == 0 or len(set(at)) != 1:
        return nan
    blob = (comp == at[0]).astype(np.uint8)
    if blob[0].any() or blob[-1].any() or blob[:, 0].any() or blob[:, -1].any():
        return nan
    ys, xs = np.nonzero(cv2.dilate(blob, np.ones((3, 3), np.uint8)))
    x = np.c_[xs + u0, ys + v0].astype(np.float64)
    y = np.clip(contrast[ys, xs], 0, None).astype(np.float64)
    fixed = np.asarray(fixed_uv, np.float64).reshape(-1, 2)
    k = len(fixed)

    def gauss(c, inv):
        d = x[:, None, :] - c[None, :, :]
        return np.exp(-0.5 * np.einsum("nki,ij,nkj->nk", d, inv, d))

    def covariance(q):  # shared by the Gaussians, from its Cholesky factor (log diagonal)
        chol = np.array([[np.exp(q[4]), 0.0], [q[5], np.exp(q[6])]])
        return chol @ chol.T

    def model(q):
        centres = np.r_[q[:4].reshape(2, 2), fixed]
        return gauss(centres, np.linalg.inv(covariance(q))) @ q[7:]

    sigma = 0.5 * np.sqrt(blob.sum() / (2 * np.pi)) + 0.5
    q0 = np.r_[a, b, np.log(sigma), 0.0, np.log(sigma), np.full(2 + k, y.max())]
    if len(y) <= len(q0):
        return nan
    fit = least_squares(lambda q: model(q) - y, q0)
    q = fit.x
    ev = np.linalg.eigvalsh(covariance(q))
    rms = np.sqrt(np.mean(fit.fun**2)) / y.max()
    return q[:4].reshape(2, 2), np.array([q[7], q[8], rms, np.sqrt(ev[0] / ev[1])])


def dot_mask(blobs: pd.DataFrame, params: DetectParams | None = None) -> np.ndarray:
    """Which blobs pass the paper's area and roundness criteria for solid dots."""
    p = params or DetectParams()
    return (
        (blobs.area_px >= p.min_area_px)
        & (blobs.roundness >= p.min_roundness)
        & (blobs.fill >= p.min_fill)
        & (blobs.fill <= p.max_fill)
    ).to_numpy()


def ellipse_maps(blobs: pd.DataFrame) -> np.ndarray:
    """(N, 2, 2) symmetric maps taking the unit circle to each blob's moment ellipse (pixels)."""
    cov = np.stack(
        [blobs.cov_uu.to_numpy(), blobs.cov_uv.to_numpy(), blobs.cov_uv.to_numpy(), blobs.cov_vv.to_numpy()],
        axis=1,
    ).reshape(-1, 2, 2)
    vals, vecs = np.linalg.eigh(cov)
    root = 2 * np.sqrt(np.maximum(vals, 1e-12))
    return np.einsum("nij,nj,nkj->nik", vecs, root, vecs)
