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
        labels="results/{test}/labels.parquet",
        kit=get_test_kit,
    output:
        cell="results/{test}/reconstruction/cell.json",
        points="results/{test}/reconstruction/cell_points.parquet",
        residuals="results/{test}/reconstruction/air_residuals.parquet",
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
        cell="results/{test}/reconstruction/cell.json",
        cell_points="results/{test}/reconstruction/cell_points.parquet",
        air_residuals="results/{test}/reconstruction/air_residuals.parquet",
        labels="results/{test}/labels.parquet",
        kit=get_test_kit,
        test_yaml=get_test_yaml,
    output:
        cameras="results/{test}/cameras.json",
        points="results/{test}/reconstruction/points.parquet",
        observations="results/{test}/reconstruction/observations.parquet",
        quality="results/{test}/reconstruction/quality.json",
        residuals="results/{test}/reconstruction/residuals.parquet",
        picture="results/{test}/reconstruction/reconstruction.png",
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
