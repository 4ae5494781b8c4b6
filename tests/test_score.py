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
    per_frame = rays & own.item.str.contains("@")
    assert own[~rays].passed.all() and per_frame.any() and (own[per_frame].value < 0.9).all()
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


def test_tracking_and_volume_errors_fail(small_test, tmp_path):
    """A swapped ID in one frame, a volume 0.3 % off at one frame and a dot lost at the end fail."""
    import pandas as pd

    from triaxtrack.kit import load_kit_design, target_table
    from triaxtrack.score import score_kept, score_tracking, score_volume

    truth = small_test / "truth"
    tol = ScoreTolerances()
    obs = pd.read_parquet(truth / "observations.parquet")
    assert score_tracking(obs, obs, tol).set_index("metric").loc["id_swaps", "value"] == 0
    swapped = obs.copy()
    a, b = swapped.index[(swapped.camera == "cam01") & (swapped.frame == 2)][:2]
    swapped.loc[[a, b], ["u_px", "v_px"]] = swapped.loc[[b, a], ["u_px", "v_px"]].to_numpy()
    rows = score_tracking(swapped, obs, tol).set_index("metric")
    assert rows.loc["id_swaps", "value"] == 2 and not rows.loc["id_swaps", "passed"]

    vol = pd.read_parquet(truth / "volume.parquet")
    assert score_volume(vol, vol, tol).passed.all()
    off = vol.assign(volume_mm3=vol.volume_mm3 * [1, 1, 1.003, 1])
    rows = score_volume(off, vol, tol)
    failed = set(rows[~rows.passed].metric)
    assert failed == {"volume_error", "volume_change_error"}
    by_item = rows.set_index(["metric", "item"])["value"]
    assert by_item[("volume_error", "worst@2")] == pytest.approx(0.003)
    assert by_item[("volume_error", "failed frames")] == 1

    points = pd.read_parquet(truth / "points.parquet")
    table = target_table(load_kit_design(small_test / "kit"))
    assert score_kept(points, points, table, tol).passed.all()
    membrane = table.loc[table.surface == "membrane", "id"]
    seen = points[(points.frame == 0) & points.id.isin(membrane) & (points.n_rays >= 2)].id
    lost = points[~((points.frame == 3) & points.id.isin(seen.iloc[: len(seen) // 10]))]
    rows = score_kept(lost, points, table, tol)
    assert not rows.passed.any() and rows.value.iloc[0] == pytest.approx(1 - (len(seen) // 10) / len(seen))
