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
from triaxtrack.timesteps import MOTION, handover_check, timestep_quality

log_to(snakemake.log[0])

table = target_table(load_kit_design(snakemake.input.kit))
membrane_ids = table.loc[table["surface"] == "membrane", "id"].to_numpy()
points = concat_tables(snakemake.input.points, POINTS)
residuals = concat_tables(snakemake.input.residuals, RESIDUALS)
motion = concat_tables(snakemake.input.motion, MOTION)
tracks = concat_tables(snakemake.input.tracks, TRACKS)
labels = read_table(snakemake.input.labels, LABELS)
reference = json.load(open(snakemake.input.reference))
tol = snakemake.params.handover_px

handovers = []
for path in snakemake.input.handovers:
    shared = read_table(path, TRACKS)
    for (camera, frame), got in shared.groupby(["camera", "frame"]):
        lab = labels[(labels["camera"] == camera) & (labels["frame"] == frame)]
        check = {"camera": camera, "frame": int(frame), "source": str(path)}
        if lab.empty:
            check["note"] = "the next chunk's labels are of a later frame: not compared"
        else:
            check.update(handover_check(got, lab, tol))
        handovers.append(check)

observations = tracks[tracks["reason"] == ""].merge(
    residuals[["camera", "frame", "id", "du_px", "dv_px", "used", "reason"]].rename(columns={"reason": "reason_3d"}),
    on=["camera", "frame", "id"], how="left",
)  # fmt: skip
observations["used"] = observations["used"].astype("boolean").fillna(False).astype(bool)
observations = observations.drop(columns=["reason"]).rename(columns={"reason_3d": "reason"}).fillna({"reason": ""})
quality = timestep_quality(reference, points, residuals, tracks, motion, handovers, membrane_ids)

write_table(points, snakemake.output.points, POINTS)
write_table(observations, snakemake.output.observations, OBSERVATIONS)
write_table(tracks, snakemake.output.tracking, TRACKS)
with open(snakemake.output.quality, "w") as f:
    json.dump(quality, f, indent=2)
print(json.dumps({k: quality[k] for k in ("mean_reprojection_px", "tracking", "camera_motion")}, indent=2))
print(pd.DataFrame(quality["frames"]).describe().to_string())
print(f"handovers: {quality['handovers']['checked']} checked, {quality['handovers']['disagreements']} disagreements")
