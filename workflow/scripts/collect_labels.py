"""Rule collect_labels: every camera's chunk labels of a test in one table."""

from triaxtrack.logs import log_to
from triaxtrack.tables import LABELS, concat_tables, write_table

log_to(snakemake.log[0])

labels = concat_tables(snakemake.input.labels, LABELS)
write_table(labels, snakemake.output.labels, LABELS)
got = labels[labels.id > 0]
print(f"{len(got)} labels in {labels.groupby(['camera', 'frame']).ngroups} camera frames")
