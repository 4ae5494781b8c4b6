"""Rule render_video_chunk: render frames [start, stop) of one camera of a simulated test."""

from pathlib import Path

from triaxtrack.logs import log_to
from triaxtrack.simulate import render_chunk

log = log_to(snakemake.log[0])

render_chunk(
    Path(snakemake.input.test_yaml).parent,
    snakemake.wildcards.camera,
    snakemake.params.frames["start"],
    snakemake.params.frames["stop"],
    snakemake.output.video,
    snakemake.output.observations,
)
