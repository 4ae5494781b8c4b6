"""Rule stress_strain: the load-frame log's clock, then stress and strain per processed frame."""

from triaxtrack.logs import log_to
from triaxtrack.stress import run_stress_strain

log_to(snakemake.log[0])

i, o, p = snakemake.input, snakemake.output, snakemake.params
run_stress_strain(
    volume=i.volume, points=i.points, kit=i.kit, test_yaml=i.test_yaml,
    stress=o.stress, clock=o.clock,
    stress_cfg=p.stress, volume_cfg=p.volume,
)  # fmt: skip
