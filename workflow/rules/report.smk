# Figures and a movie for Snakemake's HTML report: `snakemake --report report.html` after a run.
#
# Wire-up in the Snakefile (after `configfile:`), the global report page and this file:
#
#     report: "workflow/report/workflow.rst"
#     include: "workflow/rules/report.smk"
#
# Config section config["report"], handed whole to the package (triaxtrack.report.ReportConfig):
# strain_map_frames, movie_fps, movie_max_frames, movie_colour_by, movie_magnify,
# movie_height_px (see config/README.md).
#
# Snakemake's report shows PNG, SVG, JPEG inline and HTML and PDF in a frame; any other file,
# an MP4 included, is only a download button. So specimen_movie also writes specimen.html, a
# page that plays the embedded MP4: it is what plays inline in the report.


rule report_figures:
    """Volume and strains against time, local strain maps at a few times, reprojection error
    per camera, tracking losses and footage quality per camera of one test, as PNG figures for
    the report (matplotlib); the membrane grid (rows, columns, IDs) is the test's kit.
    """
    input:
        volume=R.volume,
        strains=R.strains,
        quality=R.quality,
        tracking=R.tracking,
        labels=R.labels,
        kit=get_test_kit,
    output:
        volume_strain=report(
            R.volume_strain_figure,
            caption="../report/volume_strain.rst",
            category="{test}",
            subcategory="1 volume and strain",
        ),
        strain_maps=report(
            R.strain_maps_figure,
            caption="../report/strain_maps.rst",
            category="{test}",
            subcategory="2 strain maps",
        ),
        reprojection=report(
            R.reprojection_figure,
            caption="../report/reprojection.rst",
            category="{test}",
            subcategory="4 reconstruction quality",
        ),
        tracking=report(
            R.tracking_figure,
            caption="../report/tracking.rst",
            category="{test}",
            subcategory="5 tracking",
        ),
        cameras=report(
            R.cameras_figure,
            caption="../report/cameras.rst",
            category="{test}",
            subcategory="6 footage per camera",
        ),
    log:
        "logs/{test}/report_figures.log",
    benchmark:
        "benchmarks/{test}/report_figures.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=4000,  # tracking.parquet: one row per camera, target and frame
        runtime=20,
    params:
        report=config["report"],
    script:
        "../scripts/report_figures.py"


rule specimen_movie:
    """The deforming specimen seen from two opposite sides, coloured by radial displacement or
    local strain, as an H.264 MP4 and an HTML page that plays it.
    """
    input:
        points=R.points,
        strains=R.strains,
        kit=get_test_kit,
    output:
        movie=report(
            R.specimen_movie,
            caption="../report/specimen_movie.rst",
            category="{test}",
            subcategory="3 movie",
        ),
        player=report(
            R.specimen_player,
            caption="../report/specimen_player.rst",
            category="{test}",
            subcategory="3 movie",
        ),
    log:
        "logs/{test}/specimen_movie.log",
    benchmark:
        "benchmarks/{test}/specimen_movie.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        report=config["report"],
    script:
        "../scripts/specimen_movie.py"
