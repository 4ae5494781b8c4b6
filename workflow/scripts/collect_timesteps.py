"""Rule collect_timesteps: the whole test's points, observations, tracks and quality."""

import json

import pandas as pd

from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.tables import (
    LABELS,
    OBSERVATIONS,
    POINTS,
    RESIDUALS,
    TRACKS,
    concat_tables,
    read_table,
    write_table,
)
from triaxtrack.timesteps import MOTION, handover_checks, observations_table, timestep_quality

log_to(snakemake.log[0])

table = target_table(load_kit_design(snakemake.input.kit))
membrane_ids = table.loc[table["surface"] == "membrane", "id"].to_numpy()
points = concat_tables(snakemake.input.points, POINTS)
residuals = concat_tables(snakemake.input.residuals, RESIDUALS)
motion = concat_tables(snakemake.input.motion, MOTION)
tracks = concat_tables(snakemake.input.tracks, TRACKS)
shared = concat_tables(snakemake.input.handovers, TRACKS)
handovers = handover_checks(shared, read_table(snakemake.input.labels, LABELS), snakemake.params.handover_px)
reference = json.load(open(snakemake.input.reference))
quality = timestep_quality(
    reference, points, residuals, tracks, motion, handovers, membrane_ids, snakemake.params.cameras_left_out
)

write_table(points, snakemake.output.points, POINTS)
write_table(observations_table(tracks, residuals), snakemake.output.observations, OBSERVATIONS)
write_table(tracks, snakemake.output.tracking, TRACKS)
with open(snakemake.output.quality, "w") as f:
    json.dump(quality, f, indent=2)
print(json.dumps({k: quality[k] for k in ("mean_reprojection_px", "tracking", "camera_motion")}, indent=2))
print(pd.DataFrame(quality["frames"]).describe().to_string())
h = quality["handovers"]
print(f"handovers: {h['checked']} checked, {h['disagreements']} disagreements")
