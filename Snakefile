"""triaxtrack: continuous 3-D deformation of triaxial soil specimens from multi-camera video.

    snakemake --cores 2                          # the tests of config/config.yaml (default: demo)
    snakemake --cores 2 --config test=PATH       # one recorded test folder
    snakemake --profile profiles/slurm           # on a SLURM cluster

Outputs under results/<test>/, the kit under results/kit/; logs/ and benchmarks/ per job.
"""

from snakemake.utils import min_version

min_version("8.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/kit.smk"
include: "workflow/rules/simulate.smk"
include: "workflow/rules/calibrate.smk"
include: "workflow/rules/frames.smk"
include: "workflow/rules/identify.smk"
include: "workflow/rules/reconstruct.smk"
include: "workflow/rules/track.smk"
include: "workflow/rules/volume.smk"
include: "workflow/rules/report.smk"
include: "workflow/rules/stress.smk"
include: "workflow/rules/inventory.smk"


localrules:
    all,


rule all:
    default_target: True
    input:
        get_final_outputs(),


onerror:
    # Snakemake itself says only "Error in rule ... (check log file(s))": print the reason at the
    # end of each failed job's log (the exception message), read from Snakemake's own log.
    import sys
    from triaxtrack.errors import format_failed_jobs

    message = format_failed_jobs(log)
    if message:
        print(message, file=sys.stderr)
