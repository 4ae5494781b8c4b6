"""Rule simulate_truth: gather the chunk observations into truth/points and truth/observations."""

from pathlib import Path

from triaxtrack.logs import log_to
from triaxtrack.simulate import finish_truth

log = log_to(snakemake.log[0])

finish_truth(Path(snakemake.input.test_yaml).parent, list(snakemake.input.chunks))
