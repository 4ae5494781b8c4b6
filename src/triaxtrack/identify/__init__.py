"""Identification: give every detected dot its design ID, or leave it unlabelled with a reason.

The paper's section 2.3, second half, against the kit design (``triaxtrack.kit``). All geometry
is done in undistorted pixels (ideal pinhole pixels of the calibrated camera matrix), where a
straight line in space stays straight. Every step accepts a dot only when it is the single
candidate within its gate (a fraction of the local dot spacing) and not claimed twice; the
larger dots must be larger. A region, stripe or grid that fails a check is left unlabelled
(``reason``), never guessed.

Modules (the method of each step is described in its module):

* :mod:`~triaxtrack.identify.state`: the frame's working state, :class:`IdentifyParams` and
  ``LABEL_COLUMNS``;
* :mod:`~triaxtrack.identify.grid`: the pool of candidate dots, chain and grid growing, a CT's
  local affine map and ellipse helpers;
* :mod:`~triaxtrack.identify.coded`: the decoded CTs (centres and ellipse maps, the blobs on
  their labels, the plausible ones, the CT stripes);
* :mod:`~triaxtrack.identify.cell`: the cell's annular stripes (Eq. 1) and longitudinal
  stripes, and the bands that hide the membrane behind them (and the dots beside them);
* :mod:`~triaxtrack.identify.uncoded_stripes`: longitudinal stripes whose CTs are out of the
  picture (a close ring), named by the membrane behind them and counted from a printed end;
* :mod:`~triaxtrack.identify.membrane`: the membrane grid's regions, phase and IDs (Eq. 4),
  regions fixed across a band, the dots beside a band labelled from the grid around them, and
  the grid-neighbour checks on membrane IDs (a dot off the smooth lines of its grid column and
  row by more than its size class's centroid noise allows is not labelled:
  :func:`~triaxtrack.identify.membrane._off_grid`);
* :mod:`~triaxtrack.identify.anchors`: the pedestal CTs that fix a region's column and row;
* :mod:`~triaxtrack.identify.merged`: stripe dots re-centred beside a dark edge, membrane dots
  re-centred beside a band, and membrane dots merged in pairs fitted apart (``quality``
  ``MERGED_QUALITY``);
* :mod:`~triaxtrack.identify.frame`: :func:`identify` (one frame's detections, then the accuracy
  filters), :func:`label_frame`, :func:`label_chunk_start` and :func:`draw_labels`, and the
  workflow's stages (:func:`run_identify_targets`, :func:`run_collect_labels`).
"""

from triaxtrack.identify.anchors import MAX_TAN_PHI, MIN_OVERRULING_PAIRS, settle_offsets
from triaxtrack.identify.anchors import _Anchor as _Anchor
from triaxtrack.identify.anchors import _anchor_offsets as _anchor_offsets
from triaxtrack.identify.anchors import _axis_down as _axis_down
from triaxtrack.identify.anchors import _grid_steps as _grid_steps
from triaxtrack.identify.anchors import _membrane_region_offsets as _membrane_region_offsets
from triaxtrack.identify.anchors import _MembraneView as _MembraneView
from triaxtrack.identify.anchors import _pedestal_anchors as _pedestal_anchors
from triaxtrack.identify.anchors import _width_ratio as _width_ratio
from triaxtrack.identify.cell import CHAIN_AXIS_DEG, CHAIN_LINE_PX, MIN_CHAIN_DOTS, SURFACE_NEIGHBOURS
from triaxtrack.identify.cell import _hide_behind_band as _hide_behind_band
from triaxtrack.identify.cell import _label_cell_stripes as _label_cell_stripes
from triaxtrack.identify.cell import _label_longitudinal as _label_longitudinal
from triaxtrack.identify.cell import _near_polyline as _near_polyline
from triaxtrack.identify.cell import _neighbour_down as _neighbour_down
from triaxtrack.identify.cell import _on_another_surface as _on_another_surface
from triaxtrack.identify.cell import _straight_chains as _straight_chains
from triaxtrack.identify.coded import _ct_maps as _ct_maps
from triaxtrack.identify.coded import _ct_stripes as _ct_stripes
from triaxtrack.identify.coded import _inside_cts as _inside_cts
from triaxtrack.identify.coded import _plausible_cts as _plausible_cts
from triaxtrack.identify.coded import _theta_dir as _theta_dir
from triaxtrack.identify.frame import (
    BAND_BLUR_PX,
    BLUR_REACH,
    FAR_PX,
    MERGED_AREA_RATIO,
    MERGED_ROUNDNESS_RATIO,
    draw_labels,
    identify,
    label_chunk_start,
    label_frame,
    run_collect_labels,
    run_identify_targets,
    undistorted_pixels,
)
from triaxtrack.identify.grid import (
    AREA_RANGE,
    MIN_SUPPORT,
    NEIGHBOURS,
    WHITE_TOLERANCE,
    ellipse_radius,
    grow_chain,
    grow_grid,
    local_affine,
    undistorted_jacobians,
)
from triaxtrack.identify.grid import _grow_region as _grow_region
from triaxtrack.identify.grid import _Pool as _Pool
from triaxtrack.identify.grid import _seed_grid as _seed_grid
from triaxtrack.identify.membrane import _bridge as _bridge
from triaxtrack.identify.membrane import _grid_ids as _grid_ids
from triaxtrack.identify.membrane import _grid_neighbour as _grid_neighbour
from triaxtrack.identify.membrane import _grid_phase as _grid_phase
from triaxtrack.identify.membrane import _is_membrane as _is_membrane
from triaxtrack.identify.membrane import _label_membrane as _label_membrane
from triaxtrack.identify.membrane import _membrane_row_ends as _membrane_row_ends
from triaxtrack.identify.membrane import _over_neighbours as _over_neighbours
from triaxtrack.identify.membrane import _row_ends as _row_ends
from triaxtrack.identify.membrane import _without_cross_support as _without_cross_support
from triaxtrack.identify.merged import GAP_ACROSS_PX, MERGED_FIT_RMS, MERGED_HEIGHT_RATIO, MERGED_QUALITY
from triaxtrack.identify.merged import _recentred_beside_edge as _recentred_beside_edge
from triaxtrack.identify.merged import _split_merged_pairs as _split_merged_pairs
from triaxtrack.identify.state import LABEL_COLUMNS, NOT_REACHED, UNLABELLED, IdentifyParams
from triaxtrack.identify.state import _assign as _assign
from triaxtrack.identify.state import _Frame as _Frame

__all__ = [
    "AREA_RANGE", "BAND_BLUR_PX", "BLUR_REACH", "CHAIN_AXIS_DEG", "CHAIN_LINE_PX", "FAR_PX",
    "GAP_ACROSS_PX", "IdentifyParams", "LABEL_COLUMNS", "MAX_TAN_PHI", "MERGED_AREA_RATIO",
    "MERGED_FIT_RMS", "MERGED_HEIGHT_RATIO", "MERGED_QUALITY", "MERGED_ROUNDNESS_RATIO",
    "MIN_CHAIN_DOTS", "MIN_OVERRULING_PAIRS", "MIN_SUPPORT", "NEIGHBOURS", "NOT_REACHED",
    "SURFACE_NEIGHBOURS", "UNLABELLED", "WHITE_TOLERANCE", "draw_labels", "ellipse_radius", "grow_chain",
    "grow_grid", "identify", "label_chunk_start", "label_frame", "local_affine", "run_collect_labels",
    "run_identify_targets",
    "settle_offsets", "undistorted_jacobians", "undistorted_pixels",
]  # fmt: skip
