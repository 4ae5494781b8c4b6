"""Rule render_calibration: render one camera's calibration-board images."""

from pathlib import Path

from triaxtrack.logs import log_to
from triaxtrack.simulate import render_calibration

log = log_to(snakemake.log[0])

render_calibration(
    Path(snakemake.input.test_yaml).parent,
    snakemake.wildcards.camera,
    snakemake.output.calibration,
)
