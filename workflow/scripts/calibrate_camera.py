"""Rule calibrate_camera: K and distortion of one camera from its checkerboard images."""

from triaxtrack.calibrate import run_calibrate_camera
from triaxtrack.logs import log_to

log = log_to(snakemake.log[0])

p = snakemake.params
run_calibrate_camera(
    camera=snakemake.wildcards.camera, folder=p.folder, kit=snakemake.input.kit,
    calibration=snakemake.output.calibration,
    calibration_cfg=p.calibration,
)  # fmt: skip
