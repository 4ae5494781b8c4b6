"""Rule report_figures: the report's PNG figures of one test (volume and strains, strain maps,
reprojection error, tracking losses, footage quality per camera), drawn with matplotlib."""

from triaxtrack.logs import log_to
from triaxtrack.report import run_report_figures

log_to(snakemake.log[0])

i, o = snakemake.input, snakemake.output
run_report_figures(
    volume=i.volume, strains=i.strains, quality=i.quality, tracking=i.tracking, labels=i.labels, kit=i.kit,
    volume_strain_png=o.volume_strain, strain_maps_png=o.strain_maps, reprojection_png=o.reprojection,
    tracking_png=o.tracking, cameras_png=o.cameras,
    report_cfg=snakemake.params.report,
)  # fmt: skip
