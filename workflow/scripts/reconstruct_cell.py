"""Rule reconstruct_cell: cameras and cell wall in air from the labelled cell-wall targets, and the
cameras that see too little of the wall through it, from the targets in the water."""

from triaxtrack.logs import log_to
from triaxtrack.sfm_stage import run_reconstruct_cell

log_to(snakemake.log[0])

i, o, p = snakemake.input, snakemake.output, snakemake.params
run_reconstruct_cell(
    calibrations=i.calibrations, labels=i.labels, kit=i.kit,
    cell=o.cell, points=o.points, residuals=o.residuals,
    reconstruction_cfg=p.reconstruction, cell_cfg=p.cell,
)  # fmt: skip
