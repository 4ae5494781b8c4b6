"""Rule specimen_viewer: a self-contained offline HTML page of the specimen with a time slider."""

from pathlib import Path

from triaxtrack.export import MembraneFrame, membrane_frames
from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.report import chosen_frames
from triaxtrack.report.viewer import viewer_html
from triaxtrack.tables import POINTS, VOLUME_RESULT, read_table

log_to(snakemake.log[0])

design = load_kit_design(snakemake.input.kit)
volume = read_table(snakemake.input.volume, VOLUME_RESULT)
points = read_table(snakemake.input.points, POINTS)
cfg = snakemake.params.volume
reference = volume["reference_frame"].dropna()
frames = chosen_frames(volume.loc[volume["reason"] == "", "frame"].tolist(), snakemake.params.max_frames)
series = membrane_frames(
    points, target_table(design), design, frames, int(reference.iloc[0]) if len(reference) else -1,
    t0=cfg["membrane_thickness_mm"], max_missing_share=cfg["max_missing_share"],
)  # fmt: skip
shown = [f for f in series if isinstance(f, MembraneFrame)]
Path(snakemake.output.html).write_text(viewer_html(shown, snakemake.params.colour_by, snakemake.params.name))
print(f"viewer: {len(shown)} of {len(frames)} frames")
