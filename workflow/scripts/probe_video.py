"""Rule probe_video: demux every packet of one recorded video and check it against its own index
(an empty, truncated or frameless file stops here with a message naming it); describe it (frames,
keyframes, fps, size, codec) as JSON."""

from triaxtrack.inventory import run_probe_video
from triaxtrack.logs import log_to

log = log_to(snakemake.log[0])

run_probe_video(video=snakemake.input.video, probe=snakemake.output.probe)
