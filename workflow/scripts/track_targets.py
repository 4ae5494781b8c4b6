"""Rule track_targets: follow one camera's labelled targets through one chunk."""

import time

import yaml

from triaxtrack.completion import dot_grid
from triaxtrack.frames import ProcessedTestFrames, iter_test_frames
from triaxtrack.kit import load_kit_design
from triaxtrack.logs import log_to
from triaxtrack.tables import FRAME_MAP, LABELS, TRACKS, read_table, write_table
from triaxtrack.timesteps import tracking_summary
from triaxtrack.track import TrackingConfig, chunk_frames, track_frames

log_to(snakemake.log[0])

cfg = TrackingConfig.from_dict(snakemake.params.tracking)
fmap = read_table(snakemake.input.frames, FRAME_MAP)
labels = read_table(snakemake.input.labels, LABELS)
fps = float(yaml.safe_load(open(snakemake.input.test_yaml))["fps"])
camera = snakemake.wildcards.camera
plan = chunk_frames(labels, fmap, fps, snakemake.params.chunk, cfg, snakemake.input.labels)
fast = cfg.step_s is not None and snakemake.params.tracking["fast"]
if fast:  # decode only the processed frames; follow the targets across the others
    frames = ProcessedTestFrames(snakemake.input.video, fmap, plan.first, plan.end, plan.report)
else:
    frames = iter_test_frames(snakemake.input.video, fmap, plan.first, plan.end)
t0 = time.perf_counter()
complete = snakemake.params.tracking["complete_grid"]
grid = dot_grid(load_kit_design(snakemake.input.kit)) if complete else None
tracks = track_frames(frames, labels, camera, plan.report, cfg, grid)
seconds = time.perf_counter() - t0
mode = f"fast mode: {frames.decoded} frames decoded ({frames.seeks} seeks)" if fast else "every frame decoded"
print(f"{camera}: {mode} for {len(plan.report)} reported of frames {plan.first}..{plan.end - 1}: "
      f"decoding and tracking {seconds:.2f} s")  # fmt: skip
shared = tracks["frame"] == plan.handover
write_table(tracks[~shared], snakemake.output.tracks, TRACKS)
write_table(tracks[shared], snakemake.output.handover, TRACKS)
summary = tracking_summary(tracks[~shared]).drop(columns=["camera", "frame"])
print(f"{camera}: {labels['id'].gt(0).sum()} targets labelled at frame {plan.first}; per frame:")
print(summary.describe().loc[["mean", "min", "max"]].to_string())
