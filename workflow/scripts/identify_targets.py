"""Rule identify_targets: detect and label every target in the first frame of one camera's chunk."""

import cv2

from triaxtrack.calibrate import calibrated_camera, read_calibration
from triaxtrack.identify import draw_labels, label_chunk_start
from triaxtrack.kit import ct_codes, load_kit_design, target_table
from triaxtrack.logs import log_to
from triaxtrack.tables import FRAME_MAP, LABELS, read_table, write_table

log_to(snakemake.log[0])

camera = calibrated_camera(read_calibration(snakemake.input.calibration))
design = load_kit_design(snakemake.input.kit)
codes = ct_codes(design, target_table(design))
fmap = read_table(snakemake.input.frames, FRAME_MAP)
chunk = snakemake.params.chunk
frame, image, labels = label_chunk_start(
    snakemake.input.video, fmap, camera, design, codes, chunk["start"], chunk["stop"]
)
write_table(labels, snakemake.output.labels, LABELS)
if image is None:
    raise ValueError(
        f"{snakemake.input.video}: camera {camera.name} recorded none of test frames "
        f"{chunk['start']}..{chunk['stop'] - 1} (see {snakemake.input.frames})"
    )
cv2.imwrite(snakemake.output.frame, image)
cv2.imwrite(snakemake.output.overlay, draw_labels(image, labels))
got = labels[labels.id > 0]
print(
    f"{camera.name} frame {frame}: {len(got)} targets labelled ({(got.kind == 'coded').sum()} CTs), "
    f"{(labels.id < 0).sum()} detections left unlabelled:"
)
print(labels[labels.id < 0].reason.value_counts().to_string())
