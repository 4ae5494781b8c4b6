"""Identification of one frame of every camera of a simulated test, scored against its truth.

Labels frame FRAME (default 0) of each camera's video with the camera's TRUE intrinsics (so no
calibration or workflow run is needed) and prints ``triaxtrack.score``'s identification rows per
camera, then one line: coverage min / median, wrong IDs, worst cell-wall centroid p95 (pixels).
A quick check of detection and identification on many renders:

    triaxtrack simulate /tmp/t --frames 2 --chunk-size 2 --preset nvr --seed 3
    FRAME=1 .venv/bin/python bench/identify_frame.py /tmp/t
"""

import os
import sys
from pathlib import Path

import av
import numpy as np
import pandas as pd

from triaxtrack.identify import label_frame
from triaxtrack.kit import ct_codes, load_kit_design, target_table
from triaxtrack.layout import TEST_FOLDER
from triaxtrack.optics import Camera
from triaxtrack.score import ScoreTolerances, score_identification
from triaxtrack.testfolder import read_cameras_doc


def main(test_dir: Path, frame: int) -> pd.DataFrame:
    cams = read_cameras_doc(test_dir / TEST_FOLDER.truth.cameras)
    design = load_kit_design(test_dir / TEST_FOLDER.kit)
    codes = ct_codes(design, target_table(design))
    labels = []
    for name, cj in sorted(cams.items()):
        cam = Camera.from_json(name, {**cj, "R": np.eye(3), "t": np.zeros(3)})
        with av.open(str(test_dir / TEST_FOLDER.video.format(camera=name))) as c:
            img = next(f for i, f in enumerate(c.decode(video=0)) if i == frame).to_ndarray(format="gray")
        labels.append(label_frame(img, cam, design, codes).assign(camera=name, frame=frame))
    lab = pd.concat(labels, ignore_index=True)
    posed = {n: Camera.from_json(n, cj) for n, cj in cams.items()}
    return score_identification(
        lab,
        pd.read_parquet(test_dir / TEST_FOLDER.truth.observations),
        pd.read_parquet(test_dir / TEST_FOLDER.truth.points),
        posed,
        target_table(design),
        design,
        ScoreTolerances(),
    )


if __name__ == "__main__":
    test = Path(sys.argv[1])
    scores = main(test, int(os.environ.get("FRAME", 0)))
    w = scores.pivot_table(index="item", columns="metric", values="value")
    print(w.round(3).to_string())
    print(
        f"{test.name}: coverage min {w.coverage.min():.3f} median {w.coverage.median():.3f} "
        f"(within 60 deg: min {w.coverage_frontal.min():.3f}) | "
        f"wrong {int(w.wrong_ids.sum())} | cell p95 worst {w.filter(like='p95').max().max():.3f}"
    )
