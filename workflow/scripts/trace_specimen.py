"""Rule trace_specimen: the first frame's targets in the water, the cell frame, the outputs."""

from triaxtrack.logs import log_to
from triaxtrack.specimen_stage import run_trace_specimen

log_to(snakemake.log[0])

i, o, p = snakemake.input, snakemake.output, snakemake.params
run_trace_specimen(
    cell=i.cell, cell_points=i.cell_points, air_residuals=i.air_residuals, labels=i.labels, kit=i.kit,
    test_yaml=i.test_yaml,
    cameras=o.cameras, points=o.points, observations=o.observations, quality=o.quality,
    residuals=o.residuals, picture=o.picture,
    reconstruction_cfg=p.reconstruction, cell_cfg=p.cell,
)  # fmt: skip
