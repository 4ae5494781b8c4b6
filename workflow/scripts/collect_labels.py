"""Rule collect_labels: every camera's chunk labels of a test in one table."""

from triaxtrack.identify import run_collect_labels
from triaxtrack.logs import log_to

log_to(snakemake.log[0])

run_collect_labels(chunk_labels=snakemake.input.labels, labels=snakemake.output.labels)
