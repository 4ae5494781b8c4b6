"""Rule triangulate_chunk: every tracked target in the water at every processed frame of a chunk."""

import json

import numpy as np
import yaml

from triaxtrack.codec_lag import corrected_tracks, read_lag_files
from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.optics import CellOptics, read_cameras
from triaxtrack.tables import POINTS, RESIDUALS, TRACKS, concat_tables, read_table, write_table
from triaxtrack.timesteps import MOTION, camera_motion, triangulate_frames
from triaxtrack.triangulate import TriangulationConfig

log_to(snakemake.log[0])

cameras = read_cameras(snakemake.input.cameras)
cell_doc = json.load(open(snakemake.input.reference))["cell"]
cell = CellOptics(
    outer_radius=cell_doc["outer_radius_mm"],
    inner_radius=cell_doc["inner_radius_mm"],
    n_acrylic=cell_doc["n_acrylic"],
    n_water=cell_doc["n_water"],
)
table = target_table(load_kit_design(snakemake.input.kit))
fps = float(yaml.safe_load(open(snakemake.input.test_yaml))["fps"])
tracks = concat_tables(snakemake.input.tracks, TRACKS)
if snakemake.input.lags:  # P frames moved by each camera's codec lag (rule measure_codec_lag)
    tracks = corrected_tracks(tracks, read_lag_files(snakemake.input.lags))
reference = read_table(snakemake.input.points, POINTS)
wall = reference[reference["id"].isin(table.loc[table["surface"] == "cell_outer", "id"])]
moved_px = snakemake.params.tracking["moved_px"]
motion, poses = camera_motion(cameras, wall, tracks, moved_px)
in_water = table.loc[table["surface"] != "cell_outer", "id"].to_numpy()
frames = np.unique(tracks["frame"].to_numpy())
points, residuals = triangulate_frames(
    cameras, tracks, cell, in_water, frames, fps,
    TriangulationConfig.from_dict(snakemake.params.reconstruction), motion, poses,
)  # fmt: skip
write_table(points, snakemake.output.points, POINTS)
write_table(residuals, snakemake.output.residuals, RESIDUALS)
write_table(motion, snakemake.output.motion, MOTION)
print(f"{len(frames)} frames, {len(points)} points, {int(residuals['used'].sum())} observations used")
print(points.groupby("frame").size().describe().to_string())
moved = motion[motion["moved"]]
if len(moved):
    print(f"cameras moved (cell-wall drift above {moved_px} px): {sorted(set(moved['camera']))}, "
          f"posed again at {int(moved['reposed'].sum())} of their {len(moved)} frames")  # fmt: skip
print(f"largest cell-wall drift: {motion['drift_px'].max():.3f} px")
