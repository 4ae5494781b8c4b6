"""Rule simulate_scene: lay out cameras and specimen; write test.yaml and truth/ of the test."""

from pathlib import Path

from triaxtrack.logs import log_to
from triaxtrack.simulate import SimulationConfig, make_scene

log = log_to(snakemake.log[0])

make_scene(
    SimulationConfig.from_dict(snakemake.params.sim),
    snakemake.input.kit,
    Path(snakemake.output.test_yaml).parent,
    snakemake.params.name,
)
