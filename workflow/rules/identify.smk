# Identification (paper section 2.3): every target in the first frame of each camera's chunk.


rule identify_targets:
    """Detect the dots and CTs in the first recorded frame of one camera's chunk and label
    them from the kit design; a PNG of the frame and one of the labels for a person to check.
    """
    input:
        video=get_camera_video,
        frames=R.frames,
        calibration=R.calibration,
        kit=get_test_kit,
    output:
        labels=R.chunk_labels,
        frame=R.chunk_frame,
        overlay=R.chunk_overlay,
    log:
        "logs/{test}/identify_targets/{camera}/{chunk}.log",
    benchmark:
        "benchmarks/{test}/identify_targets/{camera}/{chunk}.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=1500,
        runtime=10,
    params:
        chunk=get_chunk_frames,
    script:
        "../scripts/identify_targets.py"


rule collect_labels:
    """All cameras' chunk labels of a test in one table."""
    input:
        labels=get_chunk_labels,
    output:
        labels=R.labels,
    log:
        "logs/{test}/collect_labels.log",
    benchmark:
        "benchmarks/{test}/collect_labels.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=5,
    script:
        "../scripts/collect_labels.py"
