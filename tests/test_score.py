"""`triaxtrack score` catches what it must."""

from __future__ import annotations

import json

import pytest

from triaxtrack.cli import main
from triaxtrack.optics import read_cameras
from triaxtrack.score import ScoreTolerances, score


def test_truth_scores_perfectly_and_errors_fail(small_test, tmp_path):
    own = score(small_test / "truth", small_test)
    # 3 cameras around the cell: no membrane dot is seen by 3 of them, so this one cannot pass
    rays = own.metric == "membrane_3_rays"
    assert own[~rays].passed.all() and rays.any() and (own[rays].value < 0.9).all()
    assert set(own.metric) >= {"membrane_rms_error", "pedestal_rms_error", "cell_wall_rms_error"}
    cams = json.loads((small_test / "truth" / "cameras.json").read_text())
    cams["cameras"]["cam02"]["K"][0][0] *= 1.003  # 0.3 % focal error
    cams["cameras"]["cam03"]["t"][2] += 0.8  # 0.8 mm shift
    (tmp_path / "cameras.json").write_text(json.dumps(cams))
    df = score(tmp_path, small_test, ScoreTolerances())
    failed = set(zip(df[~df.passed].metric, df[~df.passed].item, strict=True))
    assert failed == {("focal_rel_error", "cam02"), ("camera_center_error", "cam03")}
    assert main(["score", str(tmp_path), str(small_test)]) == 1
    assert main(["score", str(small_test / "truth"), str(small_test)]) == 1  # membrane_3_rays


def test_bad_input_names_the_file(tmp_path):
    (tmp_path / "cameras.json").write_text("{not json")
    with pytest.raises(ValueError, match="cameras.json"):
        read_cameras(tmp_path / "cameras.json")
