"""Rule probe_video: describe one recorded video (frames, fps, size, codec) as JSON."""

import json

from triaxtrack.logs import log_to
from triaxtrack.video import probe_video

log = log_to(snakemake.log[0])

with open(snakemake.output.probe, "w") as f:
    json.dump(probe_video(snakemake.input.video), f, indent=2, sort_keys=True)
