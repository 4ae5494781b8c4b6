"""Rule specimen_movie: the deforming specimen of one test as an MP4 and an HTML page playing it."""

from triaxtrack.kit import load_kit_design
from triaxtrack.logs import log_to
from triaxtrack.report import chosen_frames, membrane_layout, specimen_frames, write_movie, write_movie_page
from triaxtrack.tables import POINTS, STRAINS, read_table

log_to(snakemake.log[0])

params = snakemake.params
layout = membrane_layout(load_kit_design(snakemake.input.kit))
points = read_table(snakemake.input.points, POINTS)
strains = read_table(snakemake.input.strains, STRAINS)
frames = chosen_frames(points["frame"].unique(), params.max_frames)
movie = specimen_frames(
    points,
    layout,
    strains,
    colour_by=params.colour_by,
    frames=frames,
    height=params.height_px,
    magnify=params.magnify,
)
n = write_movie(movie, snakemake.output.movie, params.fps)
write_movie_page(
    snakemake.output.movie,
    snakemake.output.player,
    f"test {snakemake.wildcards.test}: {n} frames of {points['frame'].nunique()}, coloured by "
    f"{params.colour_by}, displacements x{params.magnify:g}",
)
print(f"{snakemake.output.movie}: {n} frames at {params.fps} fps ({layout.describe()})")
