# Stress and strain from the load-frame log on the measured specimen (issue 18), the exports
# (CSV tables, the membrane's ParaView series) and the 3-D viewer.


rule stress_strain:
    """Synchronise the load-frame log's clock with the measured top cap, then q on the measured
    mean area, mid-height and smallest sections, the lab's standard q, p, p', moduli, with
    their uncertainties, per processed frame."""
    input:
        volume=R.volume,
        points=R.points,
        kit=get_test_kit,
        test_yaml=get_test_yaml,
        load_frame=get_load_frame_log,
    output:
        stress=R.stress_strain,
        clock=R.clock,
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
        table=R.table,
    output:
        csv=R.table_csv,
    log:
        "logs/{test}/export_csv/{table}.log",
    benchmark:
        "benchmarks/{test}/export_csv/{table}.tsv"
    wildcard_constraints:
        table="|".join(CSV_TABLES),
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
        volume=R.volume,
        points=R.points,
        kit=get_test_kit,
    output:
        series=directory(R.paraview),
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
        volume=R.volume,
        points=R.points,
        kit=get_test_kit,
    output:
        html=report(
            R.viewer,
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
        stress=R.stress_strain,
    output:
        q_strain=report(
            R.q_strain_figure,
            caption="../report/q_strain.rst",
            category="{test}",
            subcategory="7 stress and strain",
        ),
        volumetric=report(
            R.volumetric_strain_figure,
            caption="../report/volumetric_strain.rst",
            category="{test}",
            subcategory="7 stress and strain",
        ),
        modulus=report(
            R.modulus_figure,
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
