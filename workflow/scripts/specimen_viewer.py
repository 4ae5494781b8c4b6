"""Rule specimen_viewer: a self-contained offline HTML page of the specimen with a time slider."""

from pathlib import Path

from triaxtrack.export import MembraneFrame, measured_membrane_frames
from triaxtrack.logs import log_to
from triaxtrack.report.viewer import viewer_html

log_to(snakemake.log[0])

i, p = snakemake.input, snakemake.params
series = list(measured_membrane_frames(i.kit, i.volume, i.points, p.volume, p.max_frames))
shown = [f for f in series if isinstance(f, MembraneFrame)]
skipped = [f for f in series if not isinstance(f, MembraneFrame)]
Path(snakemake.output.html).write_text(viewer_html(shown, p.colour_by, p.name, skipped))
print(f"viewer: {len(shown)} of {len(series)} frames")
