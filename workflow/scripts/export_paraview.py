"""Rule export_paraview: the membrane surface of every processed frame as a ParaView series."""

from triaxtrack.export import run_export_paraview
from triaxtrack.logs import log_to

log_to(snakemake.log[0])

i = snakemake.input
run_export_paraview(
    kit=i.kit, volume=i.volume, points=i.points,
    series=snakemake.output.series,
    volume_cfg=snakemake.params.volume,
)  # fmt: skip
