"""Rule probe_video: demux every packet of one recorded video and check it against its own index
(an empty, truncated or frameless file stops here with a message naming it); describe it (frames,
keyframes, fps, size, codec) as JSON."""

import json

from triaxtrack.logs import log_to
from triaxtrack.video import probe_video

log = log_to(snakemake.log[0])

probe = probe_video(snakemake.input.video)
with open(snakemake.output.probe, "w") as f:
    json.dump(probe, f, indent=2, sort_keys=True)
print(f"{probe['path']}: {probe['frames']} frames ({probe['keyframes']} keyframes), {probe['fps']:.6g} fps, "
      f"{probe['width']}x{probe['height']}, {probe['codec']}")  # fmt: skip
