"""Rule report_figures: the report's PNG figures of one test (volume and strains, strain maps,
reprojection error, tracking losses, footage quality per camera), drawn with matplotlib."""

import json

from triaxtrack.camera_report import camera_quality, camera_quality_figure
from triaxtrack.kit import load_kit_design
from triaxtrack.logs import log_to
from triaxtrack.report import (
    chosen_frames,
    membrane_layout,
    reprojection_figure,
    save_figure,
    strain_maps_figure,
    tracking_figure,
    volume_strain_figure,
)
from triaxtrack.tables import LABELS, STRAINS, TRACKS, VOLUME, read_table

log_to(snakemake.log[0])

layout = membrane_layout(load_kit_design(snakemake.input.kit))
print(f"kit: {layout.describe()}")
volume = read_table(snakemake.input.volume, VOLUME)
strains = read_table(snakemake.input.strains, STRAINS)
with open(snakemake.input.quality) as f:
    quality = json.load(f)
tracks = read_table(snakemake.input.tracking, TRACKS)
cameras = camera_quality(tracks, read_table(snakemake.input.labels, LABELS))
print(cameras.to_string(index=False))

frames = chosen_frames(strains["frame"].unique(), snakemake.params.strain_map_frames)
print(f"strain maps at frames {frames}")
out = snakemake.output
save_figure(volume_strain_figure(volume), out.volume_strain)
save_figure(strain_maps_figure(strains, layout, frames), out.strain_maps)
save_figure(reprojection_figure(quality), out.reprojection)
save_figure(tracking_figure(tracks, layout), out.tracking)
save_figure(camera_quality_figure(cameras), out.cameras)
print(f"figures written: {', '.join(out)}")
