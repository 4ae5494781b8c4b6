"""Rule reconstruct_cell: cameras and cell wall in air from the labelled cell-wall targets."""

import json

from triaxtrack.calibrate import calibrated_camera, read_calibration
from triaxtrack.kit import design_points, load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.sfm import SfmConfig, cell_summary, reconstruct_cell
from triaxtrack.tables import LABELS, POINTS, RESIDUALS, read_table, write_table

log_to(snakemake.log[0])

cameras = {}
for path in snakemake.input.calibrations:
    cam = calibrated_camera(read_calibration(path))
    cameras[cam.name] = cam
design = load_kit_design(snakemake.input.kit)
table = target_table(design)
cell_targets = design_points(design, table)[(table["surface"] == "cell_outer").to_numpy()]
labels = read_table(snakemake.input.labels, LABELS)
rec = reconstruct_cell(cameras, labels, cell_targets, SfmConfig.from_dict(snakemake.params.reconstruction))
summary = cell_summary(rec)
with open(snakemake.output.cell, "w") as f:
    json.dump(summary, f, indent=2)
write_table(rec.points.assign(frame=0, time_s=0.0), snakemake.output.points, POINTS)
write_table(rec.residuals, snakemake.output.residuals, RESIDUALS)
print(json.dumps({k: v for k, v in summary.items() if k != "cameras"}, indent=2))
