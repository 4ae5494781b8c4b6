"""Rule frame_map: which video frame of one camera is each test frame."""

from triaxtrack.frames import run_frame_map
from triaxtrack.logs import log_to

log = log_to(snakemake.log[0])  # a sub-frame start offset is warned about here

i = snakemake.input
run_frame_map(
    camera=snakemake.wildcards.camera, video=i.video, test_yaml=i.test_yaml,
    frame_count_video=i.frame_count_video, frames=snakemake.output.frames,
)  # fmt: skip
