"""Rule calibrate_camera: K and distortion of one camera from its checkerboard images."""

import json

from triaxtrack import __version__
from triaxtrack.calibrate import CalibrationConfig, calibrate_camera, format_calibration
from triaxtrack.logs import log_to

log = log_to(snakemake.log[0])

result = calibrate_camera(
    snakemake.wildcards.camera,
    snakemake.params.folder,
    snakemake.input.kit,
    CalibrationConfig.from_dict(snakemake.params.calibration),
)
result["triaxtrack_version"] = __version__
with open(snakemake.output.calibration, "w") as f:
    json.dump(result, f, indent=2)
print(format_calibration(result))
