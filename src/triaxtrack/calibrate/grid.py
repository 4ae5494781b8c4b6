"""A partial board's corner grid: 3 x 3 seeds among the image's saddle points, grown corner by
corner (:func:`grow_grid`), checked for a checkerboard's squares and against its neighbours."""

from __future__ import annotations

import cv2
import numpy as np

from triaxtrack.calibrate.corners import (
    REFINE_MIN_CONTRAST,
    REFINE_RADIUS_FRACTION,
    REFINE_RADIUS_PX,
    SmoothedImage,
    _interpolate,
    refine_corners,
)

# ... its seeds: saddle points of the blurred image (Hessian determinant below -SADDLE_MIN,
# grey levels^2 / px^4; a corner of contrast C gives about -(0.14 C)^2), local extremes within
# SADDLE_NMS_PX, the SEED_MAX_POINTS strongest, refined with windows up to SEED_RADIUS_PX;
# grids are grown from up to SEED_TRIES of them, and kept if CHECKER_AGREEMENT of their squares
# alternate dark and bright
SADDLE_MIN = 4.0
SADDLE_NMS_PX = 2
SEED_MAX_POINTS = 400
SEED_RADIUS_PX = 5.0
SEED_TRIES = 3
SEED_NEIGHBOURS = 8  # nearest saddle points searched for a seed's two grid directions
CHECKER_AGREEMENT = 0.95
# a partial board's grid: a corner farther than GRID_TOLERANCE times the local spacing from
# where its neighbours put it is dropped; corners are refined to GRID_REFINE_TOL_PX while the
# grid is built (all are refined to REFINE_TOL_PX after)
GRID_TOLERANCE = 0.25
GRID_REFINE_TOL_PX = 0.01


def _grid_predictions(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each cell of a (rows, cols, 2) corner grid (NaN: empty) should lie, seen from its
    neighbours: (rows, cols, P, 2) predictions, NaN where a neighbour is missing, and the
    (rows, cols, P) corner spacing each is based on, pixels. Along each of the grid's four
    directions the next corner lies at ``3 a - 3 b + c`` (a, b, c the next three in that
    direction: quadratic extrapolation, exact for smoothly varying spacing) or ``2 a - b``;
    between its two neighbours in a row or column at their mean; and, from each diagonal
    neighbour d and the two corners a, b beside both, at ``a + b - d``."""
    rows, cols = grid.shape[:2]
    pad = np.full((rows + 6, cols + 6, 2), np.nan)
    pad[3:-3, 3:-3] = grid

    def at(dr: int, dc: int) -> np.ndarray:
        return pad[3 + dr : 3 + dr + rows, 3 + dc : 3 + dc + cols]

    preds, scales = [], []
    for dr, dc in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        a, b, c = at(dr, dc), at(2 * dr, 2 * dc), at(3 * dr, 3 * dc)
        quad = 3 * a - 3 * b + c
        preds.append(np.where(np.isfinite(quad), quad, 2 * a - b))
        scales.append(np.linalg.norm(a - b, axis=2))
    for dr, dc in ((0, 1), (1, 0)):
        a, b = at(dr, dc), at(-dr, -dc)
        preds.append((a + b) / 2)
        scales.append(np.linalg.norm(a - b, axis=2) / 2)
    for dr, dc in ((1, 1), (1, -1), (-1, 1), (-1, -1)):  # parallelograms: a + b - d
        a, b, d = at(dr, 0), at(0, dc), at(dr, dc)
        preds.append(a + b - d)
        scales.append(np.minimum(np.linalg.norm(a - d, axis=2), np.linalg.norm(b - d, axis=2)))
    return np.stack(preds, axis=2), np.stack(scales, axis=2)


def consistent_corners(grid_px: np.ndarray, tolerance: float = GRID_TOLERANCE) -> np.ndarray:
    """(rows, cols) bool: the corners of a (rows, cols, 2) grid (NaN: empty) that lie within
    ``tolerance`` times the local spacing of where at least one of their neighbour predictions
    (:func:`_grid_predictions`) puts them. A corner given the wrong grid index is a whole
    spacing off every prediction; its neighbours still agree with other ones."""
    preds, scales = _grid_predictions(grid_px)
    with np.errstate(invalid="ignore", divide="ignore"):
        miss = np.linalg.norm(preds - grid_px[:, :, None], axis=3) / scales
    return np.isfinite(grid_px[..., 0]) & (np.nan_to_num(miss, nan=np.inf) <= tolerance).any(axis=2)


def _crop(grid: np.ndarray) -> tuple[np.ndarray, tuple[int, int]]:
    """The grid without its empty outer rows and columns (at least one cell must be filled),
    and the (row, column) of the input where it starts."""
    filled = np.isfinite(grid[..., 0])
    rows, cols = np.flatnonzero(filled.any(axis=1)), np.flatnonzero(filled.any(axis=0))
    return grid[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1].copy(), (int(rows[0]), int(cols[0]))


def grow_grid(image: SmoothedImage, grid_px: np.ndarray, max_cells: int) -> np.ndarray:
    """The corner grid (rows, cols, 2; NaN: empty) grown to every corner of the board it can
    reach: each empty cell next to the grid is predicted from its neighbours
    (:func:`_grid_predictions`, averaged), refined (:func:`refine_corners`, window half-width
    ``REFINE_RADIUS_FRACTION`` of the local spacing, to ``GRID_REFINE_TOL_PX``) and kept if the
    fit accepts it within ``GRID_TOLERANCE`` of the spacing from the prediction and away from
    every corner already there; until nothing is added (a cell that failed is tried again only
    when more neighbours predict it). The grid never exceeds ``max_cells`` rows or columns.
    Growth stops by itself at the board's edge (the white margin holds no corner) and at the
    image's (the window must fit inside). A new grid is returned."""
    grid, _ = _crop(np.asarray(grid_px, np.float64))
    origin = np.zeros(2, np.int64)  # index of grid[0, 0] in the seed's frame
    failed: dict[tuple[int, int], int] = {}  # cell -> number of predictions when it failed
    for _ in range(4 * max_cells):
        grid = np.pad(grid, ((1, 1), (1, 1), (0, 0)), constant_values=np.nan)
        origin -= 1
        preds, scales = _grid_predictions(grid)
        have = np.isfinite(preds).all(axis=3)
        n = have.sum(axis=2)
        with np.errstate(invalid="ignore", divide="ignore"):
            guess = np.where(have[..., None], preds, 0.0).sum(axis=2) / n[..., None]
            scale = np.where(have, scales, 0.0).sum(axis=2) / n
        cand = ~np.isfinite(grid[..., 0]) & (n > 0)
        if grid.shape[0] - 2 >= max_cells:  # no room for another row
            cand[[0, -1]] = False
        if grid.shape[1] - 2 >= max_cells:
            cand[:, [0, -1]] = False
        for (fr, fc), fn in failed.items():
            r_, c_ = fr - origin[0], fc - origin[1]
            if 0 <= r_ < grid.shape[0] and 0 <= c_ < grid.shape[1] and n[r_, c_] <= fn:
                cand[r_, c_] = False
        if not cand.any():
            break
        r, c = np.nonzero(cand)
        start, spacing = guess[r, c], scale[r, c]
        radius = np.clip(REFINE_RADIUS_FRACTION * spacing, *REFINE_RADIUS_PX)
        refined, ok = refine_corners(image, start, radius, tol_px=GRID_REFINE_TOL_PX)
        ok &= np.linalg.norm(refined - start, axis=1) <= GRID_TOLERANCE * spacing
        existing = grid[np.isfinite(grid[..., 0])]
        for k in np.flatnonzero(ok):
            crowded = np.linalg.norm(existing - refined[k], axis=1).min() < 0.5 * spacing[k]
            crowded |= (np.linalg.norm(refined[ok] - refined[k], axis=1) < 0.5 * spacing[k]).sum() > 1
            ok[k] = not crowded
        for k in np.flatnonzero(~ok):
            failed[(int(r[k] + origin[0]), int(c[k] + origin[1]))] = int(n[r[k], c[k]])
        grid[r[ok], c[ok]] = refined[ok]
        grid, (dr, dc) = _crop(grid)
        origin += (dr, dc)
    return grid


def saddle_points(image: SmoothedImage) -> tuple[np.ndarray, np.ndarray]:
    """Candidate checkerboard corners of a smoothed image: ``(uv_px (N, 2), strength (N,))``,
    strongest first. At a corner the blurred image is a saddle: its Hessian determinant is
    strongly negative (about -(0.14 contrast)^2 per px^4 at 1.5 px blur); the candidates are the
    local maxima (``SADDLE_NMS_PX``) of ``-det`` above ``SADDLE_MIN``, with pixel positions."""
    g_uu = np.gradient(image.grad_u, axis=1)
    g_uv = np.gradient(image.grad_u, axis=0)
    g_vv = np.gradient(image.grad_v, axis=0)
    saddle = g_uv**2 - g_uu * g_vv
    peak = cv2.dilate(saddle, np.ones((2 * SADDLE_NMS_PX + 1,) * 2, np.uint8))
    v, u = np.nonzero((saddle >= peak) & (saddle > SADDLE_MIN))
    strength = saddle[v, u].astype(np.float64)
    order = np.argsort(-strength, kind="stable")
    return np.c_[u, v][order].astype(np.float64), strength[order]


def _seed_grids(image: SmoothedImage) -> list[np.ndarray]:
    """3 x 3 corner grids (3, 3, 2) found around the strongest saddle points
    (:func:`saddle_points`, refined by :func:`refine_corners`): a point whose four nearest
    neighbours form two opposite pairs, with corners at the four diagonal predictions too, and
    the four squares between them alternately dark and bright. At most ``SEED_TRIES``, best
    first."""
    from scipy.spatial import cKDTree

    cand, _ = saddle_points(image)
    if len(cand) < 9:
        return []
    cand = cand[:SEED_MAX_POINTS]
    near = cKDTree(cand).query(cand, k=2)[0][:, 1]
    refined, ok = refine_corners(image, cand, np.clip(0.5 * near, 2.0, SEED_RADIUS_PX), tol_px=0.01)
    pts = refined[ok]
    if len(pts) < 9:
        return []
    tree = cKDTree(pts)
    seeds = []
    for p in pts:
        grid = _seed_around(image, tree, pts, p)
        if grid is not None:
            seeds.append(grid)
            if len(seeds) >= SEED_TRIES:
                break
    return seeds


def _seed_around(image: SmoothedImage, tree, pts: np.ndarray, p: np.ndarray) -> np.ndarray | None:
    """The 3 x 3 grid (3, 3, 2) of corners ``pts`` centred on corner ``p``, or None: two pairs
    of opposite neighbours among its ``SEED_NEIGHBOURS`` nearest (on a sheared grid a diagonal
    neighbour can be nearer than a side one, so every non-collinear choice is tried, shortest
    first) whose four diagonal predictions are corners too, with the four squares between them
    alternately dark and bright (which a basis along a diagonal fails)."""
    k = min(SEED_NEIGHBOURS + 1, len(pts))
    d, idx = tree.query(p, k=k)
    v = pts[idx[1:]] - p
    n = len(v)
    pairs = [(v[i] - v[j]) / 2 for i in range(n) for j in range(i + 1, n)
             if np.linalg.norm(v[i] + v[j]) < GRID_TOLERANCE * min(d[i + 1], d[j + 1])]  # fmt: skip
    bases = [
        (e1, e2)
        for i, e1 in enumerate(pairs)
        for e2 in pairs[i + 1 :]
        if abs(e1[0] * e2[1] - e1[1] * e2[0]) >= 0.3 * np.linalg.norm(e1) * np.linalg.norm(e2)
    ]
    bases.sort(key=lambda e: np.linalg.norm(e[0]) + np.linalg.norm(e[1]))
    for e1, e2 in bases:
        grid = p + np.arange(-1, 2)[:, None, None] * e2 + np.arange(-1, 2)[None, :, None] * e1
        dd, ii = tree.query(grid.reshape(-1, 2))
        if (dd > GRID_TOLERANCE * min(np.linalg.norm(e1), np.linalg.norm(e2))).any():
            continue
        grid = pts[ii].reshape(3, 3, 2)
        centres = (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:]) / 4
        grey = _interpolate(image, centres)
        dark_bright = grey[0, 0] + grey[1, 1] - grey[0, 1] - grey[1, 0]
        spread = max(abs(grey[0, 0] - grey[1, 1]), abs(grey[0, 1] - grey[1, 0]))
        if abs(dark_bright) / 2 >= REFINE_MIN_CONTRAST and spread <= 0.25 * abs(dark_bright):
            return grid
    return None


def checkered(image: SmoothedImage, grid_px: np.ndarray) -> bool:
    """True when the squares between the corners of a (rows, cols, 2) grid (NaN: empty) are
    alternately dark and bright, as on a checkerboard, for at least ``CHECKER_AGREEMENT`` of
    the squares with four corners (a grid that skips corners, or runs along diagonals, has grey
    corners at its squares' centres)."""
    centres = (grid_px[:-1, :-1] + grid_px[:-1, 1:] + grid_px[1:, :-1] + grid_px[1:, 1:]) / 4
    have = np.isfinite(centres[..., 0])
    if not have.any():
        return False
    grey = _interpolate(image, centres[have])
    r, c = np.nonzero(have)
    parity = (r + c) % 2 == 0
    if parity.all() or not parity.any():
        return False
    gap = grey[parity].mean() - grey[~parity].mean()
    if abs(gap) < REFINE_MIN_CONTRAST:
        return False
    mid = (grey[parity].mean() + grey[~parity].mean()) / 2
    right = np.where(parity, grey > mid, grey < mid) if gap > 0 else np.where(parity, grey < mid, grey > mid)
    return bool(right.mean() >= CHECKER_AGREEMENT)
