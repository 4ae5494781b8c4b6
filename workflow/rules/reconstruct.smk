# 3-D reconstruction at the first frame (paper sections 2.3, 3.1-3.2): the cameras and the cell
# by structure from motion in air, then the specimen by ray tracing through the cell wall.


rule reconstruct_cell:
    """Pose every camera by PnP on its cell-wall targets, bundle-adjust cameras and targets with
    pycolmap, scale to the design and fit the cell's outer cylinder (its axis becomes z); pose the
    cameras that see too few wall targets through the wall from the pedestal CTs and membrane
    dots (against the nominal cell when none sees the wall); leave out, with the reason, the
    cameras that cannot be posed.
    """
    input:
        calibrations=get_calibrations,
        labels=R.labels,
        kit=get_test_kit,
    output:
        cell=R.cell,
        points=R.cell_points,
        residuals=R.air_residuals,
    log:
        "logs/{test}/reconstruct_cell.log",
    benchmark:
        "benchmarks/{test}/reconstruct_cell.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        reconstruction=config["reconstruction"],
        cell=config["cell"],
    script:
        "../scripts/reconstruct_cell.py"


rule trace_specimen:
    """Triangulate the pedestal and membrane targets of the first frame through the cell wall
    (Snell's law at both walls), optionally refine the cell, fix the cell frame from the bottom
    pedestal's CTs; write cameras.json, the first-frame points, quality.json and a picture.
    """
    input:
        cell=R.cell,
        cell_points=R.cell_points,
        air_residuals=R.air_residuals,
        labels=R.labels,
        kit=get_test_kit,
        test_yaml=get_test_yaml,
    output:
        cameras=R.cameras,
        points=R.first_points,
        observations=R.first_observations,
        quality=R.first_quality,
        residuals=R.first_residuals,
        picture=R.reconstruction_picture,
    log:
        "logs/{test}/trace_specimen.log",
    benchmark:
        "benchmarks/{test}/trace_specimen.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=20,
    params:
        reconstruction=config["reconstruction"],
        cell=config["cell"],
    script:
        "../scripts/trace_specimen.py"
