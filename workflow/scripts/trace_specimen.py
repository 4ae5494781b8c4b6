"""Rule trace_specimen: the first frame's targets in the water, the cell frame, the outputs."""

import json

import cv2
import yaml

from triaxtrack.kit import design_points, load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.optics import cell_optics, read_cameras
from triaxtrack.plots import reconstruction_picture
from triaxtrack.sfm import REFERENCE_FRAME
from triaxtrack.tables import LABELS, OBSERVATIONS, POINTS, RESIDUALS, read_table, write_table
from triaxtrack.triangulate import TriangulationConfig, quality_report, reconstruct_specimen

log_to(snakemake.log[0])


cell_doc = json.loads(open(snakemake.input.cell).read())
cameras = read_cameras(snakemake.input.cell)
design = load_kit_design(snakemake.input.kit)
table = target_table(design)
points = design_points(design, table)
given = snakemake.params.cell
cell = cell_optics(
    design,
    outer_radius=cell_doc["cell"]["outer_radius_mm"],
    wall_thickness_mm=given["wall_thickness_mm"],
    n_acrylic=given["n_acrylic"],
    n_water=given["n_water"],
)
fps = float(yaml.safe_load(open(snakemake.input.test_yaml))["fps"])
labels = read_table(snakemake.input.labels, LABELS)
in_water = table.loc[table["surface"] != "cell_outer", "id"].to_numpy()
bottom = points[(table["surface"] == "pedestal_bottom").to_numpy()]
rec = reconstruct_specimen(
    cameras,
    read_table(snakemake.input.cell_points, POINTS).drop(columns=["frame", "time_s"]),
    read_table(snakemake.input.air_residuals, RESIDUALS),
    labels,
    in_water,
    bottom,
    cell,
    cell_doc["cell"]["outer_radius_sigma_mm"],
    TriangulationConfig.from_dict(snakemake.params.reconstruction),
    REFERENCE_FRAME,
    REFERENCE_FRAME / fps,
)
membrane_ids = table.loc[table["surface"] == "membrane", "id"].to_numpy()
quality = quality_report(rec, labels, membrane_ids)
quality["cell"]["wavelength_nm"] = given["wavelength_nm"] or design["cell"].get("wavelength_nm")
quality["cell"]["temperature_c"] = given["temperature_c"] or design["cell"].get("temperature_c")
quality["cell"]["axis_tilt_deg"] = cell_doc["cell"]["axis_tilt_deg"]
quality["cell"]["cylinder_rms_mm"] = cell_doc["cell"]["cylinder_rms_mm"]
quality["cell"]["source"] = cell_doc["cell"]["source"]
quality["cameras_posed"] = cell_doc["cameras_posed"]
quality["cameras_dropped"] = cell_doc["cameras_dropped"]

with open(snakemake.output.cameras, "w") as f:
    json.dump({"cameras": {n: c.to_json() for n, c in sorted(rec.cameras.items())}}, f, indent=2)
write_table(rec.points, snakemake.output.points, POINTS)
used = rec.residuals[rec.residuals["used"]]
write_table(used[used["frame"] == REFERENCE_FRAME], snakemake.output.observations, OBSERVATIONS)
write_table(rec.residuals, snakemake.output.residuals, RESIDUALS)
with open(snakemake.output.quality, "w") as f:
    json.dump(quality, f, indent=2)

water_used = used[used["medium"] == "water"]
picture = reconstruction_picture(
    rec.cameras, rec.points, rec.cell, water_used, membrane_ids, quality["mean_reprojection_px"]
)
cv2.imwrite(snakemake.output.picture, picture)
print(json.dumps({k: v for k, v in quality.items() if k != "per_camera"}, indent=2))
