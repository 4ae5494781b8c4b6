"""Rule inventory: what each camera's video of a recorded test holds; flag cameras that disagree."""

import json

from triaxtrack import __version__
from triaxtrack.inventory import summarize_probes
from triaxtrack.logs import log_to

log = log_to(snakemake.log[0])
probes = []
for path in snakemake.input.probes:
    with open(path) as f:
        probes.append(json.load(f))
inventory = summarize_probes(snakemake.params.test, probes, snakemake.wildcards.test)
inventory["triaxtrack_version"] = __version__
with open(snakemake.output.inventory, "w") as f:
    json.dump(inventory, f, indent=2)
for c in inventory["cameras"]:
    print(f"{c['camera']}: {c['frames']} frames, {c['fps']:.3f} fps, {c['flags'] or 'ok'}")
