"""Rule export_csv: a result table as CSV beside its Parquet file."""

from triaxtrack.export import run_export_csv
from triaxtrack.logs import log_to

log_to(snakemake.log[0])

run_export_csv(table=snakemake.input.table, csv=snakemake.output.csv, name=snakemake.wildcards.table)
