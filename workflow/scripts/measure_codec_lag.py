"""Rule measure_codec_lag: how one camera's P frames depart from its keyframes."""

from triaxtrack.codec_lag import run_measure_codec_lag
from triaxtrack.logs import log_to

log_to(snakemake.log[0])

i = snakemake.input
run_measure_codec_lag(
    camera=snakemake.wildcards.camera, tracks=i.tracks, video=i.video, frames=i.frames, kit=i.kit,
    lags=snakemake.output.lags,
)  # fmt: skip
