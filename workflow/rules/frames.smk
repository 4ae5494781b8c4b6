# Frame maps: which frame of each camera's video is test frame k (start offsets, dropped frames).


rule frame_map:
    """Map every test frame to one camera's video frame (or to why it has none)."""
    input:
        video=get_camera_video,
        test_yaml=get_test_yaml,
        frame_count_video=get_frame_count_video,
        videos_checked=get_videos_checked,
    output:
        frames=R.frames,
    log:
        "logs/{test}/frame_map/{camera}.log",
    benchmark:
        "benchmarks/{test}/frame_map/{camera}.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    script:
        "../scripts/frame_map.py"
