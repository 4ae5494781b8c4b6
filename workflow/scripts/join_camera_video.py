"""Rule join_camera_video: join one camera's chunk videos by stream copy."""

from triaxtrack.logs import log_to
from triaxtrack.video import concat_videos

log = log_to(snakemake.log[0])

frames = concat_videos(list(snakemake.input.segments), snakemake.output.video)
print(f"{snakemake.output.video}: {frames} frames from {len(snakemake.input.segments)} segments")
