# Camera calibration: intrinsics and distortion of each camera from its checkerboard images.


rule calibrate_camera:
    """Calibrate one camera (K, distortion) from its board images; reject outlier images."""
    input:
        images=get_calibration_images,
        kit=get_test_kit,
        videos_checked=get_videos_checked,
    output:
        calibration=R.calibration,
    log:
        "logs/{test}/calibrate_camera/{camera}.log",
    benchmark:
        "benchmarks/{test}/calibrate_camera/{camera}.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=1500,
        runtime=15,
    params:
        folder=get_calibration_folder,
        calibration=config["calibration"],
    script:
        "../scripts/calibrate_camera.py"
