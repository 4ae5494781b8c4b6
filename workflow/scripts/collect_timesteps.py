"""Rule collect_timesteps: the whole test's points, observations, tracks and quality."""

from triaxtrack.logs import log_to
from triaxtrack.timesteps import run_collect_timesteps

log_to(snakemake.log[0])

i, o, p = snakemake.input, snakemake.output, snakemake.params
run_collect_timesteps(
    chunk_points=i.points, chunk_residuals=i.residuals, chunk_motion=i.motion, tracks=i.tracks,
    handovers=i.handovers, labels=i.labels, reference=i.reference, kit=i.kit,
    points=o.points, observations=o.observations, tracking=o.tracking, quality=o.quality,
    handover_px=p.handover_px, cameras_left_out=p.cameras_left_out,
)  # fmt: skip
