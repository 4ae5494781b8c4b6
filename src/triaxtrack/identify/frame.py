"""One frame's identification (:func:`identify`, the steps in order, then the accuracy filters),
detection and identification of a grey frame (:func:`label_frame`), the chunk start's labels
(:func:`label_chunk_start`) and a picture of them for a person to check (:func:`draw_labels`);
the workflow's stages, from the files to the labels and pictures (:func:`run_identify_targets`)
and every chunk's labels in one table (:func:`run_collect_labels`).
The method is described in :mod:`triaxtrack.identify`."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from triaxtrack.calibrate.files import calibrated_camera
from triaxtrack.detect import DetectParams, background_size_px
from triaxtrack.identify.anchors import _axis_down, _pedestal_anchors
from triaxtrack.identify.cell import (
    BEHIND_BAND,
    _band_zone,
    _hide_behind_band,
    _label_cell_stripes,
    _label_longitudinal,
    _on_another_surface,
    _over_chain_neighbours,
    _row_pitch_px,
    _straight_chains,
)
from triaxtrack.identify.coded import _ct_maps, _inside_cts, _plausible_cts
from triaxtrack.identify.grid import _Pool
from triaxtrack.identify.membrane import (
    _is_membrane,
    _label_beside_band,
    _label_membrane,
    _membrane_row_ends,
    _off_grid,
    _over_neighbours,
    _without_cross_support,
)
from triaxtrack.identify.merged import _recentred_beside_band, _recentred_beside_edge, _split_merged_pairs
from triaxtrack.identify.state import LABEL_COLUMNS, NOT_REACHED, UNLABELLED, IdentifyParams, _Frame
from triaxtrack.identify.uncoded_stripes import label_uncoded_stripes
from triaxtrack.kit import ct_codes, load_kit_design, target_table
from triaxtrack.kit_design import KitDesign
from triaxtrack.tables import FRAME_MAP, LABELS, concat_tables, read_table, write_table
from triaxtrack.testfolder import read_calibration

if TYPE_CHECKING:
    from triaxtrack.optics import Camera

# a membrane dot beside a dark edge this much less round than its grid neighbours (seen at the
# same angle) has merged with the edge's fringe: on the demo one at 0.52 was 1.4 px off; 0.45 %
# of all labelled membrane dots on four tests fall below it, beside an edge or not
MERGED_ROUNDNESS_RATIO = 0.55
# a membrane dot beside a dark edge this much larger than its grid neighbours has merged with the
# edge: of 869 end-row dots beside a gap in their row on four tests, 99 % were under 1.33 and at
# most 0.39 px off; the largest (1.8) was 0.93 px off; on soft footage (720p, 1 px blur) an end-row
# dot at 2x its neighbours' area was 1.28 px off without a gap beside it
MERGED_AREA_RATIO = 1.5
# a dot whose blob's long axis (over its printed diameter) is this much longer than its grid
# neighbours' (membrane) or its stripe neighbours' (cell wall) holds more than one dot, or a dot
# and an edge's fringe, wherever it is: on the 10 % strain test at 720p (nvr, 16 cameras, 4 chunk
# starts, 70,070 labelled membrane dots) the two wrong IDs (end-row dots merged with the row
# beside them or the pedestal's edge, 1.2 and 2.3 px off) were 1.75 and 1.96 times their
# neighbours' length, and 18 dots (0.03 %) over 1.6. Along a cell-wall stripe the same holds of
# the area over the printed diameter squared: a cell band's last dot at a silhouette (450 mm ring,
# 1080p), merged with the dot beside it, 1.2 px off, was 1.85 times its neighbour's area; 7 of
# 4,433 cell-wall dots on four tests (clean and nvr, 720p and 1080p) were over 1.6
MERGED_LENGTH_RATIO = 1.6
FAR_PX = 1e9
OFF_GRID = "off the line of its grid column or row (an edge's fringe or a neighbour in its centroid)"
# a dot whose image (its moment ellipse) reaches a longitudinal band's printed edge is partly
# hidden: not labelled. One whose image comes within this of it (where the band's blurred edge
# still brightens pixels) leans on the band's fringe: its centroid, 0.1-0.4 px off at 4K (cam01
# of nvr-13cam-4k: 67 such dots, 0.37 px at the 90th percentile), is re-measured against the
# gaps beside it along its column (there 0.04 px at the median, 0.16 px at worst:
# :func:`_recentred_beside_band`), or not labelled
BAND_BLUR_PX = 0.5
BLUR_REACH = 1.0  # a blurred band edge biases a dot about one lens-blur sigma beyond it
LOCAL_DOTS = 7  # a dot and its nearest blobs, whose median size is a whole dot's there


def _band_blur(blur_px: float) -> float:
    """How far (pixels) a band's blurred edge reaches beyond its printed edge: ``BLUR_REACH``
    lens-blur sigmas ``blur_px``, at least ``BAND_BLUR_PX``."""
    return max(BAND_BLUR_PX, BLUR_REACH * blur_px)


def _hide_behind_bands(
    f: _Frame,
    pool: _Pool,
    long_names: set[str],
    blur_px: float,
    design: KitDesign,
    gray: np.ndarray | None,
    detect_params: DetectParams | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Take out of the pool what lies behind or beside the white band of each identified
    longitudinal stripe (groups ``long_names``): a dot whose image (half its major axis) comes
    within the band's blurred edge (``BAND_BLUR_PX``, or ``BLUR_REACH`` lens-blur sigmas
    ``blur_px``, beyond it). Of those, a dot whose whole image (half its major axis, or half the
    median of the dots' around it where that is longer: a dot partly behind the band images smaller,
    and its visible part's centroid lies farther from the band than its centre) reaches the band
    itself is partly hidden; the others are beside it, their centroids leaning on the edge's fringe
    (labelled later from the grid around them and re-centred: :func:`identify`). Returns per blob
    (pixels) the reaches ``(whole image, own image and blur)``, the blobs in a band's zone (bool),
    widened by the white level's closing size when ``gray`` is given (beside a band a dot's white
    level is the band's), and the dots beside a band."""
    blobs = f.blobs
    major = blobs.major_px.to_numpy()
    near = pool.tree.query(f.pos, k=min(LOCAL_DOTS, len(major)))[1].reshape(len(major), -1)
    image = np.maximum(major, np.median(major[near], axis=1)) / 2 if len(major) else major / 2
    pad = major / 2 + _band_blur(blur_px)
    # a dot's white level is a closing over `size` pixels: beside a band it reads the band's white
    size = background_size_px(gray.shape[1], detect_params) if gray is not None else 0
    known, beside = np.zeros(len(blobs), bool), np.zeros(len(blobs), bool)
    for sel in (np.nonzero(f.group == nm)[0] for nm in long_names):
        if len(sel) >= 2:
            order = sel[np.argsort(f.ids[sel])]
            beside |= _hide_behind_band(f, pool, order, image, pad, design)
            known |= _band_zone(f, order, pad + size, design)
    return np.c_[image, pad], known, beside


def _drop_unidentified_stripes(
    f: _Frame, pool: _Pool, centres: dict, known: np.ndarray, reach: np.ndarray, design: KitDesign
) -> tuple[np.ndarray, list[np.ndarray], np.ndarray, float]:
    """Take out of the pool the longitudinal stripes whose coded target is out of the picture: a
    straight line of free dots along the axis, on a white band in front of the membrane, never
    membrane dots, whose band hides the membrane (``reach``: :func:`_hide_behind_bands`). Dots in
    an identified stripe's band zone (``known``) are not candidates: their white level is its.
    Returns the dots left beside these bands, the stripes (blob indices, in order along each),
    the image direction down the specimen and the membrane's row pitch (pixels)."""
    pos = f.pos
    axis = _axis_down(_pedestal_anchors(centres, design))
    free = np.nonzero(pool.free)[0]
    pitch = float(np.nanmedian(_row_pitch_px(pos, free, axis))) if len(free) > 9 else np.nan
    cand = np.nonzero(_on_another_surface(pool) & ~known)[0]
    beside = np.zeros(len(pos), bool)
    chains = _straight_chains(pos, cand, axis, pitch, design)
    for order in chains:
        pool.free[order] = False
        f.reason[order] = "on a longitudinal stripe not identified (its coded target not seen)"
        beside |= _hide_behind_band(f, pool, order, reach[:, 0], reach[:, 1], design)
    return beside, chains, axis, pitch


def _drop_inaccurate(
    f: _Frame,
    edge: np.ndarray,
    recentred: np.ndarray,
    design: KitDesign,
    p: IdentifyParams,
    beside: np.ndarray,
) -> None:
    """Unlabel (with the reason) the labelled dots whose centroid is not accurate: cut by the image
    border; beside a longitudinal stripe's band (``beside``) and not re-centred; too small or seen
    too obliquely for their place (see :class:`IdentifyParams`: cell-wall dots beside a dark edge
    (``edge``) need more, re-centred ones (``recentred``) less roundness); the last dot of a
    membrane row beside a dark edge (a silhouette, a pedestal edge), whose blob takes in the edge's
    fringe (up to 1.4 px off on the demo), while the end rows along the pedestal faces keep theirs,
    also beside a gap where one of their dots was lost to the pedestal's edge (on four tests 0.17 px
    at the 95th percentile; the one bad dot, 0.93 px off, had taken in the edge: 1.8 times its
    neighbours' area); and dots merged with an edge or another dot, by their size and roundness
    against their grid or stripe neighbours (``MERGED_*``); and, of the membrane dots left, those no
    dot of the rows above or below confirms
    (:func:`~triaxtrack.identify.membrane._without_cross_support`)."""
    blobs, n, m = f.blobs, len(f.blobs), design.membrane
    membrane = _is_membrane(f.ids, m)
    cell_area = np.where(edge, p.min_cell_area_px, p.min_clear_cell_area_px)
    cell_round = np.where(edge, p.min_cell_roundness, p.min_clear_cell_roundness)
    cell_round = np.where(recentred, p.min_recentred_roundness, cell_round)
    row_end, row_gap = _membrane_row_ends(f.ids, m)
    at_border = blobs.at_border.to_numpy(bool, copy=True) if "at_border" in blobs else np.zeros(n, bool)
    # each blob's long axis over its target's printed diameter
    diameter = target_table(design).set_index("id").diameter_mm.reindex(f.ids).to_numpy()
    length = blobs.major_px.to_numpy() / diameter
    area = blobs.area_px.to_numpy() / diameter**2
    for bad, why in (
        (at_border, "cut by the image border"),
        (beside & ~recentred, BEHIND_BAND),
        (blobs.area_px.to_numpy() < np.where(membrane, p.min_membrane_area_px, cell_area),
         "too small for an accurate centroid"),
        (blobs.roundness.to_numpy() < np.where(membrane, p.min_membrane_roundness, cell_round),
         "seen too obliquely for an accurate centroid"),
        (row_end & ~row_gap & edge,
         "last of its membrane row, beside a dark edge"),
        (edge & (_over_neighbours(f.ids, blobs.area_px.to_numpy(), m) > MERGED_AREA_RATIO),
         "larger than its neighbours beside a dark edge (merged with the edge)"),
        ((_over_neighbours(f.ids, blobs.roundness.to_numpy(), m) < MERGED_ROUNDNESS_RATIO) & edge,
         "less round than its neighbours, beside a dark edge (merged with the edge's fringe)"),
        (_over_neighbours(f.ids, length, m) > MERGED_LENGTH_RATIO,
         "longer than its grid neighbours (two dots, or a dot and an edge, merged)"),
        (~membrane & (np.fmax(_over_chain_neighbours(f.ids, length, f.group),
                              _over_chain_neighbours(f.ids, area, f.group)) > MERGED_LENGTH_RATIO),
         "larger than its neighbours along its stripe (two dots, or a dot and an edge, merged)"),
    ):  # fmt: skip
        bad &= f.ids != UNLABELLED
        f.ids[bad] = UNLABELLED
        f.reason[bad] = why
    off = _off_grid(f.ids, f.pos, blobs.area_px.to_numpy(), m)  # on the labels left
    f.ids[off] = UNLABELLED
    f.reason[off] = OFF_GRID
    alone = _without_cross_support(f.ids, m) & (f.ids != UNLABELLED)
    f.ids[alone] = UNLABELLED
    f.reason[alone] = "no labelled grid neighbour in the rows above or below (a row's chain alone)"


def _merged_pair_rows(
    f: _Frame,
    uv: np.ndarray,
    gray: np.ndarray,
    free: np.ndarray,
    undistort: Callable[[np.ndarray], np.ndarray],
    design: KitDesign,
    p: IdentifyParams,
    detect_params: DetectParams | None,
) -> pd.DataFrame:
    """The rows (``LABEL_COLUMNS``) of membrane dots merged in pairs and fitted apart
    (:func:`_split_merged_pairs`) among the ``free`` blobs, with their undistorted pixels; a dot
    beyond the lens model is left out."""
    split = _split_merged_pairs(f, uv, gray, free, design.membrane, p, detect_params)
    und = undistort(split[["u_px", "v_px"]].to_numpy(np.float64)) if len(split) else np.zeros((0, 2))
    split = split.assign(u_undist_px=und[:, 0], v_undist_px=und[:, 1])
    return split[np.isfinite(und).all(axis=1)]


def _label_table(
    f: _Frame, cts: pd.DataFrame, candidates: np.ndarray, uv: np.ndarray, split: pd.DataFrame
) -> pd.DataFrame:
    """The frame's labels (``LABEL_COLUMNS``): a row per CT (``quality`` its code's confidence),
    per candidate dot (labelled, or ``id`` -1 with its reason) and per dot of a merged pair
    fitted apart (``split``); ``uv``: the dots' pixels (re-centred ones moved)."""
    blobs, pos = f.blobs, f.pos
    ct_rows = pd.DataFrame({
        "id": cts.id.to_numpy(np.int64), "kind": "coded", "group": "coded",
        "u_px": cts.u_px.to_numpy(), "v_px": cts.v_px.to_numpy(),
        "u_undist_px": pos[cts.blob.to_numpy(), 0] if len(cts) else [],
        "v_undist_px": pos[cts.blob.to_numpy(), 1] if len(cts) else [],
        "area_px": blobs.area_px.to_numpy()[cts.blob.to_numpy()] if len(cts) else [],
        "roundness": blobs.roundness.to_numpy()[cts.blob.to_numpy()] if len(cts) else [],
        "quality": cts.confidence.to_numpy(), "reason": "",
    })  # fmt: skip
    sel = np.nonzero(candidates)[0]
    dot_rows = pd.DataFrame({
        "id": f.ids[sel], "kind": "dot", "group": f.group[sel],
        "u_px": uv[sel, 0], "v_px": uv[sel, 1], "u_undist_px": pos[sel, 0], "v_undist_px": pos[sel, 1],
        "area_px": blobs.area_px.to_numpy()[sel], "roundness": blobs.roundness.to_numpy()[sel],
        "quality": f.quality[sel], "reason": f.reason[sel],
    })  # fmt: skip
    parts = [ct_rows, dot_rows] + ([split[LABEL_COLUMNS].astype(dot_rows.dtypes)] if len(split) else [])
    return pd.concat(parts, ignore_index=True)[LABEL_COLUMNS]


def identify(
    blobs: pd.DataFrame,
    cts: pd.DataFrame,
    design: KitDesign,
    undistort,
    dots: np.ndarray,
    params: IdentifyParams | None = None,
    gray: np.ndarray | None = None,
    detect_params=None,
) -> pd.DataFrame:
    """Label one frame's detections (see the module docstring).

    ``blobs``/``cts``: from :func:`triaxtrack.detect.detect_blobs` and
    :func:`~triaxtrack.coded_targets.decode_coded_targets`; ``dots``: the blobs that pass the dot
    criteria (:func:`~triaxtrack.detect.dot_mask`); ``undistort``: (N, 2) distorted pixels ->
    undistorted pixels; ``gray``: the frame, if given, re-centres the longitudinal stripes' dots
    beside a dark edge and the membrane dots beside a stripe's band
    (:func:`~triaxtrack.detect.gap_background_centroids`; without it those are not labelled)
    and fits membrane dots merged in pairs apart (:func:`_split_merged_pairs`, with
    ``detect_params``' ink rule).
    Returns one row per CT and per dot (columns ``LABEL_COLUMNS``), ``id`` -1 with a ``reason``
    where the dot could not be labelled beyond doubt; a merged pair's two dots have a row each.
    """
    p = params or IdentifyParams()
    blur_px = float(blobs.blur.iloc[0]) if "blur" in blobs and len(blobs) else 0.0
    uv = blobs[["u_px", "v_px"]].to_numpy(np.float64, copy=True)
    pos = undistort(uv) if len(uv) else uv.copy()
    invertible = np.isfinite(pos).all(axis=1)
    pos = np.where(invertible[:, None], pos, FAR_PX)  # beyond the lens model: never a candidate
    n = len(blobs)
    f = _Frame(
        blobs=blobs,
        pos=pos,
        ids=np.full(n, UNLABELLED, np.int64),
        group=np.full(n, "", object),
        quality=np.zeros(n),
        reason=np.full(n, NOT_REACHED, object),
    )
    in_ct = _inside_cts(f, cts, design.coded_target)
    cts = _plausible_cts(cts, design)
    candidates = np.asarray(dots, bool) & ~in_ct & invertible
    centres = _ct_maps(f, cts, undistort)
    pool = _Pool(pos, candidates, blobs)
    _label_cell_stripes(f, pool, centres, design, p)
    _label_longitudinal(f, pool, centres, design, p)
    long_names = {s.name for s in design.cell_targets.longitudinal_stripes}
    reach, known, beside = _hide_behind_bands(f, pool, long_names, blur_px, design, gray, detect_params)
    beside_uncoded, chains, axis, pitch = _drop_unidentified_stripes(f, pool, centres, known, reach, design)
    beside |= beside_uncoded
    _label_membrane(f, pool, centres, design, p)
    # a stripe beyond the membrane's silhouette is on no brighter surface than its own dots: it is
    # a straight chain among the dots the membrane leaves
    left = np.nonzero(pool.free & (f.ids == UNLABELLED))[0]
    chains = chains + _straight_chains(pos, left, axis, pitch, design)
    label_uncoded_stripes(f, chains, candidates, gray, axis, blur_px, design)  # named by the membrane behind
    _label_beside_band(f, pool, beside, reach[:, 0], _band_blur(blur_px), design.membrane, p)
    edge = blobs.beside_edge.to_numpy(bool, copy=True)
    recentred = np.zeros(n, bool)
    if gray is not None:
        # a longitudinal stripe seen edge-on lies along the dark beyond its band: its dots'
        # centroids, re-measured against the gaps' background, are as good as those clear of it
        k, new = _recentred_beside_edge(f, uv, edge, gray, long_names)
        new_pos = undistort(new) if len(k) else new
        ok = np.isfinite(new_pos).all(axis=1)
        k, new, new_pos = k[ok], new[ok], new_pos[ok]
        uv[k], pos[k], edge[k], recentred[k] = new, new_pos, False, True
        # a membrane dot beside a band: the band's fringe runs along its column, past its gaps
        k, new = _recentred_beside_band(f, uv, beside, gray, design.membrane)
        new_pos = undistort(new) if len(k) else new
        ok = np.isfinite(new_pos).all(axis=1)
        uv[k[ok]], pos[k[ok]], recentred[k[ok]] = new[ok], new_pos[ok], True
    _drop_inaccurate(f, edge, recentred, design, p, beside)
    split = pd.DataFrame(columns=LABEL_COLUMNS)
    if gray is not None:
        # a blob nothing labelled or turned down (not by a band, a filter), clear of a dark edge
        free = ~in_ct & invertible & ~edge & (f.reason == NOT_REACHED)
        split = _merged_pair_rows(f, uv, gray, free, undistort, design, p, detect_params)
    return _label_table(f, cts, candidates, uv, split)


def undistorted_pixels(camera: Camera) -> Callable[[np.ndarray], np.ndarray]:
    """(N, 2) distorted pixels -> undistorted pixels of ``camera`` (NaN where not invertible)."""
    from functools import partial

    from triaxtrack.optics import pixels_to_undistorted

    return partial(pixels_to_undistorted, camera)


def label_frame(gray: np.ndarray, camera, design: KitDesign, codes: dict[int, int], detect_params=None,
                identify_params: IdentifyParams | None = None) -> pd.DataFrame:  # fmt: skip
    """Detect and identify every target in one grey frame of a calibrated ``camera``
    (:class:`triaxtrack.optics.Camera`, intrinsics used), with ``detect_params`` scaled to the
    frame's exposure (:func:`~triaxtrack.detect.exposure_params`). Columns ``LABEL_COLUMNS``."""
    from triaxtrack.coded_targets import decode_coded_targets
    from triaxtrack.detect import detect_blobs, dot_mask, exposure_params

    detect_params = exposure_params(gray, detect_params)
    blobs = detect_blobs(gray, detect_params)
    cts = decode_coded_targets(gray, blobs, codes, design.coded_target, detect_params)
    return identify(blobs, cts, design, undistorted_pixels(camera), dot_mask(blobs, detect_params),
                    identify_params, gray=gray, detect_params=detect_params)  # fmt: skip


def draw_labels(gray: np.ndarray, labels: pd.DataFrame, scale: int = 2) -> np.ndarray:
    """A BGR picture of the frame with every labelled target's ID, for a person to check.

    Green: CTs (ID printed); cyan: cell dots; yellow: membrane dots (ID printed on the larger
    ones and every tenth); red crosses: detections left unlabelled.
    """
    import cv2

    img = cv2.cvtColor(np.asarray(gray, np.uint8), cv2.COLOR_GRAY2BGR)
    img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_LINEAR)
    font = cv2.FONT_HERSHEY_SIMPLEX
    for r in labels.itertuples(index=False):
        c = (int(round((r.u_px + 0.5) * scale - 0.5)), int(round((r.v_px + 0.5) * scale - 0.5)))
        if r.id == UNLABELLED:
            cv2.drawMarker(img, c, (0, 0, 255), cv2.MARKER_TILTED_CROSS, 3 * scale, 1)
            continue
        if r.kind == "coded":
            colour, text = (0, 220, 0), str(r.id)
        elif str(r.group).startswith("membrane"):
            colour, text = (0, 220, 220), str(r.id) if r.id % 10 == 0 else ""
        else:
            colour, text = (220, 220, 0), str(r.id) if r.id % 4 == 1 else ""
        cv2.circle(img, c, 2 * scale, colour, 1, cv2.LINE_AA)
        if text:
            cv2.putText(
                img, text, (c[0] + 3 * scale, c[1] - 2 * scale), font, 0.3 * scale, colour, 1, cv2.LINE_AA
            )
    return img


def label_chunk_start(
    video_path, fmap: pd.DataFrame, camera, design: KitDesign, codes: dict[int, int], start: int, stop: int
) -> tuple[int | None, np.ndarray | None, pd.DataFrame]:
    """Label the first frame of the chunk ``[start, stop)`` that the camera recorded.

    Returns ``(frame, image, labels)``; ``frame`` is None (and ``labels`` empty) when the camera
    recorded none of the chunk's frames. ``labels`` carries ``camera`` and ``frame`` columns.
    """
    from triaxtrack.frames import iter_test_frames

    for k, image in iter_test_frames(video_path, fmap, start, stop):
        if image is not None:
            labels = label_frame(image, camera, design, codes)
            return k, image, labels.assign(camera=camera.name, frame=k)
    return None, None, pd.DataFrame(columns=["camera", "frame", *LABEL_COLUMNS])


def run_identify_targets(
    *,
    video: str | Path,
    frames: str | Path,
    calibration: str | Path,
    kit: str | Path,
    labels: str | Path,
    frame: str | Path,
    overlay: str | Path,
    chunk: dict,
) -> None:
    """Rule identify_targets: label the first frame of ``chunk`` (``{'start', 'stop'}``, stop
    exclusive) that the camera of ``calibration`` recorded in ``video`` (frame map ``frames``),
    with the kit folder ``kit``; write the ``labels`` table, the grey ``frame`` and the
    ``overlay`` of the labels as PNG, and print the counts. ValueError naming the video when the
    camera recorded none of the chunk's frames (the labels table is written first, empty)."""
    import cv2

    camera = calibrated_camera(read_calibration(calibration))
    design = load_kit_design(kit)
    codes = ct_codes(design, target_table(design))
    fmap = read_table(frames, FRAME_MAP)
    start, stop = chunk["start"], chunk["stop"]
    k, image, got = label_chunk_start(video, fmap, camera, design, codes, start, stop)
    write_table(got, labels, LABELS)
    if image is None:
        raise ValueError(
            f"{video}: camera {camera.name} recorded none of test frames {start}..{stop - 1} (see {frames})"
        )
    cv2.imwrite(str(frame), image)
    cv2.imwrite(str(overlay), draw_labels(image, got))
    found = got[got.id > 0]
    print(
        f"{camera.name} frame {k}: {len(found)} targets labelled ({(found.kind == 'coded').sum()} CTs), "
        f"{(got.id < 0).sum()} detections left unlabelled:"
    )
    print(got[got.id < 0].reason.value_counts().to_string())


def run_collect_labels(*, chunk_labels: Sequence[str | Path], labels: str | Path) -> None:
    """Rule collect_labels: every camera's chunk labels (``chunk_labels``, rule
    identify_targets) of a test in one ``labels`` table; prints the counts."""
    got = concat_tables(chunk_labels, LABELS)
    write_table(got, labels, LABELS)
    found = got[got.id > 0]
    print(f"{len(found)} labels in {got.groupby(['camera', 'frame']).ngroups} camera frames")
