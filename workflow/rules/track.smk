# Tracking and per-timestep 3-D (paper sections 2.4 and 3.3): every labelled target followed
# through each camera's chunk, then triangulated at every processed frame, chunk by chunk.


rule track_targets:
    """Follow the targets labelled at the chunk's first frame through the chunk (decoded as a
    stream), and on to the first frame of the next chunk for the handover check."""
    input:
        video=get_camera_video,
        frames=R.frames,
        labels=R.chunk_labels,
        test_yaml=get_test_yaml,
        kit=get_test_kit,
    output:
        tracks=R.tracks,
        handover=R.handover,
    log:
        "logs/{test}/track_targets/{camera}/{chunk}.log",
    benchmark:
        "benchmarks/{test}/track_targets/{camera}/{chunk}.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=1500,
        runtime=30,
    params:
        chunk=get_chunk_frames,
        tracking=config["tracking"],
    script:
        "../scripts/track_targets.py"


rule measure_codec_lag:
    """Measure how one camera's P frames depart from its keyframes, at every keyframe of the
    test from the tracks on both sides of it (whichever chunks they are in)."""
    input:
        tracks=get_camera_tracks,
        video=get_camera_video,
        frames=R.frames,
        kit=get_test_kit,
    output:
        lags=R.codec_lag,
    log:
        "logs/{test}/measure_codec_lag/{camera}.log",
    benchmark:
        "benchmarks/{test}/measure_codec_lag/{camera}.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=20,
    script:
        "../scripts/measure_codec_lag.py"


rule triangulate_chunk:
    """Triangulate every tracked target in the water at every processed frame of one chunk
    (cameras and cell of the first frame; P frames corrected by each camera's codec lag), and
    check that no camera moved."""
    input:
        tracks=get_chunk_tracks,
        lags=get_codec_lags,
        cameras=R.cameras,
        reference=R.first_quality,
        points=R.first_points,
        kit=get_test_kit,
        test_yaml=get_test_yaml,
    output:
        points=R.chunk_points,
        residuals=R.chunk_residuals,
        motion=R.chunk_motion,
    log:
        "logs/{test}/triangulate_chunk/{chunk}.log",
    benchmark:
        "benchmarks/{test}/triangulate_chunk/{chunk}.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=60,
    params:
        reconstruction=config["reconstruction"],
        tracking=config["tracking"],
    script:
        "../scripts/triangulate_chunk.py"


rule collect_timesteps:
    """All chunks in one test: points.parquet, observations.parquet, tracking.parquet and
    quality.json (first-frame reconstruction, per-frame counts, camera motion, handovers).
    """
    input:
        points=get_timestep_points,
        residuals=get_timestep_residuals,
        motion=get_timestep_motion,
        tracks=get_all_tracks,
        handovers=get_all_handovers,
        labels=R.labels,
        reference=R.first_quality,
        kit=get_test_kit,
    output:
        points=R.points,
        observations=R.observations,
        tracking=R.tracking,
        quality=R.quality,
    log:
        "logs/{test}/collect_timesteps.log",
    benchmark:
        "benchmarks/{test}/collect_timesteps.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=20,
    params:
        handover_px=config["tracking"]["handover_px"],
        cameras_left_out=get_cameras_left_out,
    script:
        "../scripts/collect_timesteps.py"
