"""Rule identify_targets: detect and label every target in the first frame of one camera's chunk."""

from triaxtrack.identify import run_identify_targets
from triaxtrack.logs import log_to

log_to(snakemake.log[0])

i, o = snakemake.input, snakemake.output
run_identify_targets(
    video=i.video, frames=i.frames, calibration=i.calibration, kit=i.kit,
    labels=o.labels, frame=o.frame, overlay=o.overlay,
    chunk=snakemake.params.chunk,
)  # fmt: skip
