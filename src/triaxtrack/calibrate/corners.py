"""Corner refinement: the point-symmetry fit of checkerboard corners (:func:`refine_corners`,
:func:`refine_view`) on a smoothed image, and the corners' grid indices and spacing."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from triaxtrack.optics import UNDISTORT_CRITERIA

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
    padded = np.zeros((rows * 1024, 2), np.float32)
    padded[:n] = flat
    maps = padded.reshape(rows, 1024, 2)
    out = []
    for grad in (image.grad_u, image.grad_v):
        at = cv2.remap(grad, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out.append(at.ravel()[:n])
    return np.stack(out, axis=-1).astype(np.float64).reshape(uv.shape)


@dataclass(frozen=True)
class _Windows:
    """The symmetry fit's windows in an image of ``shape`` (h, w): the stencil ``offsets``
    (M, 2) and ``weights`` (M,) of :func:`_symmetry_stencil`, drawn in pixels, or, with ``K``
    and ``dist``, as squares in undistorted coordinates mapped into the image through the lens."""

    offsets: np.ndarray
    weights: np.ndarray
    shape: tuple[int, int]
    K: np.ndarray | None = None
    dist: np.ndarray | None = None

    def at(self, c: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image positions (n, M, 2) of c + d and c - d."""
        d = self.offsets[None] * r[:, None, None]
        if self.K is None:
            return c[:, None] + d, c[:, None] - d
        K, dist = self.K, self.dist
        focal = np.array([K[0, 0], K[1, 1]])
        x0 = cv2.undistortPoints(c.reshape(-1, 1, 2), K, dist, None, None, None, UNDISTORT_CRITERIA)
        x0 = x0.reshape(-1, 1, 2)
        pts = np.concatenate([x0 + d / focal, x0 - d / focal], axis=1)
        pts3 = np.concatenate([pts, np.ones(pts.shape[:-1] + (1,))], axis=-1).reshape(-1, 1, 3)
        uv, _ = cv2.projectPoints(pts3, np.zeros(3), np.zeros(3), K, dist)
        uv = uv.reshape(pts.shape)
        return uv[:, : len(self.offsets)], uv[:, len(self.offsets) :]

    def inside(self, plus: np.ndarray, minus: np.ndarray) -> np.ndarray:
        """(n,) bool: both halves of each window keep ``REFINE_EDGE_PX`` inside the image."""
        h, w = self.shape
        lo = np.minimum(plus.min(axis=1), minus.min(axis=1))
        hi = np.maximum(plus.max(axis=1), minus.max(axis=1))
        return (
            (lo >= REFINE_EDGE_PX).all(axis=1)
            & (hi[:, 0] <= w - 1 - REFINE_EDGE_PX)
            & (hi[:, 1] <= h - 1 - REFINE_EDGE_PX)
        )


def _symmetry_steps(
    image: SmoothedImage,
    win: _Windows,
    start: np.ndarray,
    r: np.ndarray,
    active: np.ndarray,
    tol_px: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton iterations of the point-symmetry fit from corners ``start`` (n, 2), window
    half-widths ``r`` (n,), moving the ``active`` ones: each stops when its step is below
    ``tol_px``, it is more than 2 ``r`` from its start or its normal equations are singular
    (``REFINE_MAX_ITER`` iterations at most). Returns ``(corners (n, 2), solvable (n,))``,
    solvable false where the last step taken could not be solved."""
    c = start.copy()
    good = np.ones(len(c), bool)
    active = active.copy()
    for _ in range(REFINE_MAX_ITER):
        if not active.any():
            break
        a = np.flatnonzero(active)
        plus, minus = win.at(c[a], r[a])
        res = _interpolate(image, plus) - _interpolate(image, minus)
        jac = _gradient(image, plus) - _gradient(image, minus)
        A = np.einsum("m,nmi,nmj->nij", win.weights, jac, jac)
        b = np.einsum("m,nmi,nm->ni", win.weights, jac, res)
        det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
        solvable = det > 1e-12 * np.maximum(A[:, 0, 0] * A[:, 1, 1], 1e-300)
        step = np.zeros((len(a), 2))
        step[solvable] = -np.linalg.solve(A[solvable], b[solvable][..., None])[..., 0]
        step = np.clip(step, -1.0, 1.0)
        c[a] += step
        good[a] = solvable
        moved = np.abs(step).max(axis=1) >= tol_px
        active[a] = solvable & moved & (np.linalg.norm(c[a] - start[a], axis=1) <= 2 * r[a])
    return c, good


def _looks_like_corner(
    image: SmoothedImage, win: _Windows, c: np.ndarray, r: np.ndarray, start: np.ndarray
) -> np.ndarray:
    """(n,) bool: the fitted corners ``c`` whose windows (half-widths ``r``) lie inside the image,
    that moved at most ``REFINE_MAX_SHIFT`` times ``r`` from ``start``, and whose windows look
    like a checkerboard corner (contrast at least ``REFINE_MIN_CONTRAST``, mismatch with the
    half-turned copy at most ``REFINE_MAX_ASYMMETRY`` of it)."""
    plus, minus = win.at(c, r)
    vp, vm = _interpolate(image, plus), _interpolate(image, minus)
    both = np.concatenate([vp, vm], axis=1)
    contrast = np.percentile(both, 95, axis=1) - np.percentile(both, 5, axis=1)
    mismatch = np.sqrt((win.weights * (vp - vm) ** 2).sum(axis=1) / win.weights.sum())
    return (
        win.inside(plus, minus)
        & (np.linalg.norm(c - start, axis=1) <= REFINE_MAX_SHIFT * r)
        & (contrast >= REFINE_MIN_CONTRAST)
        & (mismatch <= REFINE_MAX_ASYMMETRY * contrast)
    )


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
    offsets, weights = _symmetry_stencil()
    if K is not None:
        K = np.asarray(K, np.float64)
        dist = np.zeros(5) if dist is None else np.asarray(dist, np.float64)
    win = _Windows(offsets, weights, image.shape, K, dist)
    idx = np.flatnonzero(ok)
    c, r = start[idx].copy(), radius[idx]
    fits = win.inside(*win.at(c, r))
    for _ in range(3):  # shrink windows that leave the image, by up to half
        if fits.all():
            break
        r = np.where(fits, r, r * 0.8)
        fits = win.inside(*win.at(c, r))
    c, good = _symmetry_steps(image, win, c, r, fits, tol_px)
    keep = fits & good & _looks_like_corner(image, win, c, r, start[idx])
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
