"""Rule report_figures: the report's PNG figures of one test (volume and strains, strain maps,
reprojection error, tracking losses, footage quality per camera)."""

import json

import cv2

from triaxtrack.camera_report import camera_quality, camera_quality_plot
from triaxtrack.logs import log_to
from triaxtrack.report import (
    chosen_frames,
    reprojection_plot,
    strain_maps,
    tracking_plot,
    volume_strain_plot,
)
from triaxtrack.tables import LABELS, STRAINS, TRACKS, VOLUME, read_table

log_to(snakemake.log[0])

volume = read_table(snakemake.input.volume, VOLUME)
strains = read_table(snakemake.input.strains, STRAINS)
with open(snakemake.input.quality) as f:
    quality = json.load(f)
tracks = read_table(snakemake.input.tracking, TRACKS)
cameras = camera_quality(tracks, read_table(snakemake.input.labels, LABELS))
print(cameras.to_string(index=False))

frames = chosen_frames(strains["frame"].unique(), snakemake.params.strain_map_frames)
print(f"strain maps at frames {frames}")
figures = {
    snakemake.output.volume_strain: volume_strain_plot(volume),
    snakemake.output.strain_maps: strain_maps(strains, frames),
    snakemake.output.reprojection: reprojection_plot(quality),
    snakemake.output.tracking: tracking_plot(tracks),
    snakemake.output.cameras: camera_quality_plot(cameras),
}
for path, image in figures.items():
    if not cv2.imwrite(path, image):
        raise OSError(f"cannot write {path}")
    print(f"{path}: {image.shape[1]} x {image.shape[0]} px")
