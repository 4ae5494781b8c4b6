"""`triaxtrack score` catches what it must."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from triaxtrack.cli import main
from triaxtrack.optics import read_cameras
from triaxtrack.score import COLUMNS, ScoreTolerances, _metric, score, summarise_frames


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


def test_volume_uncertainty_and_measured_fraction_are_reported(small_test):
    """error / volume_sigma_mm3 per frame and the smallest measured_fraction: reported only."""
    import numpy as np
    import pandas as pd

    from triaxtrack.score import score_volume

    vol = pd.read_parquet(small_test / "truth" / "volume.parquet")
    v0 = float(vol.volume_mm3.iloc[0])
    got = vol.assign(volume_mm3=vol.volume_mm3 + [0.0, 0.001 * v0, 0.0, 0.002 * v0],
                     volume_sigma_mm3=[0.0005 * v0, 0.0005 * v0, np.nan, 0.0005 * v0],
                     measured_fraction=[0.9, 0.7, 0.85, 0.8])  # fmt: skip
    rows = score_volume(got, vol, ScoreTolerances())
    by_item = rows.set_index(["metric", "item"])
    assert by_item.loc[("volume_error_sigmas", "worst@3"), "value"] == pytest.approx(4, rel=1e-3)
    assert by_item.loc[("volume_error_sigmas", "all@0"), "value"] == 0
    sig = rows[rows.metric == "volume_error_sigmas"]
    assert sig.tolerance.isna().all() and sig.passed.all() and "all@2" not in set(sig["item"])  # NaN sigma
    assert by_item.loc[("measured_fraction_min", "worst@1"), "value"] == 0.7
    passed = rows.groupby("metric").passed.all()  # 0.2 % off: within 0.25 % but its change is not
    assert passed["volume_error"] and not passed["volume_change_error"]
    plain = score_volume(vol, vol, ScoreTolerances())
    assert plain.passed.all()
    assert not plain.metric.isin(["volume_error_sigmas", "measured_fraction_min"]).any()


def test_per_camera_sigma_rows_and_summary(small_test, tmp_path, capsys):
    """tracking.parquet gives reported-only per-camera rows and a per-camera summary after the
    main table; a camera with noisier footage shows a larger sigma."""
    import numpy as np
    import pandas as pd

    from triaxtrack.camera_report import camera_summary, format_camera_summary
    from triaxtrack.tables import TRACKS, write_table

    obs = pd.read_parquet(small_test / "truth" / "observations.parquet")
    sigma = np.where(obs.camera == "cam02", 0.2, 0.05)
    lost = (obs.camera == "cam03") & (obs.index % 4 == 0)  # a quarter of cam03's targets lost
    reason = np.where(lost, "lost", "")
    tracks = obs.assign(area_px=20.0, sigma_px=np.where(lost, np.nan, sigma), reason=reason)
    write_table(tracks, tmp_path / "tracking.parquet", TRACKS)
    df = score(tmp_path, small_test)
    rows = df.set_index(["metric", "item"])
    assert rows.loc[("centroid_sigma_median", "cam02"), "value"] == pytest.approx(0.2)
    assert rows.loc[("centroid_sigma_p95", "cam01"), "value"] == pytest.approx(0.05)
    assert rows.loc[("tracked_share", "cam01"), "value"] == 1
    assert rows.loc[("tracked_share", "cam03"), "value"] == pytest.approx(0.75, abs=0.01)
    assert df.tolerance.isna().all() and df.passed.all()

    coverage = pd.DataFrame({"metric": "coverage", "item": ["cam01@0", "cam01@3", "cam02@0"],
                             "value": [0.9, 0.8, 0.95], "tolerance": 0.95, "unit": "", "passed": False,
                             "source": "labels.parquet"})  # fmt: skip
    summary = camera_summary(pd.concat([coverage, df], ignore_index=True)).set_index("camera")
    assert summary.index.tolist() == ["cam01", "cam02", "cam03"]
    assert summary.loc["cam01", ["coverage_min", "coverage_median"]].tolist() == pytest.approx([0.8, 0.85])
    assert np.isnan(summary.loc["cam03", "coverage_min"])
    assert summary.loc["cam02", "sigma_median_px"] == pytest.approx(0.2)
    text = format_camera_summary(summary.reset_index())
    assert "0.800 / 0.850" in text and "75.0" in text and len(text.splitlines()) == 2 + 3
    assert format_camera_summary(camera_summary(df.iloc[:0])) == ""
    assert main(["score", str(tmp_path), str(small_test)]) == 0
    out = capsys.readouterr().out
    assert out.index("within tolerance") < out.index("per camera:") and "cam03" in out.split("per camera:")[1]


def test_nothing_to_score_exits_non_zero(tmp_path, capsys):
    """A results folder without any file the score reads is an error (exit 2), not a pass."""
    truth = tmp_path / "truth"
    truth.mkdir()
    camera = {"width": 64, "height": 48, "K": [[50.0, 0, 31.5], [0, 50.0, 23.5], [0, 0, 1]],
              "dist": [0.0] * 5, "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 300.0]}  # fmt: skip
    (truth / "cameras.json").write_text(json.dumps({"cameras": {"cam01": camera}}))
    results = tmp_path / "results"
    results.mkdir()
    (results / "notes.txt").write_text("the run stopped early")
    assert score(results, truth).empty
    assert main(["score", str(results), str(truth)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"triaxtrack score: {results}: nothing to score: the results folder holds none of")
    (results / "cameras.json").write_text(json.dumps({"cameras": {"cam01": camera}}))
    assert main(["score", str(results), str(truth)]) == 0  # the same camera: every row passes


def test_every_metric_is_documented_in_the_help_and_the_config_readme():
    """Each metric `triaxtrack score` can print is explained by `triaxtrack score --help` and in
    config/README.md (a new metric without words fails here)."""
    import re
    from pathlib import Path

    import triaxtrack.camera_report as camera_report
    import triaxtrack.score as score_module
    import triaxtrack.score_cameras as score_cameras
    from triaxtrack.cli import SCORE_HELP

    source = "".join(Path(m.__file__).read_text() for m in (score_module, score_cameras, camera_report))
    names = set(re.findall(r'_metric\(\s*"(\w+)"', source)) | set(
        re.findall(r'\(\s*"(\w+_rms_error)"', source)
    )
    names |= set(re.findall(r'\("(centroid_sigma_\w+|tracked_share)"', source))
    assert {"observations_without_truth", "id_swaps", "tracked_share", "pedestal_rms_error"} <= names
    readme = (Path(__file__).resolve().parents[1] / "config" / "README.md").read_text()
    assert [n for n in sorted(names) if n not in SCORE_HELP] == []
    assert [n for n in sorted(names) if f"`{n}`" not in readme] == []


def test_view_angle_of_targets_round_the_cylinder():
    """A camera 340 mm out on the x axis sees a target on the x axis face-on, one 60 degrees
    round at about 65 degrees (the line of sight from a near camera leans further off its normal
    than from infinity), one on the y axis nearly edge-on; an unknown target is NaN."""
    import numpy as np
    import pandas as pd

    from triaxtrack.optics import Camera
    from triaxtrack.score import _view_cos

    R = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])  # looks along -x
    cam = Camera.from_json("c", {"K": np.eye(3).tolist(), "dist": [0.0] * 5, "width": 10, "height": 10,
                                 "R": R.tolist(), "t": (-R @ np.array([340.0, 0, 70])).tolist()})  # fmt: skip
    a = np.radians(60)
    pts = pd.DataFrame({"frame": 0, "id": [1, 2, 3], "x_mm": [35.0, 35 * np.cos(a), 0.0],
                        "y_mm": [0.0, 35 * np.sin(a), 35.0], "z_mm": 70.0})  # fmt: skip
    cos = _view_cos(cam, np.array([1, 2, 3, 9]), 0, pts)
    assert cos[0] == pytest.approx(1.0)
    assert cos[1] == pytest.approx(np.cos(a + np.arctan2(35 * np.sin(a), 340 - 35 * np.cos(a))), abs=1e-9)
    assert 0.4 < cos[1] < 0.5 and abs(cos[2]) < 0.11 and np.isnan(cos[3])


def test_a_camera_left_out_by_the_workflow_is_reported_not_failed():
    """A true camera missing from the results fails, unless quality.json says it was left out."""
    import numpy as np

    from triaxtrack.optics import Camera
    from triaxtrack.score_cameras import score_cameras

    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    t = np.array([0.0, 0.0, 300.0])
    cams = {n: Camera(n, 640, 480, K, np.zeros(5), np.eye(3), t) for n in ("a", "b", "c")}
    result = {n: cams[n] for n in ("a", "b")}
    rows = score_cameras(result, cams, ScoreTolerances()).set_index("metric")
    assert not rows.loc["camera_missing", "passed"] and rows.loc["camera_missing", "item"] == "c"
    left_out = {"c": "video file not found"}
    rows = score_cameras(result, cams, ScoreTolerances(), left_out=left_out).set_index("metric")
    assert "camera_missing" not in rows.index and rows.loc["camera_left_out", "passed"]


def test_a_camera_left_out_has_no_calibration_and_is_not_failed_for_it(small_test, tmp_path):
    """Issue 20: a camera whose video was empty was left out (quality.json `cameras_left_out`), so
    it has no calibration either; `triaxtrack score` failed it as `camera_missing` in the
    calibration rows (source calibration/cam03.json) while reporting it left out below."""
    truth = json.loads((small_test / "truth" / "cameras.json").read_text())["cameras"]
    (tmp_path / "calibration").mkdir()
    for name in ("cam01", "cam02"):
        cam = truth[name]
        calibration = {"camera": name, **{k: cam[k] for k in ("width", "height", "K", "dist")}}
        (tmp_path / "calibration" / f"{name}.json").write_text(json.dumps(calibration))
    why = f"{small_test}/videos/cam03.mp4: the video file is empty (0 bytes)"
    quality = {"mean_reprojection_px": 0.02, "per_camera": {}, "cameras_left_out": {"cam03": why}}
    (tmp_path / "quality.json").write_text(json.dumps(quality))
    df = score(tmp_path, small_test)
    assert "camera_missing" not in set(df.metric), df[~df.passed]
    left = df[df.metric == "camera_left_out"]
    assert left.item.tolist() == ["cam03"] and left.passed.all() and (left.source == "quality.json").all()
    assert df.passed.all(), df[~df.passed]


def test_a_metric_measured_at_no_frame_has_no_worst_frame():
    """The top pedestal in no picture: its CTs' RMS is NaN at every frame. The summary keeps the
    first and last frames of it (NaN) and the worst of the other metrics, and does not fail."""
    rows = [
        _metric("top_ct_rms", f"all@{f}", float("nan"), float("nan"), "mm", "points.parquet")
        for f in range(4)
    ]
    rows += [
        _metric("membrane_rms_error", f"all@{f}", 0.01 * f, 0.05, "mm", "points.parquet") for f in range(4)
    ]
    out = summarise_frames(pd.DataFrame(rows, columns=COLUMNS))
    assert sorted(out.loc[out.metric == "top_ct_rms", "item"]) == ["all@0", "all@3"]
    assert "worst@3" in set(out.loc[out.metric == "membrane_rms_error", "item"])
