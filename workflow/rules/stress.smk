# Stress and strain from the load-frame log on the measured specimen (issue 18), the exports
# (CSV tables, the membrane's ParaView series) and the 3-D viewer.


rule stress_strain:
    """Synchronise the load-frame log's clock with the measured top cap, then q on the measured
    mean area, mid-height and smallest sections, the lab's standard q, p, p', moduli, with
    their uncertainties, per processed frame."""
    input:
        volume="results/{test}/volume.parquet",
        points="results/{test}/points.parquet",
        kit=get_test_kit,
        test_yaml=get_test_yaml,
        load_frame=get_load_frame_log,
    output:
        stress="results/{test}/stress_strain.parquet",
        clock="results/{test}/clock.json",
    log:
        "logs/{test}/stress_strain.log",
    benchmark:
        "benchmarks/{test}/stress_strain.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        stress=config["stress"],
        volume=config["volume"],
    script:
        "../scripts/stress_strain.py"


rule export_csv:
    """A result table as CSV beside its Parquet file (volume, stress_strain)."""
    input:
        table="results/{test}/{table}.parquet",
    output:
        csv="results/{test}/{table}.csv",
    log:
        "logs/{test}/export_csv/{table}.log",
    benchmark:
        "benchmarks/{test}/export_csv/{table}.tsv"
    wildcard_constraints:
        table="volume|stress_strain",
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    script:
        "../scripts/export_csv.py"


rule export_paraview:
    """The membrane surface of every processed frame as a ParaView time series (VTU + PVD) with
    displacement and strain as point data."""
    input:
        volume="results/{test}/volume.parquet",
        points="results/{test}/points.parquet",
        kit=get_test_kit,
    output:
        series=directory("results/{test}/paraview"),
    log:
        "logs/{test}/export_paraview.log",
    benchmark:
        "benchmarks/{test}/export_paraview.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        volume=config["volume"],
    script:
        "../scripts/export_paraview.py"


rule specimen_viewer:
    """One self-contained offline HTML page: the membrane surface coloured by a strain component,
    with a time slider."""
    input:
        volume="results/{test}/volume.parquet",
        points="results/{test}/points.parquet",
        kit=get_test_kit,
    output:
        html=report(
            "results/{test}/report/viewer.html",
            caption="../report/viewer.rst",
            category="{test}",
            subcategory="3 specimen",
        ),
    log:
        "logs/{test}/specimen_viewer.log",
    benchmark:
        "benchmarks/{test}/specimen_viewer.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        report=config["report"],
        volume=config["volume"],
        name="{test}",
    script:
        "../scripts/specimen_viewer.py"


rule stress_figures:
    """Deviator stress, volumetric strain and Young's modulus against axial strain."""
    input:
        stress="results/{test}/stress_strain.parquet",
    output:
        q_strain=report(
            "results/{test}/report/q_strain.png",
            caption="../report/q_strain.rst",
            category="{test}",
            subcategory="7 stress and strain",
        ),
        volumetric=report(
            "results/{test}/report/volumetric_strain.png",
            caption="../report/volumetric_strain.rst",
            category="{test}",
            subcategory="7 stress and strain",
        ),
        modulus=report(
            "results/{test}/report/modulus.png",
            caption="../report/modulus.rst",
            category="{test}",
            subcategory="7 stress and strain",
        ),
    log:
        "logs/{test}/stress_figures.log",
    benchmark:
        "benchmarks/{test}/stress_figures.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    script:
        "../scripts/stress_figures.py"
