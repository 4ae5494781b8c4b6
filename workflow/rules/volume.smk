# Mesh, volume and strain per processed frame (paper section 3.3): the membrane grid closed by
# the pedestal faces, the soil volume inside the membrane, axial, radial, volumetric and local
# strains.


rule measure_volume:
    """Close the specimen's surface at every processed frame, measure its soil volume and
    strains, export the meshes of a few chosen frames as PLY."""
    input:
        points=R.points,
        observations=R.observations,
        kit=get_test_kit,
    output:
        volume=R.volume,
        strains=R.strains,
        meshes=directory(R.mesh),
    log:
        "logs/{test}/measure_volume.log",
    benchmark:
        "benchmarks/{test}/measure_volume.tsv"
    conda:
        "../envs/triaxtrack.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        volume=config["volume"],
    script:
        "../scripts/measure_volume.py"
