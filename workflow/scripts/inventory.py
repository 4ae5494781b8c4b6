"""Rule inventory: what each camera's video of a recorded test holds; flag cameras that disagree."""

from triaxtrack.inventory import run_inventory
from triaxtrack.logs import log_to

log = log_to(snakemake.log[0])

run_inventory(
    probes=snakemake.input.probes, inventory=snakemake.output.inventory,
    test=snakemake.params.test, name=snakemake.wildcards.test,
)  # fmt: skip
