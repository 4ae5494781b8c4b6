"""Rule stress_figures: q, volumetric strain and Young's modulus against axial strain."""

from triaxtrack.logs import log_to
from triaxtrack.report import save_figure
from triaxtrack.report.stress import modulus_figure, q_strain_figure, volumetric_figure
from triaxtrack.tables import STRESS_STRAIN, read_table

log_to(snakemake.log[0])

stress = read_table(snakemake.input.stress, STRESS_STRAIN)
save_figure(q_strain_figure(stress), snakemake.output.q_strain)
save_figure(volumetric_figure(stress), snakemake.output.volumetric)
save_figure(modulus_figure(stress), snakemake.output.modulus)
