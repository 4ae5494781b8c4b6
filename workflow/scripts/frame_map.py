"""Rule frame_map: which video frame of one camera is each test frame."""

from triaxtrack.frames import count_test_frames, frame_map, read_camera_timing, summarize_frame_map
from triaxtrack.logs import log_to
from triaxtrack.tables import FRAME_MAP, write_table
from triaxtrack.video import probe_video

log = log_to(snakemake.log[0])  # a sub-frame start offset is warned about here

timing = read_camera_timing(snakemake.input.test_yaml, snakemake.wildcards.camera)
frames = count_test_frames(snakemake.input.test_yaml, snakemake.input.frame_count_video or None)
fmap = frame_map(timing, frames, probe_video(snakemake.input.video)["frames"])
write_table(fmap, snakemake.output.frames, FRAME_MAP)
print(f"{timing.camera}: {summarize_frame_map(fmap)}, offset residual {timing.offset_residual_s:+.4f} s")
