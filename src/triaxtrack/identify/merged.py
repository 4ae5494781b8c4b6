"""Dots whose image merged with something: a longitudinal stripe's dots re-centred beside a dark
edge, membrane dots re-centred beside a stripe's white band, and membrane dots merged in pairs
fitted apart.

Two membrane dots whose images merged into one blob (at high strain and low resolution) are
labelled once the grid around them is: between their labelled neighbours along a column or a
row, the blob is fitted with two Gaussians (:func:`~triaxtrack.detect.merged_pair_centroids`)
and each dot gets its own row at its fitted centre, with ``quality`` ``MERGED_QUALITY``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from triaxtrack.detect import gap_background_centroids, merged_pair_centroids
from triaxtrack.identify.membrane import _grid_neighbour, _is_membrane
from triaxtrack.identify.state import LABEL_COLUMNS, IdentifyParams, _Frame
from triaxtrack.kit_design import MembraneDesign

GAP_ACROSS_PX = 1.0  # a re-centred dot's window reaches this far across beyond its moment ellipse
# two membrane dots merged in one blob (at 10 % strain, 720p) and fitted apart: on the one test
# of four with them, 228 dots were 0.11 px off at the median and 0.30 px at worst, so they are
# reported with a lower quality
MERGED_HEIGHT_RATIO = 2.0  # the two fitted Gaussians' heights agree within this factor
MERGED_FIT_RMS = 0.25  # residual RMS of the fit over the blob's largest contrast, at most
MERGED_QUALITY = 0.5


def _recentred_beside_edge(
    f: _Frame, uv: np.ndarray, edge: np.ndarray, gray: np.ndarray, stripes: set[str]
) -> tuple[np.ndarray, np.ndarray]:
    """(blob indices, their new distorted centroids) of the labelled dots of ``stripes`` beside a
    dark edge whose two neighbours along the stripe are labelled, re-centred by
    :func:`~triaxtrack.detect.gap_background_centroids`; where that fails, left out."""
    on = np.isin(f.group, list(stripes))
    blob_of = {(f.group[k], int(f.ids[k])): k for k in np.nonzero(on)[0]}
    sel, prev, nxt = [], [], []
    for k in np.nonzero(on & edge)[0]:
        a, b = (blob_of.get((f.group[k], int(f.ids[k]) + s)) for s in (-1, 1))
        if a is not None and b is not None:
            sel.append(k)
            prev.append(a)
            nxt.append(b)
    return _recentred_between(f, uv, np.asarray(sel, int), np.asarray(prev, int), np.asarray(nxt, int), gray)


def _recentred_between(
    f: _Frame, uv: np.ndarray, at: np.ndarray, prev: np.ndarray, nxt: np.ndarray, gray: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(blob indices, their new distorted centroids) of the dots ``at`` (blob indices) between
    their neighbours ``prev`` and ``nxt`` along a row of dots, re-centred by
    :func:`~triaxtrack.detect.gap_background_centroids`; where that fails, left out."""
    if not len(at):
        return at, np.zeros((0, 2))
    minor = f.blobs.minor_px.to_numpy()[at]
    new = gap_background_centroids(gray, uv[at], uv[prev], uv[nxt], 0.5 * minor + GAP_ACROSS_PX)
    ok = np.isfinite(new).all(axis=1)
    return at[ok], new[ok]


def _recentred_beside_band(
    f: _Frame, uv: np.ndarray, beside: np.ndarray, gray: np.ndarray, m: MembraneDesign
) -> tuple[np.ndarray, np.ndarray]:
    """(blob indices, their new distorted centroids) of the labelled membrane dots ``beside`` a
    longitudinal stripe's white band whose two neighbours along their column are labelled,
    re-centred by :func:`~triaxtrack.detect.gap_background_centroids`: the band's blurred edge
    runs along the column, so it brightens the gaps beside each dot as it does the dot's own
    surround, and cancels; where that fails, left out."""
    member = np.nonzero(_is_membrane(f.ids, m))[0]
    blob_of = pd.Series(member, index=f.ids[member])
    blob_of = blob_of[~blob_of.index.duplicated()]
    at = member[beside[member]]
    prev, nxt = (blob_of.reindex(_grid_neighbour(f.ids[at], m, dr, 0)).to_numpy() for dr in (-1, 1))
    ok = np.isfinite(prev) & np.isfinite(nxt)
    return _recentred_between(f, uv, at[ok], prev[ok].astype(int), nxt[ok].astype(int), gray)


def _split_merged_pairs(
    f: _Frame,
    uv: np.ndarray,
    gray: np.ndarray,
    free: np.ndarray,
    m: MembraneDesign,
    p: IdentifyParams,
    detect_params,
) -> pd.DataFrame:
    """Label rows (``LABEL_COLUMNS``) of membrane dots merged in pairs, each pair fitted apart
    by :func:`~triaxtrack.detect.merged_pair_centroids`.

    Two neighbouring unlabelled grid nodes A, B between labelled dots U, D (U, A, B, D along a
    column or a row) whose images merged (a blob at the midpoint of U and D, ``free``: nothing
    labelled it or turned it down, and larger than U and D) are expected at the thirds of U-D.
    They are labelled when both fitted centres lie within the gate of the thirds, their heights
    agree within a factor of ``MERGED_HEIGHT_RATIO`` and the fit leaves under
    ``MERGED_FIT_RMS`` of the blob's contrast.
    ``uv``: the blobs' (distorted) centroids. The merged blob itself stays unlabelled, with a reason.
    """
    member = np.nonzero(_is_membrane(f.ids, m))[0]
    labelled = f.ids[member]
    blob_of = pd.Series(member, index=labelled)
    blob_of = blob_of[~blob_of.index.duplicated()]
    tree = cKDTree(uv)
    area = f.blobs.area_px.to_numpy()
    white = f.blobs.background.to_numpy()
    quads: list[tuple[int, int, int, int]] = []  # blob of U, IDs of A and B, blob of D
    for dr, dc in ((1, 0), (0, 1)):
        a, b, d = (_grid_neighbour(labelled, m, j * dr, j * dc) for j in (1, 2, 3))
        ok = (a > 0) & (b > 0) & ~np.isin(a, labelled) & ~np.isin(b, labelled) & np.isin(d, labelled)
        quads += zip(member[ok], a[ok], b[ok], blob_of.reindex(d[ok]).to_numpy(), strict=True)
    rows: list[dict] = []
    taken: set[int] = set()
    split: set[int] = set()
    for ku, id_a, id_b, kd in sorted(quads, key=lambda q: (f.ids[q[0]], q[2] - q[1])):
        step = (uv[kd] - uv[ku]) / 3
        gate = p.gate * np.linalg.norm(step)
        dist, k = tree.query(uv[ku] + 1.5 * step)
        if (
            {id_a, id_b} & taken
            or k in split
            or dist > gate
            or not free[k]
            or area[k] <= max(area[ku], area[kd])
        ):
            continue
        expected = np.array([uv[ku] + step, uv[ku] + 2 * step])
        centres, (ha, hb, rms, roundness) = merged_pair_centroids(
            gray, expected[0], expected[1], white[k], uv[[ku, kd]], detect_params
        )
        if not (
            np.isfinite(centres).all()
            and (np.linalg.norm(centres - expected, axis=1) <= gate).all()
            and 0 < min(ha, hb)
            and max(ha, hb) <= MERGED_HEIGHT_RATIO * min(ha, hb)
            and rms <= MERGED_FIT_RMS
        ):
            continue
        taken |= {int(id_a), int(id_b)}
        split.add(k)
        f.reason[k] = f"two dots merged, fitted apart as {id_a} and {id_b}"
        for tid, c in zip((id_a, id_b), centres, strict=True):
            rows.append({"id": int(tid), "kind": "dot", "group": f.group[ku], "u_px": c[0], "v_px": c[1],
                         "area_px": area[k] / 2, "roundness": roundness, "quality": MERGED_QUALITY,
                         "reason": ""})  # fmt: skip
    return pd.DataFrame(rows, columns=[c for c in LABEL_COLUMNS if "undist" not in c])
