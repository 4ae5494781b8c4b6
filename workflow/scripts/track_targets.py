"""Rule track_targets: follow one camera's labelled targets through one chunk."""

from triaxtrack.logs import log_to
from triaxtrack.track_stage import run_track_targets

log_to(snakemake.log[0])

i, o, p = snakemake.input, snakemake.output, snakemake.params
run_track_targets(
    camera=snakemake.wildcards.camera,
    video=i.video, frames=i.frames, labels=i.labels, test_yaml=i.test_yaml, kit=i.kit,
    tracks=o.tracks, handover=o.handover,
    chunk=p.chunk, tracking_cfg=p.tracking,
)  # fmt: skip
