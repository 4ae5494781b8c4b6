# Simulated tests: write a synthetic test folder results/{test}/simulated (test-folder.md),
# rendering the videos chunk by chunk and joining them per camera.


rule simulate_scene:
    """Lay out the cameras and the deforming specimen; write test.yaml, kit/ (a copy of
    results/kit) and the static truth."""
    input:
        kit=KIT_DIR,
    output:
        test_yaml=R.simulated.test_yaml,
        cameras=R.simulated.truth.cameras,
        volume=R.simulated.truth.volume,
        scene=R.simulated.truth.scene,
        kit=directory(R.simulated.kit),
    log:
        "logs/{test}/simulate_scene/simulate_scene.log",
    benchmark:
        "benchmarks/{test}/simulate_scene/simulate_scene.tsv"
    wildcard_constraints:
        test=SIMULATED_TEST,
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=15,
    params:
        sim=get_sim_config,
        name="{test}",
    script:
        "../scripts/simulate_scene.py"


rule render_video_chunk:
    """Render one video segment of one camera and its exact observations: chunk_size frames
    rounded up to whole GOPs, starting on the recorder's keyframe grid (gop_s), so that the
    joined video has keyframes there only."""
    input:
        kit=R.simulated.kit,
        test_yaml=R.simulated.test_yaml,
        cameras=R.simulated.truth.cameras,
        scene=R.simulated.truth.scene,
    output:
        video=temp(R.sim_chunk_video),
        observations=R.sim_chunk_observations,
    log:
        "logs/{test}/render_video_chunk/{camera}/{segment}.log",
    benchmark:
        "benchmarks/{test}/render_video_chunk/{camera}/{segment}.tsv"
    wildcard_constraints:
        test=SIMULATED_TEST,
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    params:
        frames=get_segment_frames,
    script:
        "../scripts/render_video_chunk.py"


rule join_camera_video:
    """Join one camera's chunk videos into videos/{camera}.mp4 (stream copy)."""
    input:
        segments=get_camera_chunk_videos,
    output:
        video=R.simulated.video,
    log:
        "logs/{test}/join_camera_video/{camera}.log",
    benchmark:
        "benchmarks/{test}/join_camera_video/{camera}.tsv"
    wildcard_constraints:
        test=SIMULATED_TEST,
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    script:
        "../scripts/join_camera_video.py"


rule render_calibration:
    """Render one camera's calibration-board images, and their board poses into truth/."""
    input:
        kit=R.simulated.kit,
        test_yaml=R.simulated.test_yaml,
        cameras=R.simulated.truth.cameras,
        scene=R.simulated.truth.scene,
    output:
        calibration=directory(R.simulated.calibration_images),
        board_poses=R.simulated.truth.board_poses,
    log:
        "logs/{test}/render_calibration/{camera}.log",
    benchmark:
        "benchmarks/{test}/render_calibration/{camera}.tsv"
    wildcard_constraints:
        test=SIMULATED_TEST,
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=20,
    script:
        "../scripts/render_calibration.py"


rule simulate_truth:
    """Gather the chunk observations into truth/points.parquet and truth/observations.parquet."""
    input:
        kit=R.simulated.kit,
        test_yaml=R.simulated.test_yaml,
        cameras=R.simulated.truth.cameras,
        scene=R.simulated.truth.scene,
        chunks=get_chunk_observations,
    output:
        points=R.simulated.truth.points,
        observations=R.simulated.truth.observations,
    log:
        "logs/{test}/simulate_truth/simulate_truth.log",
    benchmark:
        "benchmarks/{test}/simulate_truth/simulate_truth.tsv"
    wildcard_constraints:
        test=SIMULATED_TEST,
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=15,
    script:
        "../scripts/simulate_truth.py"


rule check_simulation:
    """Check the finished synthetic test folder against its truth; write a JSON report."""
    input:
        kit=R.simulated.kit,
        test_yaml=R.simulated.test_yaml,
        cameras=R.simulated.truth.cameras,
        volume=R.simulated.truth.volume,
        scene=R.simulated.truth.scene,
        points=R.simulated.truth.points,
        observations=R.simulated.truth.observations,
        videos=get_sim_videos,
        calibration=get_sim_calibrations,
        board_poses=get_sim_board_poses,
    output:
        json=R.simulation_check,
    log:
        "logs/{test}/check_simulation/check_simulation.log",
    benchmark:
        "benchmarks/{test}/check_simulation/check_simulation.tsv"
    wildcard_constraints:
        test=SIMULATED_TEST,
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30,
    script:
        "../scripts/check_simulation.py"


rule simulate_load_frame:
    """Write the simulated load-frame log (loadframe.csv) and its truth (clock offset, stress and
    strain per frame)."""
    input:
        kit=R.simulated.kit,
        test_yaml=R.simulated.test_yaml,
        scene=R.simulated.truth.scene,
    output:
        log=R.simulated.load_frame_log,
        truth=R.simulated.truth.load_frame,
        stress=R.simulated.truth.stress_strain,
    log:
        "logs/{test}/simulate_load_frame/simulate_load_frame.log",
    benchmark:
        "benchmarks/{test}/simulate_load_frame/simulate_load_frame.tsv"
    wildcard_constraints:
        test=SIMULATED_TEST,
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        load_frame=get_load_frame_settings,
    script:
        "../scripts/simulate_load_frame.py"
