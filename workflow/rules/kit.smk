rule make_kit:
    """Export the target kit (sheets, target tables, textures) from its design."""
    input:
        design=config["kit_design"],
    output:
        kit=directory(KIT_DIR),
    log:
        "logs/kit/make_kit.log",
    benchmark:
        "benchmarks/kit/make_kit.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=15,
    script:
        "../scripts/make_kit.py"
