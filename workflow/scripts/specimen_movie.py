"""Rule specimen_movie: the deforming specimen of one test as an MP4 and an HTML page playing it."""

from triaxtrack.logs import log_to
from triaxtrack.report import run_specimen_movie

log_to(snakemake.log[0])

i, o, p = snakemake.input, snakemake.output, snakemake.params
run_specimen_movie(
    points=i.points, strains=i.strains, kit=i.kit,
    movie=o.movie, player=o.player,
    test=snakemake.wildcards.test, report_cfg=p.report,
)  # fmt: skip
