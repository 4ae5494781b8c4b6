"""Rule stress_figures: q, volumetric strain and Young's modulus against axial strain."""

from triaxtrack.logs import log_to
from triaxtrack.report.stress import run_stress_figures

log_to(snakemake.log[0])

o = snakemake.output
run_stress_figures(
    stress=snakemake.input.stress,
    q_strain_png=o.q_strain, volumetric_png=o.volumetric, modulus_png=o.modulus,
)  # fmt: skip
