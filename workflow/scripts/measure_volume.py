"""Rule measure_volume: soil volume and strains of every processed frame, meshes of a few."""

from triaxtrack.logs import log_to
from triaxtrack.volume import run_measure_volume

log_to(snakemake.log[0])

i, o = snakemake.input, snakemake.output
run_measure_volume(
    points=i.points, observations=i.observations, kit=i.kit,
    volume=o.volume, strains=o.strains, meshes=o.meshes,
    volume_cfg=snakemake.params.volume,
)  # fmt: skip
