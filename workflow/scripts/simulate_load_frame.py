"""Rule simulate_load_frame: write the simulated load-frame log and its truth."""

from pathlib import Path

from triaxtrack.logs import log_to
from triaxtrack.simulate.loadlog import write_load_frame

log = log_to(snakemake.log[0])

write_load_frame(Path(snakemake.input.test_yaml).parent, snakemake.params.load_frame)
