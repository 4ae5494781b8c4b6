"""The workflow's stage of :mod:`triaxtrack.track` (rule track_targets): one camera's chunk from
its video and labels to its tracks and the handover to the next chunk
(:func:`run_track_targets`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.completion import dot_grid
from triaxtrack.frames import ProcessedTestFrames, iter_test_frames
from triaxtrack.kit import load_kit_design
from triaxtrack.tables import FRAME_MAP, LABELS, TRACKS, read_table, write_table
from triaxtrack.testfolder import read_test_fps
from triaxtrack.timesteps import tracking_summary
from triaxtrack.track import processed_frames, track_frames
from triaxtrack.tracking_config import TrackingConfig


@dataclass(frozen=True)
class ChunkPlan:
    """The frames one camera's chunk decodes and reports."""

    first: int  # the labelled frame (the camera's first recorded frame of the chunk)
    end: int  # decode frames first..end-1 (the chunk, and the next chunk's first frame)
    report: np.ndarray  # processed frames of the chunk, and the handover frame
    handover: int  # the frame shared with the next chunk (-1 for the last chunk)


def chunk_frames(
    labels: pd.DataFrame,
    fmap: pd.DataFrame,
    fps: float,
    chunk: dict,
    cfg: TrackingConfig,
    source: str = "labels",
) -> ChunkPlan:
    """What a chunk ``{'start', 'stop'}`` (stop exclusive) of a test with frame map ``fmap``
    tracks, from its ``labels`` (one frame). ValueError naming ``source`` if the labels are of
    no frame of the chunk."""
    n = len(fmap)
    start, stop = int(chunk["start"]), int(chunk["stop"])
    frames = labels["frame"].unique()
    if len(frames) != 1 or not start <= int(frames[0]) < stop:
        raise ValueError(f"{source}: expected the labels of one frame of the chunk {start}..{stop - 1}, "
                         f"got frames {sorted(int(f) for f in frames)}")  # fmt: skip
    first = int(frames[0])
    handover = stop if stop < n else -1
    proc = processed_frames(n, fps, cfg.step_s)
    report = proc[(proc >= first) & (proc < stop)]
    if handover >= 0:
        report = np.r_[report, handover]
    return ChunkPlan(first, stop + 1 if handover >= 0 else stop, report, handover)


def run_track_targets(
    *,
    camera: str,
    video: str | Path,
    frames: str | Path,
    labels: str | Path,
    test_yaml: str | Path,
    kit: str | Path,
    tracks: str | Path,
    handover: str | Path,
    chunk: dict,
    tracking_cfg: dict,
) -> None:
    """Rule track_targets: follow the targets ``camera`` labelled at the first frame of
    ``chunk`` (``{'start', 'stop'}``, stop exclusive; ``labels``) through the chunk of its
    ``video`` (frame map ``frames``, ``test_yaml``'s fps) and on to the next chunk's first frame
    (:func:`chunk_frames`, :func:`~triaxtrack.track.track_frames`).
    ``tracking_cfg``: the config's ``tracking`` section; with ``step_s`` and ``fast`` only the
    processed frames are decoded, with ``complete_grid`` the kit's (folder ``kit``) membrane
    dots not labelled are taken on. Writes the chunk's ``tracks`` and, apart, the ``handover``
    frame's; prints the time taken and the counts per frame."""
    cfg = TrackingConfig.from_dict(tracking_cfg)
    fmap = read_table(frames, FRAME_MAP)
    labelled = read_table(labels, LABELS)
    plan = chunk_frames(labelled, fmap, read_test_fps(test_yaml), chunk, cfg, str(labels))
    fast = cfg.step_s is not None and cfg.fast
    # fast: decode only the processed frames; follow the targets across the others
    sparse = ProcessedTestFrames(video, fmap, plan.first, plan.end, plan.report) if fast else None
    images = sparse if sparse is not None else iter_test_frames(video, fmap, plan.first, plan.end)
    t0 = time.perf_counter()
    grid = dot_grid(load_kit_design(kit)) if cfg.complete_grid else None
    tracked = track_frames(images, labelled, camera, plan.report, cfg, grid)
    seconds = time.perf_counter() - t0
    mode = "every frame decoded"
    if sparse is not None:
        mode = f"fast mode: {sparse.decoded} frames decoded ({sparse.seeks} seeks)"
    print(f"{camera}: {mode} for {len(plan.report)} reported of frames {plan.first}..{plan.end - 1}: "
          f"decoding and tracking {seconds:.2f} s")  # fmt: skip
    shared = tracked["frame"] == plan.handover
    write_table(tracked[~shared], tracks, TRACKS)
    write_table(tracked[shared], handover, TRACKS)
    summary = tracking_summary(tracked[~shared]).drop(columns=["camera", "frame"])
    print(f"{camera}: {labelled['id'].gt(0).sum()} targets labelled at frame {plan.first}; per frame:")
    print(summary.describe().loc[["mean", "min", "max"]].to_string())
