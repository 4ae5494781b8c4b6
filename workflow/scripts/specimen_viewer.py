"""Rule specimen_viewer: a self-contained offline HTML page of the specimen with a time slider."""

from triaxtrack.logs import log_to
from triaxtrack.report.viewer import run_specimen_viewer

log_to(snakemake.log[0])

i, p = snakemake.input, snakemake.params
run_specimen_viewer(
    volume=i.volume, points=i.points, kit=i.kit, html=snakemake.output.html,
    report_cfg=p.report, volume_cfg=p.volume, name=p.name,
)  # fmt: skip
