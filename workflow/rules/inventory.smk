# Recorded tests: describe what each camera's video holds before any per-frame work.


rule probe_video:
    """Probe one recorded video (frames, fps, size, codec) without decoding it."""
    input:
        video=get_recorded_video,
    output:
        probe=R.probe,
    log:
        "logs/{test}/probe_video/{camera}.log",
    benchmark:
        "benchmarks/{test}/probe_video/{camera}.tsv"
    wildcard_constraints:
        test=RECORDED_TEST,
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    script:
        "../scripts/probe_video.py"


rule inventory:
    """List the cameras with their frames, fps and size; flag cameras that disagree."""
    input:
        test_yaml=get_recorded_test_yaml,
        probes=get_inventory_probes,
    output:
        inventory=R.inventory,
    log:
        "logs/{test}/inventory/inventory.log",
    benchmark:
        "benchmarks/{test}/inventory/inventory.tsv"
    wildcard_constraints:
        test=RECORDED_TEST,
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    params:
        test=get_recorded_spec,
    script:
        "../scripts/inventory.py"
