"""Rule make_kit: export the target kit from its design."""

from triaxtrack.kit import export_kit, load_design
from triaxtrack.logs import log_to

log = log_to(snakemake.log[0])

export_kit(load_design(snakemake.input.design), snakemake.output.kit)
