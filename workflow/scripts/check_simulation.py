"""Rule check_simulation: check a finished synthetic test folder; write a JSON report."""

from pathlib import Path

from triaxtrack.logs import log_to
from triaxtrack.simulate import check_simulation

log = log_to(snakemake.log[0])

check_simulation(Path(snakemake.input.test_yaml).parent, snakemake.output.json)
