"""Rule stress_strain: the load-frame log's clock, then stress and strain per processed frame."""

import json
from pathlib import Path

import yaml

from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.stress import StressConfig, measure_stress
from triaxtrack.tables import POINTS, STRESS_STRAIN, VOLUME_RESULT, read_table, write_table

log_to(snakemake.log[0])

design = load_kit_design(snakemake.input.kit)
test_yaml = yaml.safe_load(Path(snakemake.input.test_yaml).read_text())
stress, clock = measure_stress(
    Path(snakemake.input.test_yaml).parent, test_yaml, read_table(snakemake.input.volume, VOLUME_RESULT),
    read_table(snakemake.input.points, POINTS), target_table(design), design,
    StressConfig.from_dict(snakemake.params.stress), snakemake.params.volume,
)  # fmt: skip
write_table(stress, snakemake.output.stress, STRESS_STRAIN)
Path(snakemake.output.clock).write_text(json.dumps(clock, indent=2))
print(json.dumps(clock, indent=2))
if clock["warning"]:
    print(f"WARNING: {clock['warning']}")
