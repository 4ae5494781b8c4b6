"""Longitudinal stripes whose coded targets are out of the picture, named from what is seen.

At a close ring (300 mm at 1080p) the cell's CT bands leave the picture at its top and bottom
edges, and a longitudinal stripe's dots, found as a straight chain on a white band
(:func:`triaxtrack.identify.cell._straight_chains`), have no CT to name them. Two things the
picture holds name them instead:

* **Which stripe**: the membrane behind it. The labelled membrane columns give the camera's
  azimuth psi: a column at azimuth theta images across the axis at ``x0 + k sin(theta - psi)``
  (fitted by least squares). A line of sight through a stripe at azimuth phi meets the membrane
  further round, on the same side of psi (the membrane is nearer the axis: ``sin`` of the angle
  grows as the radius falls, and refraction into the water bends the ray towards the axis), so
  the stripe seen lies within ``MAX_VIEW_DEG`` of psi, on the side its image is on; the stripes
  are 120 degrees apart, and exactly one must fit.
* **Which dot**: the stripe's ends. Its white band ends ``band_margin`` beyond its end dots'
  edges (the printed label's edge; ``(band_margin + dot radius) / spacing`` steps past an end
  dot's centre). An end is *closed* where the band's white is gone, one spacing beyond its last
  dot, across the band's whole width (a missed dot there leaves the band white beside it), where
  the band is white beside the dot (an occluder hides it there too) and where, down the stripe's
  middle, the band ends where it is printed to end, within ``END_TOLERANCE`` steps (an
  occluder's edge is anywhere). Seen obliquely, the printed end is tilted in the image, so each
  line across the band finds it at its own distance; down the middle it is at the printed one.
  The gaps between the chain's dots are counted in the stripe's spacing (varying linearly along
  the chain, as perspective makes it), each a whole number of steps. The stripe is labelled from
  a closed end; when both are closed, or both cut by the frame's border with its band white
  beside the dot at each, only with the stripe's count of steps between them.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates
from scipy.spatial import cKDTree

from triaxtrack.identify.state import UNLABELLED, _assign, _Frame
from triaxtrack.kit_design import KitDesign

MAX_VIEW_DEG = 80.0  # a stripe seen (its dots found as a chain) faces the camera within this
MIN_SIDE_DEG = 25.0  # ... and, this far off the camera's azimuth or more, lies on its image's side
MIN_MEMBRANE_DOTS = 50  # labelled membrane dots to fit the camera's azimuth from
# a gap between a chain's dots is a whole number of steps within this (the spacing's linear model
# holds to about 0.02 steps; a CT's centre dot 13 mm beyond a stripe's end, in line with it, is 4.13
# steps off, its Eq. 1 dot 7 mm beyond 2.22)
STEP_TOLERANCE = 0.1
END_REACH = 1.15  # steps out from a stripe's end dot within which its band's end is seen
# steps: down its middle, a band's end is seen this close to where it is printed (a blur sigma is
# about 0.1 step at 720p: 1 px in 9; the white and dark levels the crossing is judged between
# are measured to a few grey levels)
END_TOLERANCE = 0.15
BORDER_PX = 2.0  # a next dot within this (plus its radius) of the frame's border is out of it
GATE = 0.3  # a dot grown onto a stripe lies within this fraction of a spacing of its prediction
MAX_WALK = 200  # steps walked beyond a chain's end, at most (a stripe has 60 dots)
MARGIN_BLURS = 2.5  # the band's margin beside a stripe's dots spans this many blur sigmas, at least
MIN_FILL = 0.9  # a stripe's dots found fill this share of the places between its ends, at least
QUALITY = 0.9  # the labels' quality (a stripe labelled from its CT: 1 at its anchors, 0.9 between)


def _camera_azimuth(f: _Frame, perp: np.ndarray, design: KitDesign) -> tuple[float, float, float] | None:
    """(psi, x0, k): the labelled membrane columns' image positions across the axis (``perp``,
    undistorted pixels) fitted as ``x0 + k sin(theta - psi)``, psi the azimuth (rad) the camera
    sees face on (the labelled dots face it: the mean of their ``cos(theta - psi)`` is positive);
    None with too few labelled membrane dots."""
    m = design.membrane
    k = f.ids - m.first_id
    on = (f.ids != UNLABELLED) & (k >= 0) & (k < m.rows * m.columns)
    if on.sum() < MIN_MEMBRANE_DOTS:
        return None
    theta = np.deg2rad(m.theta0) + 2 * np.pi * (k[on] % m.columns) / m.columns
    x = f.pos[on] @ perp
    a = np.c_[np.ones(len(x)), np.sin(theta), np.cos(theta)]
    (x0, s, c), *_ = np.linalg.lstsq(a, x, rcond=None)
    amp, psi = float(np.hypot(s, c)), float(np.arctan2(-c, s))  # s sin + c cos = amp sin(theta - psi)
    if np.mean(np.cos(theta - psi)) < 0:
        amp, psi = -amp, psi + np.pi
    return psi, float(x0), amp


def _which_stripe(x_chain: float, azimuth: tuple[float, float, float], design: KitDesign) -> int | None:
    """The index (into the design's longitudinal stripes) of the one stripe a chain at ``x_chain``
    across the axis can be, given the camera's ``azimuth`` (:func:`_camera_azimuth`); None if
    none or several."""
    psi, x0, amp = azimuth
    across = (x_chain - x0) / amp  # the sine of the membrane's angle behind it (a stripe's is nearer 0)
    side = np.sign(across) if abs(across) >= 0.5 * np.sin(np.deg2rad(MIN_SIDE_DEG)) else 0.0
    cell = design.cell_targets
    top = cell.ct_stripes[0]
    fits = []
    for j, ls in enumerate(cell.longitudinal_stripes):
        phi = np.deg2rad(cell.theta0) + 2 * np.pi * (ls.ct - top.first_id) / top.count
        off = np.rad2deg(np.angle(np.exp(1j * (phi - psi))))
        if abs(off) <= MAX_VIEW_DEG and (abs(off) < MIN_SIDE_DEG or np.sign(off) == side):
            fits.append(j)
    return fits[0] if len(fits) == 1 else None


def _steps(t: np.ndarray) -> tuple[int, int, np.ndarray] | None:
    """(first, last + 1) positions kept and the whole number of stripe spacings between
    consecutive positions ``t`` (increasing, pixels along a chain) kept, the spacing linear in
    ``t`` (fitted to the single steps). The dots beyond a gap at either end are left out: what
    lies in line with a stripe past its end (its CT's centre dot, its Eq. 1 dot) is not of it.
    None where a gap between those kept is not a whole number of steps within
    ``STEP_TOLERANCE``."""
    gaps = np.diff(t)
    mid = 0.5 * (t[1:] + t[:-1])
    unit = gaps <= 1.5 * np.median(gaps)
    if unit.sum() < 2:
        return None
    coef = np.polyfit(mid[unit], gaps[unit], 1 if unit.sum() >= 4 else 0)
    n = gaps / np.polyval(coef, mid)
    single = np.abs(n - 1) <= STEP_TOLERANCE
    if not single.any():
        return None
    lo, hi = int(np.argmax(single)), len(n) - int(np.argmax(single[::-1]))  # gaps lo..hi-1
    n = n[lo:hi]
    whole = np.round(n)
    if (whole < 1).any() or (np.abs(n - whole) > STEP_TOLERANCE).any():
        return None
    return lo, hi + 1, whole.astype(np.int64)


def _end_state(
    gray: np.ndarray, uv: np.ndarray, step: np.ndarray, beside: float, white: float, ink: float, end_at: float
) -> str:
    """'closed', 'cut' or 'open': the end of a stripe at its last dot ``uv`` (distorted pixels),
    ``step`` one spacing outwards (distorted pixels), its band ``white`` and its ink ``ink`` (grey
    levels), its band printed to end ``end_at`` steps past the dot's centre: 'cut' where the next
    dot would be outside the frame and the band is white beside this one (it is a stripe's dot,
    not one in line past its end); 'closed' where, on three lines outwards (through the dot and
    ``beside`` pixels either side of it, on the band beside the dot), the grey level falls below
    half-way from the band's white to the ink before the next dot's place is passed
    (``END_REACH`` steps out), the two beside the dot start on the band's white, and the middle
    one, white past the dot (half a step out), falls there within ``END_TOLERANCE`` steps of
    ``end_at``."""
    h, w = gray.shape
    nxt = uv + step
    reach = beside + BORDER_PX
    across = np.array([-step[1], step[0]]) / np.linalg.norm(step) * beside
    mid = 0.5 * (white + ink)
    if not (reach <= nxt[0] <= w - 1 - reach and reach <= nxt[1] <= h - 1 - reach):
        sides = np.array([uv - across, uv + across])
        on_band = map_coordinates(
            gray.astype(np.float32), [sides[:, 1], sides[:, 0]], order=1, mode="nearest"
        )
        return "cut" if (on_band > mid).all() else "open"
    s = np.arange(0.0, END_REACH + 1e-9, 0.05)
    pts = uv + s[None, :, None] * step + np.array([-1.0, 0.0, 1.0])[:, None, None] * across  # (line, s, 2)
    grey = map_coordinates(gray.astype(np.float32), [pts[..., 1].ravel(), pts[..., 0].ravel()], order=1,
                           mode="nearest").reshape(3, len(s))  # fmt: skip
    sides = grey[[0, 2]]
    if not ((sides[:, 0] > mid).all() and (sides < mid).any(axis=1).all()):
        return "open"
    past = grey[1, s >= 0.5 - 1e-9]  # down the middle, from half a step out (clear of the dot)
    s_past = s[s >= 0.5 - 1e-9]
    dark = np.nonzero(past < mid)[0]
    if past[0] <= mid or not len(dark):
        return "open"
    k = int(dark[0])  # the first sample below half-way: the crossing between it and the one before
    at = s_past[k - 1] + (s_past[k] - s_past[k - 1]) * (past[k - 1] - mid) / (past[k - 1] - past[k])
    return "closed" if abs(at - end_at) <= END_TOLERANCE else "open"


def _band_white(gray: np.ndarray, uv: np.ndarray) -> float:
    """The band's white level: the median grey level half-way between consecutive dots ``uv``
    (distorted pixels, in order along the stripe)."""
    half = 0.5 * (uv[1:] + uv[:-1])
    return float(np.median(map_coordinates(gray.astype(np.float32), [half[:, 1], half[:, 0]], order=1)))


def _walk(f: _Frame, core: np.ndarray, steps: np.ndarray, dots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(blobs, their steps from the first) of a stripe grown from its ``core`` (blob indices, top
    first, ``steps`` apart) dot by dot along it, each next dot predicted from the two before it
    (undistorted pixels), into its gaps and beyond its ends, where one of the ``dots`` (bool per
    blob), not labelled and of the stripe's size, lies within ``GATE`` of a step: a chain found on
    the white band in front of the membrane runs on in front of the pedestals and the background,
    where its band is not brighter than the dots around it."""
    at = dict(zip(np.r_[0, np.cumsum(steps)].tolist(), core.tolist(), strict=True))
    area = f.blobs.area_px.to_numpy()
    size = float(np.median(area[core]))
    dot = np.nonzero(dots)[0]
    tree = cKDTree(f.pos[dot])
    taken = set(at.values())

    def take(i: int, pred: np.ndarray, spacing: float) -> bool:
        near = dot[tree.query_ball_point(pred, GATE * spacing)]
        if (
            len(near) != 1
            or f.ids[near[0]] != UNLABELLED
            or near[0] in taken
            or not 0.5 <= area[near[0]] / size <= 2
        ):
            return False
        at[i] = int(near[0])
        taken.add(at[i])
        return True

    for i in range(min(at), max(at)):  # the gaps: between the dots either side
        if i not in at:
            lo, hi = max(j for j in at if j < i), min(j for j in at if j > i)
            a, b = f.pos[at[lo]], f.pos[at[hi]]
            take(i, a + (b - a) * (i - lo) / (hi - lo), float(np.linalg.norm(b - a)) / (hi - lo))
    for out in (-1, 1):  # beyond the ends, while there is a dot one step on
        for _ in range(MAX_WALK):
            ends = sorted(at)[::-out][:2]  # the end and the one before it
            step = (f.pos[at[ends[0]]] - f.pos[at[ends[1]]]) / abs(ends[0] - ends[1])  # outwards
            if not take(ends[0] + out, f.pos[at[ends[0]]] + step, float(np.linalg.norm(step))):
                break
    places = sorted(at)
    return np.array([at[j] for j in places]), np.array(places) - places[0]


def label_uncoded_stripes(
    f: _Frame,
    chains: list[np.ndarray],
    dots: np.ndarray,
    gray: np.ndarray | None,
    axis: np.ndarray,
    blur_px: float,
    design: KitDesign,
) -> None:
    """Label the longitudinal stripes found as straight ``chains`` of blobs (indices, undistorted
    pixels in ``f.pos``) whose CT is not seen, where the membrane behind names the stripe and a
    closed end names its dots (see the module docstring); grown along the stripe over the blobs
    ``dots`` (bool per blob) not labelled. ``axis``: the image direction down the specimen;
    ``gray``: the frame (without it, nothing is labelled); ``blur_px``: the frame's lens blur
    (sigma, pixels). A stripe is labelled only where its band's margin beside its dots spans
    ``MARGIN_BLURS`` blur sigmas (seen obliquely, soft, the band's end is not told from a dot's
    edge) and its dots fill ``MIN_FILL`` of the places between its ends."""
    if gray is None or not chains:
        return
    perp = np.array([-axis[1], axis[0]])
    azimuth = _camera_azimuth(f, perp, design)
    if azimuth is None:
        return
    uv_all = f.blobs[["u_px", "v_px"]].to_numpy(np.float64)
    width = f.blobs.minor_px.to_numpy()
    cell = design.cell_targets
    margin = (
        (cell.longitudinal_band_width - cell.longitudinal_dot_diameter) / 2 / cell.longitudinal_dot_diameter
    )
    contrast = f.blobs.contrast.to_numpy()
    stripes = design.cell_targets.longitudinal_stripes
    done = {
        j for j, ls in enumerate(stripes) if ((f.ids >= ls.first_id) & (f.ids < ls.first_id + ls.count)).any()
    }
    for core in chains:
        j = _which_stripe(float(np.median(f.pos[core] @ perp)), azimuth, design)
        if j is None or j in done or (f.ids[core] != UNLABELLED).any():  # labelled (from its CT, a chain)
            continue
        ls = stripes[j]
        # steps past an end dot's centre
        end_at = (cell.band_margin + cell.longitudinal_dot_diameter / 2) / cell.longitudinal_spacing(ls)
        core = core[np.argsort(f.pos[core] @ axis)]  # top first: the stripe's IDs increase downwards
        along = f.pos[core[-1]] - f.pos[core[0]]
        kept = _steps(f.pos[core] @ (along / np.linalg.norm(along)))
        if kept is None:
            continue
        lo, hi, steps = kept
        core = core[lo:hi]
        chain, at = _walk(f, core, steps, np.asarray(dots, bool))
        wd = float(np.median(width[chain]))  # pixels across a dot: the band's margin is margin x this
        if (
            at[-1] > ls.count - 1
            or len(chain) < MIN_FILL * (at[-1] + 1)
            or margin * wd < MARGIN_BLURS * blur_px
        ):
            continue
        uv = uv_all[chain]
        white = _band_white(gray, uv)
        ink = white - float(np.median(contrast[chain]))
        beside = (0.5 + margin / 2) * wd  # half-way across the band's margin beside a dot
        top = _end_state(gray, uv[0], (uv[0] - uv[1]) / (at[1] - at[0]), beside, white, ink, end_at)
        bottom = _end_state(gray, uv[-1], (uv[-1] - uv[-2]) / (at[-1] - at[-2]), beside, white, ink, end_at)
        whole = at[-1] == ls.count - 1  # as many places as the stripe has dots
        if top == "closed" and (bottom != "closed" or whole) or (top == bottom == "cut" and whole):
            index = at
        elif bottom == "closed" and top != "closed":
            index = ls.count - 1 - at[-1] + at
        else:
            continue
        for k, i in zip(chain, index, strict=True):
            _assign(f, int(k), ls.first_id + int(i), ls.name, QUALITY)
        done.add(j)
