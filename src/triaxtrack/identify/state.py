"""The working state of one frame's identification, its parameters and the label table's columns."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

UNLABELLED = -1
NOT_REACHED = "not reached from any coded target"  # the reason of a dot nothing labelled


@dataclass(frozen=True)
class IdentifyParams:
    """Gates, as fractions of the local dot spacing, and the checks' limits."""

    gate: float = 0.3  # a predicted dot must be within this fraction of the local spacing
    anchor_gate: float = 0.35  # the Eq. 1 and stripe-end predictions (over 9-16 mm from a CT)
    large_area_ratio: float = 1.15  # a larger dot's area over its neighbours', at least
    phase_margin: float = 0.12  # log-area margin of the large-dot phase over the next best
    min_region_dots: int = 12  # a membrane grid region smaller than this is left unlabelled
    row_tolerance: float = 1.2  # |row estimated from a pedestal CT - row assigned|, rows
    # smaller or more oblique dots are detected but not labelled, where their centroid is not
    # accurate. A dot beside a dark edge (the dark beyond a band's or a label's edge, towards a
    # silhouette) takes in the edge's blurred fringe: oblique 6-7 px stripe dots at 720p were
    # 0.15-0.27 px off, so cell-wall dots there need a larger, rounder image; a longitudinal
    # stripe's dots re-centred against the background in its gaps (see identify) were 0.05-0.06 px
    # at the 95th percentile on four tests, and count as clear of the edge. Clear of an edge, dots
    # down to 4 px were within 0.1 px at the 95th percentile on four tests, membrane dots at
    # any roundness, cell-wall dots down to 0.3; but a cell-wall dot on the sliver of a ring's
    # label at the cell's silhouette (roundness 0.32-0.38, its edge not flagged) was 0.4-1.0 px
    # off, so those stop at 0.4
    min_cell_area_px: float = 8.0  # beside an edge
    min_cell_roundness: float = 0.5  # beside an edge
    min_clear_cell_area_px: float = 4.0
    min_clear_cell_roundness: float = 0.4
    # a longitudinal stripe's dot re-centred (see identify): down to 0.2, all were within 0.1 px
    min_recentred_roundness: float = 0.2
    min_membrane_area_px: float = 4.0
    min_membrane_roundness: float = 0.2


LABEL_COLUMNS = [
    "id", "kind", "group", "u_px", "v_px", "u_undist_px", "v_undist_px", "area_px", "roundness",
    "quality", "reason",
]  # fmt: skip


@dataclass
class _Frame:
    """Working state of one frame's identification."""

    blobs: pd.DataFrame
    pos: np.ndarray  # undistorted centroids of all blobs
    ids: np.ndarray  # per blob, UNLABELLED until labelled
    group: np.ndarray  # per blob, stripe or region name
    quality: np.ndarray
    reason: np.ndarray


def _assign(f: _Frame, blob: int, tid: int, group: str, quality: float) -> None:
    f.ids[blob] = tid
    f.group[blob] = group
    f.quality[blob] = quality
    f.reason[blob] = ""
