"""Rule triangulate_chunk: every tracked target in the water at every processed frame of a chunk."""

from triaxtrack.logs import log_to
from triaxtrack.timesteps import run_triangulate_chunk

log_to(snakemake.log[0])

i, o, p = snakemake.input, snakemake.output, snakemake.params
run_triangulate_chunk(
    tracks=i.tracks, lags=i.lags, cameras=i.cameras, reference=i.reference, reference_points=i.points,
    kit=i.kit, test_yaml=i.test_yaml,
    points=o.points, residuals=o.residuals, motion=o.motion,
    reconstruction_cfg=p.reconstruction, tracking_cfg=p.tracking,
)  # fmt: skip
