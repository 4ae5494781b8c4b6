"""Coded targets (CTs) read in one grey frame, around the centre dots :mod:`triaxtrack.detect`
found.

A CT is a round blob (its centre dot) around which the kit's design is read: a white gap, the
ring of ``sectors`` code sectors, a white surround. The centre dot's moment ellipse gives the
local affine map from the printed target to the image, so the ring is read where the design
puts it, at any roll and obliquity. Each sector's mean grey level must lie clearly on one side
of the mid-level (``ct_min_confidence``); the code must match a kit code exactly (by default;
``ct_max_corrected = 1`` also accepts a difference in the one sector read least confidently:
a target partly hidden by a longitudinal band can read as a neighbour of another code).
Anything else is rejected, never guessed.

Pixel coordinates follow OpenCV (the centre of the top-left pixel is (0, 0)).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd

from triaxtrack.codes import rotations
from triaxtrack.detect import DetectParams, ellipse_maps
from triaxtrack.kit_design import CodedTargetDesign

# sampling of a CT, in units of the printed design (mm), relative to its centre
CT_INNER_WHITE = 0.5  # fraction of the way from the centre dot's edge to the ring: the white gap
CT_RING_RADII = (0.35, 0.5, 0.65)  # fractions across the code ring where sectors are read
CT_OUTER_WHITE = 0.35  # fraction of the way from the ring's outer edge to the label edge
CT_SAMPLES_PER_SECTOR = 8
CT_CENTRE_FRACTION = 0.45  # centre-dot samples within this fraction of its radius
# A CT cut by the image border is read from the sectors inside the image: at least this share of
# them, matched exactly (no corrected sector), and CT_PARTIAL_MARGIN or more sectors from every
# other code there: as for a whole CT (the kit's codes differ in 3), two misread sectors never
# give another ID
CT_MIN_KNOWN_FRACTION = 0.6
CT_PARTIAL_MARGIN = 3


@dataclass(frozen=True)
class CodeBook:
    """All rotations of the kit's CT codes, for vectorised nearest-code search."""

    ids: np.ndarray  # (K,) CT id of each rotated word
    words: np.ndarray  # (K,) rotated code words
    sectors: int

    @staticmethod
    def from_codes(codes: dict[int, int], sectors: int) -> CodeBook:
        ids, words = [], []
        for tid, word in sorted(codes.items()):
            for r in rotations(word, sectors):
                ids.append(tid)
                words.append(r)
        return CodeBook(np.array(ids, np.int64), np.array(words, np.int64), sectors)

    def nearest(self, word: int, known: int | None = None) -> tuple[int, int, int, int]:
        """(id, distance, rotated word matched, distance to the nearest *other* id), counting
        only the sectors whose bit is set in ``known`` (all when None)."""
        x = np.bitwise_xor(self.words, np.int64(word))
        if known is not None:
            x = np.bitwise_and(x, np.int64(known))
        d = np.bitwise_count(x)
        i = int(np.argmin(d))
        best_id = int(self.ids[i])
        other = d[self.ids != best_id]
        return best_id, int(d[i]), int(self.words[i]), int(other.min()) if len(other) else 99


@dataclass(frozen=True)
class _CtGeometry:
    """Sampling radii of a CT in units of its centre-dot radius: in the white gap (``inner``),
    across the code ring (``ring``), in the white surround (``outer``); ``extent``: the label's."""

    inner: float
    ring: tuple[float, ...]
    outer: float
    extent: float


def _ct_geometry(ct: CodedTargetDesign) -> _CtGeometry:
    """Sampling radii of a CT in units of its centre-dot radius."""
    rc, r0, r1 = ct.centre_radius, ct.ring_inner_radius, ct.ring_outer_radius
    label = ct.label_radius
    return _CtGeometry(
        inner=(rc + CT_INNER_WHITE * (r0 - rc)) / rc,
        ring=tuple((r0 + f * (r1 - r0)) / rc for f in CT_RING_RADII),
        outer=(r1 + CT_OUTER_WHITE * (label - r1)) / rc,
        extent=label / rc,
    )


def _ct_radii(geo: _CtGeometry) -> list[float]:
    """The radii a CT is sampled on, in units of its centre-dot radius (``geo``:
    :func:`_ct_geometry`), in this order: three in the centre dot (0..2), the white gap (3), the
    code ring's (4 .. -2), the white surround (-1)."""
    return [0.0, CT_CENTRE_FRACTION * 0.5, CT_CENTRE_FRACTION, geo.inner, *geo.ring, geo.outer]


def _ct_candidates(blobs: pd.DataFrame, p: DetectParams) -> np.ndarray:
    """Row positions (int) in ``blobs`` of the blobs that may be a CT's centre dot: large, round
    and filled enough (``ct_min_area_px``, ``ct_min_roundness``, ``min_fill`` .. ``max_fill``)."""
    return np.nonzero(
        (blobs.area_px.to_numpy() >= p.ct_min_area_px)
        & (blobs.roundness.to_numpy() >= p.ct_min_roundness)
        & (blobs.fill.to_numpy() >= p.min_fill)
        & (blobs.fill.to_numpy() <= p.max_fill)
    )[0]


def _sample_ct(
    gray: np.ndarray, centre: np.ndarray, maps: np.ndarray, radii: list[float], ns: int
) -> tuple[np.ndarray, np.ndarray]:
    """Grey levels around N candidate centre dots (``centre`` (N, 2) pixels, ``maps`` (N, 2, 2)
    unit circle -> centre-dot ellipse) on circles of the printed design of ``radii`` (centre-dot
    radii), ``ns`` samples each, counter-clockwise. Returns the levels (N, len(radii), ns) float32,
    bilinear, -1 outside the image, and whether each sample lies inside the image (same shape)."""
    phi = 2 * np.pi * (np.arange(ns) + 0.5) / ns
    # counter-clockwise as seen from outside the surface = counter-clockwise on screen (v down)
    circle = np.stack([np.cos(phi), -np.sin(phi)], axis=1)
    pts = centre[:, None, None, :] + np.einsum(
        "nij,rsj->nrsi", maps, np.asarray(radii)[:, None, None] * circle[None, :, :]
    )
    g = np.asarray(gray, np.float32)
    mx = pts[..., 0].reshape(len(centre), -1).astype(np.float32)
    my = pts[..., 1].reshape(len(centre), -1).astype(np.float32)
    vals = cv2.remap(g, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
    vals = vals.reshape(len(centre), len(radii), ns)
    h, w = g.shape
    inside = ((mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)).reshape(vals.shape)
    return vals, inside


def _normalise(
    vals: np.ndarray, inside: np.ndarray, p: DetectParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The samples of :func:`_sample_ct` (radii as :func:`_ct_radii`) scaled from each candidate's
    ``black`` (median of its centre dot) to its ``white`` (median of its gap): 0 black, 1 white, NaN
    outside the image. Returns them, ``black``, ``white`` (grey levels, (N,)) and ``ok`` (N,): the
    centre dot and the gap inside the image with ``min_contrast``, the gap white
    (``ct_min_white``), and ``ct_outer_white_fraction`` of the surround inside the image white."""
    black = np.median(vals[:, :3].reshape(len(vals), -1), axis=1)
    white = np.median(vals[:, 3], axis=1)
    span = np.maximum(white - black, 1e-6)
    norm = np.where(inside, (vals - black[:, None, None]) / span[:, None, None], np.nan)
    ok = inside[:, :4].all(axis=(1, 2)) & (white - black >= p.min_contrast)  # centre dot and gap
    ok &= norm[:, 3].min(axis=1) >= p.ct_min_white
    surround = inside[:, -1].sum(axis=1)
    ok &= (norm[:, -1] >= p.ct_min_white).sum(axis=1) >= p.ct_outer_white_fraction * np.maximum(surround, 1)
    return norm, black, white, ok


def _read_sectors(rings: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The ``n`` code sectors of N rings (``rings`` (N, radii, n * CT_SAMPLES_PER_SECTOR), scaled
    0 black .. 1 white, NaN outside the image), read at the sub-sector phase that reads most
    confidently: per sector the mean over the central half of it, at every radius.

    Returns ``confidence`` (N,): the weakest sector's distance from the mid-level (0-1, relative
    to half the contrast), -1 when no phase reads a ring dark or light across its whole width in
    every sector, or reads fewer than ``CT_MIN_KNOWN_FRACTION`` of them; ``bits`` (N, n) uint8 (1:
    dark); ``known`` (N, n) bool (the sector lies inside the image); and each sector's confidence
    (N, n; inf where not known)."""
    k = CT_SAMPLES_PER_SECTOR
    nr = rings.shape[1]
    best_conf = np.full(len(rings), -1.0)
    best_bits = np.zeros((len(rings), n), np.uint8)
    best_known = np.zeros((len(rings), n), bool)
    sector_conf = np.zeros((len(rings), n))
    for s in range(k):
        rolled = np.roll(rings, -s, axis=2).reshape(len(rings), nr, n, k)
        per_radius = rolled[..., k // 4 : k - k // 4].mean(axis=3)  # (N, radii, n), NaN: not all inside
        known = np.isfinite(per_radius).all(axis=1)  # (N, n)
        means = np.where(known, per_radius.mean(axis=1), 0.5)
        bits = known & (means < 0.5)
        # a printed sector is dark or light across the whole ring width
        consistent = (((per_radius < 0.5) == bits[:, None, :]) | ~known[:, None, :]).all(axis=(1, 2))
        enough = known.sum(axis=1) >= CT_MIN_KNOWN_FRACTION * n
        weakest = np.where(known, 2 * np.abs(means - 0.5), np.inf).min(axis=1)
        conf = np.where(consistent & enough, weakest, -1.0)
        better = conf > best_conf
        best_conf[better] = conf[better]
        best_bits[better] = bits[better].astype(np.uint8)
        best_known[better] = known[better]
        sector_conf[better] = np.where(known[better], 2 * np.abs(means[better] - 0.5), np.inf)
    return best_conf, best_bits, best_known, sector_conf


def _match_code(
    bits: np.ndarray, known_sectors: np.ndarray, sector_conf: np.ndarray, book: CodeBook, p: DetectParams
) -> tuple[int, int] | None:
    """The CT id and the sectors corrected (0 or 1) of one ring read by :func:`_read_sectors`
    (``bits``, ``known_sectors``, ``sector_conf``: (n,)), or None. A whole ring matches a code
    within ``ct_max_corrected`` sectors, with every other code at least two sectors farther, and
    a corrected sector must be the one read least confidently; a ring cut by the image border
    matches exactly on the sectors read, with every other code ``CT_PARTIAL_MARGIN`` or more
    sectors away there."""
    n = book.sectors
    word = int(sum(int(b) << j for j, b in enumerate(bits)))
    read = int(known_sectors.sum())
    known = None if read == n else int(sum(1 << j for j in np.nonzero(known_sectors)[0]))
    tid, dist, matched, other = book.nearest(word, known)
    if known is None and (dist > p.ct_max_corrected or other <= dist + 1):
        return None
    if known is not None and (dist > 0 or other < CT_PARTIAL_MARGIN):
        return None
    if dist == 1:
        flipped = int(np.log2(word ^ matched))
        if flipped != int(np.argmin(sector_conf)):
            return None
    return tid, dist


def _drop_code_pieces(
    out: pd.DataFrame, maps: np.ndarray, blob_index: pd.Index, extent: float
) -> pd.DataFrame:
    """The CTs of ``out`` (most confident first) that lie inside no more confident one's label: a
    CT's label holds nothing else, so a candidate there is a piece of its code. ``maps``: the
    centre-dot ellipse maps of the candidates whose ``blobs`` rows are ``blob_index``; ``extent``:
    the label's radius in centre-dot radii."""
    centres = out[["u_px", "v_px"]].to_numpy()
    pos = {b: i for i, b in enumerate(blob_index)}
    keep: list[int] = []
    for a in range(len(out)):
        ma = maps[pos[out.blob.iloc[a]]]
        inside = [
            np.linalg.norm(np.linalg.solve(ma, centres[b] - centres[a])) < extent
            or np.linalg.norm(np.linalg.solve(maps[pos[out.blob.iloc[b]]], centres[a] - centres[b])) < extent
            for b in keep
        ]
        if not any(inside):
            keep.append(a)
    return out.iloc[keep]


def decode_coded_targets(
    gray: np.ndarray,
    blobs: pd.DataFrame,
    codes: dict[int, int],
    ct: CodedTargetDesign,
    params: DetectParams | None = None,
) -> pd.DataFrame:
    """Read the ring code around every candidate centre dot; keep the confident, unique ones.

    ``codes``: CT id -> code word (bit k = sector k, :func:`triaxtrack.kit.ct_codes`); ``ct``: the
    kit's ``coded_target`` design. Returns one row per accepted CT: ``id``, ``blob`` (row index in
    ``blobs``), ``u_px``, ``v_px`` (the centre dot's centroid), ``confidence`` (0-1: the weakest
    sector's distance from the mid-level, relative to half the contrast), ``distance`` (sectors
    corrected, 0 or 1), ``white``, ``black`` (grey levels), ``extent_px`` (the label's radius
    along the major axis), ``sectors`` (how many were read: fewer than the design's for a CT cut
    by the image border). IDs read more than once in the frame are all dropped.

    A CT whose ring or surround runs out of the image is read from what is inside (its centre
    dot and white gap must be): at least ``CT_MIN_KNOWN_FRACTION`` of its sectors, matched with
    no correction, and only if every other code differs from the sectors read in
    ``CT_PARTIAL_MARGIN`` or more (so two misread sectors never give another ID, as for a whole
    CT).
    """
    p = params or DetectParams()
    n = int(ct.sectors)
    geo = _ct_geometry(ct)
    cand = _ct_candidates(blobs, p)
    cols = ["id", "blob", "u_px", "v_px", "confidence", "distance", "white", "black", "extent_px", "sectors"]
    if len(cand) == 0:
        return pd.DataFrame(columns=cols)
    sub = blobs.iloc[cand]
    maps = ellipse_maps(sub)  # unit circle -> centre dot ellipse
    centre = sub[["u_px", "v_px"]].to_numpy()
    vals, inside = _sample_ct(gray, centre, maps, _ct_radii(geo), n * CT_SAMPLES_PER_SECTOR)
    norm, black, white, ok = _normalise(vals, inside, p)
    best_conf, best_bits, best_known, sector_conf = _read_sectors(norm[:, 4:-1], n)
    ok &= best_conf >= p.ct_min_confidence
    book = CodeBook.from_codes(codes, n)
    rows = []
    for i in np.nonzero(ok)[0]:
        match = _match_code(best_bits[i], best_known[i], sector_conf[i], book, p)
        if match is None:
            continue
        tid, dist = match
        rows.append(dict(
            id=tid, blob=int(sub.index[i]), u_px=centre[i, 0], v_px=centre[i, 1],
            confidence=float(best_conf[i]), distance=dist, white=float(white[i]),
            black=float(black[i]), extent_px=float(np.linalg.norm(maps[i], 2) * geo.extent),
            sectors=int(best_known[i].sum()),
        ))  # fmt: skip
    out = pd.DataFrame(rows, columns=cols)
    dup = out.id.duplicated(keep=False)
    out = out[~dup].sort_values("confidence", ascending=False)
    return _drop_code_pieces(out, maps, sub.index, geo.extent).sort_values("id").reset_index(drop=True)
