"""Rule reconstruct_cell: cameras and cell wall in air from the labelled cell-wall targets, and the
cameras that see too little of the wall through it, from the targets in the water."""

import json

from triaxtrack.calibrate import calibrated_camera, read_calibration
from triaxtrack.kit import design_points, load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.optics import cell_optics
from triaxtrack.sfm import SfmConfig, cell_summary, reconstruct_cell
from triaxtrack.tables import LABELS, POINTS, RESIDUALS, read_table, write_table

log_to(snakemake.log[0])

cameras = {}
for path in snakemake.input.calibrations:
    cam = calibrated_camera(read_calibration(path))
    cameras[cam.name] = cam
design = load_kit_design(snakemake.input.kit)
table = target_table(design)
points = design_points(design, table)
wall = (table["surface"] == "cell_outer").to_numpy()
# targets in the water at their design positions at the reference frame (the specimen undeformed),
# for the cameras that see too little of the wall
water = points[~wall].assign(kind=table.loc[~wall, "surface"].to_numpy())
given = snakemake.params.cell
cell = cell_optics(
    design,
    wall_thickness_mm=given["wall_thickness_mm"],
    n_acrylic=given["n_acrylic"],
    n_water=given["n_water"],
)
labels = read_table(snakemake.input.labels, LABELS)
cfg = SfmConfig.from_dict(snakemake.params.reconstruction)
rec = reconstruct_cell(cameras, labels, points[wall], cfg, water=water, cell=cell)
summary = cell_summary(rec)
with open(snakemake.output.cell, "w") as f:
    json.dump(summary, f, indent=2)
write_table(rec.points.assign(frame=0, time_s=0.0), snakemake.output.points, POINTS)
write_table(rec.residuals, snakemake.output.residuals, RESIDUALS)
print(json.dumps({k: v for k, v in summary.items() if k != "cameras"}, indent=2))
for name, why in summary["cameras_dropped"].items():
    print(f"WARNING: {name} left out: {why}")
