"""Rule export_paraview: the membrane surface of every processed frame as a ParaView series."""

from triaxtrack.export import membrane_frames, write_paraview_series
from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.tables import POINTS, VOLUME_RESULT, read_table

log_to(snakemake.log[0])

design = load_kit_design(snakemake.input.kit)
volume = read_table(snakemake.input.volume, VOLUME_RESULT)
points = read_table(snakemake.input.points, POINTS)
cfg = snakemake.params.volume
reference = volume["reference_frame"].dropna()
frames = volume.loc[volume["reason"] == "", "frame"].tolist()
series = membrane_frames(
    points, target_table(design), design, frames, int(reference.iloc[0]) if len(reference) else -1,
    t0=cfg["membrane_thickness_mm"], max_missing_share=cfg["max_missing_share"],
)  # fmt: skip
done = write_paraview_series(series, snakemake.output.series)
print(f"{len(done['written'])} frames written; failed: {done['failed']}")
