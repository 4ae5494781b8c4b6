"""Rule export_paraview: the membrane surface of every processed frame as a ParaView series."""

from triaxtrack.export import measured_membrane_frames, write_paraview_series
from triaxtrack.logs import log_to

log_to(snakemake.log[0])

i = snakemake.input
series = measured_membrane_frames(i.kit, i.volume, i.points, snakemake.params.volume)
done = write_paraview_series(series, snakemake.output.series)
print(f"{len(done['written'])} frames written; failed: {done['failed']}")
