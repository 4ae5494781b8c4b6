"""Rule export_csv: a result table as CSV beside its Parquet file."""

from triaxtrack.export import write_csv
from triaxtrack.logs import log_to
from triaxtrack.tables import STRESS_STRAIN, VOLUME_RESULT, read_table

log_to(snakemake.log[0])

schema = {"volume": VOLUME_RESULT, "stress_strain": STRESS_STRAIN}[snakemake.wildcards.table]
write_csv(read_table(snakemake.input.table, schema), snakemake.output.csv)
