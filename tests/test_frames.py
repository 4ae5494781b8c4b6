"""Frame maps: test frame k -> video frame, with start offsets and dropped frames."""

from __future__ import annotations

import warnings
from pathlib import Path

import jsonschema
import numpy as np
import pandas as pd
import pytest
import yaml

from triaxtrack.frames import (
    CameraTiming,
    ProcessedTestFrames,
    count_test_frames,
    frame_map,
    iter_test_frames,
    keyframe_test_frames,
    read_camera_timing,
    read_test_frame,
    summarize_frame_map,
)
from triaxtrack.simulate import (
    CameraRenderer,
    SimulationConfig,
    check_simulation,
    load_scene,
    render_chunk,
    simulate_test,
)
from triaxtrack.tables import FRAME_MAP, OBSERVATIONS, read_table, write_table
from triaxtrack.video import VideoWriter, keyframe_indices, probe_video

ROOT = Path(__file__).resolve().parents[1]
FPS = 10.0


def mapping(fmap: pd.DataFrame) -> list[tuple[int, int, str]]:
    return list(zip(fmap.frame, fmap.video_index, fmap.reason, strict=True))


def test_no_offset_no_drops_is_the_identity():
    fmap = frame_map(CameraTiming("c", FPS), 5, 5)
    assert mapping(fmap) == [(k, k, "") for k in range(5)]
    assert not fmap.missing.any()
    np.testing.assert_allclose(fmap.time_s, np.arange(5) / FPS)
    np.testing.assert_allclose(fmap.video_time_s, fmap.time_s)


def test_late_start_shifts_and_ends_early():
    # started 0.2 s late: nominal frame 0 is test frame 2; a 4-frame file ends at test frame 5
    fmap = frame_map(CameraTiming("c", FPS, start_offset_s=0.2), 7, 4)
    assert mapping(fmap) == [
        (0, -1, "before_start"), (1, -1, "before_start"), (2, 0, ""), (3, 1, ""), (4, 2, ""),
        (5, 3, ""), (6, -1, "after_end"),
    ]  # fmt: skip
    assert (fmap.missing == (fmap.reason != "")).all()


def test_early_start_skips_the_frames_before_the_test():
    fmap = frame_map(CameraTiming("c", FPS, start_offset_s=-0.3), 4, 10)
    assert mapping(fmap) == [(k, k + 3, "") for k in range(4)]


def test_dropped_frames_shift_the_file_index():
    fmap = frame_map(CameraTiming("c", FPS, dropped_frames=(4, 1)), 7, 5)
    assert mapping(fmap) == [
        (0, 0, ""), (1, -1, "dropped"), (2, 1, ""), (3, 2, ""), (4, -1, "dropped"), (5, 3, ""), (6, 4, ""),
    ]  # fmt: skip


def test_offset_and_drops_together():
    # nominal n = k - 2; drops n = 0 and 3; the file holds n = 1, 2, 4, 5 (4 frames)
    fmap = frame_map(CameraTiming("c", FPS, start_offset_s=0.2, dropped_frames=(0, 3)), 9, 4)
    assert mapping(fmap) == [
        (0, -1, "before_start"), (1, -1, "before_start"), (2, -1, "dropped"), (3, 0, ""), (4, 1, ""),
        (5, -1, "dropped"), (6, 2, ""), (7, 3, ""), (8, -1, "after_end"),
    ]  # fmt: skip
    assert summarize_frame_map(fmap) == {
        "frames": 9, "present": 4, "before_start": 2, "dropped": 2, "after_end": 1,
    }  # fmt: skip
    present = fmap[~fmap.missing]
    np.testing.assert_allclose(present.video_time_s, present.time_s)
    assert fmap.loc[fmap.missing, "video_time_s"].isna().all()


def test_a_logged_drop_past_the_end_of_the_file_counts_as_dropped():
    fmap = frame_map(CameraTiming("c", FPS, dropped_frames=(4,)), 6, 4)
    assert list(fmap.reason) == ["", "", "", "", "dropped", "after_end"]


def test_subframe_offset_warns_and_records_the_residual():
    with pytest.warns(UserWarning, match=r"1\.300 frames.*residual \+0\.0300 s"):
        fmap = frame_map(CameraTiming("c", FPS, start_offset_s=0.13), 4, 10)
    assert mapping(fmap) == [(0, -1, "before_start"), (1, 0, ""), (2, 1, ""), (3, 2, "")]
    present = fmap[~fmap.missing]
    np.testing.assert_allclose(present.video_time_s - present.time_s, 0.03, atol=1e-12)
    # within 0.05 frames of a whole number: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frame_map(CameraTiming("c", FPS, start_offset_s=0.204), 4, 10)


def test_bad_timing_is_rejected():
    with pytest.raises(ValueError, match="dropped_frames"):
        CameraTiming("c", FPS, dropped_frames=(3, 3))
    with pytest.raises(ValueError, match="dropped_frames"):
        CameraTiming("c", FPS, dropped_frames=(-1,))
    with pytest.raises(ValueError, match="fps"):
        CameraTiming("c", 0.0)


def test_schema_is_checked_on_write(tmp_path):
    fmap = frame_map(CameraTiming("c", FPS, start_offset_s=0.1), 3, 3)
    write_table(fmap, tmp_path / "c.parquet", FRAME_MAP)
    back = read_table(tmp_path / "c.parquet", FRAME_MAP)
    pd.testing.assert_frame_equal(back, fmap)
    assert str(back.video_index.dtype) == "int64" and str(back.missing.dtype) == "bool"
    with pytest.raises(ValueError, match="lacks columns"):
        write_table(fmap.drop(columns="reason"), tmp_path / "bad.parquet", FRAME_MAP)


def test_camera_timing_from_test_yaml(tmp_path):
    path = tmp_path / "test.yaml"
    cameras = ["a", {"name": "b", "start_offset_s": 0.08, "dropped_frames": [9, 3]}]
    path.write_text(yaml.safe_dump({"name": "t", "fps": 25, "cameras": cameras}))
    assert read_camera_timing(path, "a") == CameraTiming("a", 25.0)
    assert read_camera_timing(path, "b") == CameraTiming("b", 25.0, 0.08, (3, 9))
    with pytest.raises(ValueError, match=r"test\.yaml.*'z' is not listed"):
        read_camera_timing(path, "z")


# ---------------------------------------------------------------- a simulated test

FRAMES = 5
# cam02 starts 1 frame late and drops its nominal frame 0: it records test frames 2, 3, 4;
# cam03 drops nominal (= test) frame 2
RECORDED = {"cam01": [0, 1, 2, 3, 4], "cam02": [2, 3, 4], "cam03": [0, 1, 3, 4]}


@pytest.fixture(scope="module")
def late_test(kit_dir, tmp_path_factory):
    """3 cameras x 5 frames at 320x180, chunks of 3 frames, lossless video (crf 0)."""
    out = tmp_path_factory.mktemp("frames") / "late"
    cfg = SimulationConfig(
        cameras=3, frames=FRAMES, width=320, height=180, crf=0, calibration_images=1,
        start_offset_s={"cam02": 1 / 15}, dropped_frames={"cam02": [0], "cam03": [2]},
    )  # fmt: skip
    simulate_test(cfg, kit_dir, out, "late", chunk_size=3)
    return out


def test_simulated_test_yaml_lists_offsets_and_drops(late_test):
    doc = yaml.safe_load((late_test / "test.yaml").read_text())
    schema = yaml.safe_load((ROOT / "workflow" / "schemas" / "test.schema.yaml").read_text())
    jsonschema.validate(doc, schema)
    late = {"name": "cam02", "start_offset_s": 1 / 15, "dropped_frames": [0]}
    assert doc["cameras"] == ["cam01", late, {"name": "cam03", "dropped_frames": [2]}]


def test_test_frames_are_the_rendered_frames(late_test):
    """Decoded test frame k equals the renderer's image of frame k (lossless video); frames the
    camera did not record come back as None; the truth holds only the recorded frames."""
    video = late_test / "videos" / "cam02.mp4"
    assert probe_video(video)["frames"] == 3
    fmap = frame_map(read_camera_timing(late_test / "test.yaml", "cam02"), FRAMES, 3)
    renderer = CameraRenderer(load_scene(late_test), "cam02")
    rendered = [renderer.render(k)[0] for k in range(FRAMES)]  # in order, as render_chunk does
    got = dict(iter_test_frames(video, fmap, 0, FRAMES))
    assert sorted(got) == list(range(FRAMES))
    assert [k for k, img in got.items() if img is None] == [0, 1]
    for k in RECORDED["cam02"]:
        assert np.array_equal(got[k], rendered[k]), f"test frame {k}"
        assert not np.array_equal(got[k], rendered[k - 1])  # the noise differs from frame to frame
    assert np.array_equal(read_test_frame(video, fmap, 3), rendered[3])
    assert read_test_frame(video, fmap, 1) is None
    obs = read_table(late_test / "truth" / "observations.parquet", OBSERVATIONS)
    assert {c: sorted(g.frame.unique()) for c, g in obs.groupby("camera")} == RECORDED


def test_a_frame_map_that_does_not_fit_the_video_names_the_file(late_test):
    video = late_test / "videos" / "cam02.mp4"
    fmap = frame_map(CameraTiming("cam02", 15.0), FRAMES, FRAMES)  # expects 5 frames, the file has 3
    with pytest.raises(ValueError, match="cam02.mp4.*ends before frame 3"):
        list(iter_test_frames(video, fmap, 0, FRAMES))
    with pytest.raises(ValueError, match="not in the frame map"):
        list(iter_test_frames(video, fmap, 3, FRAMES + 2))


def test_check_simulation_follows_the_frame_map(late_test):
    """The simulation check expects of each camera the frames it recorded, and measures its dots
    on its first and last recorded frames, read through the frame map. (Which image it gets is
    checked exactly above; at 320x180 the dot centroids are too coarse to tell frames apart.)"""
    report = check_simulation(late_test)
    cams = report["cameras"]
    assert {c: (v["frames"], v["frames_expected"]) for c, v in cams.items()} == {
        c: (len(k), len(k)) for c, k in RECORDED.items()
    }
    assert all(v["air_median_px"] is not None and v["water_median_px"] is not None for v in cams.values())


def test_simulator_rejects_offsets_it_cannot_render():
    with pytest.raises(ValueError, match="whole number of frames"):
        SimulationConfig.from_dict({"fps": 10.0, "start_offset_s": {"cam01": 0.15}})
    with pytest.raises(ValueError, match="whole number of frames"):
        SimulationConfig.from_dict({"fps": 10.0, "start_offset_s": {"cam01": -0.1}})
    with pytest.raises(ValueError, match="no camera"):
        SimulationConfig.from_dict({"cameras": 3, "dropped_frames": {"cam07": [1]}})
    with pytest.raises(ValueError, match="dropped_frames of cam01"):
        SimulationConfig.from_dict({"frames": 10, "dropped_frames": {"cam01": [10]}})


def test_a_chunk_the_camera_did_not_record_is_an_error(late_test, tmp_path):
    with pytest.raises(ValueError, match="cam02 recorded none of test frames 0..1"):
        render_chunk(late_test, "cam02", 0, 2, tmp_path / "v.mp4", tmp_path / "o.parquet")


def test_test_frames_counted_from_test_yaml_or_a_video(late_test, tmp_path):
    assert count_test_frames(late_test / "test.yaml") == FRAMES
    path = tmp_path / "test.yaml"
    path.write_text(yaml.safe_dump({"name": "t", "fps": 15, "cameras": ["cam02"]}))
    assert count_test_frames(path, late_test / "videos" / "cam02.mp4") == 3
    with pytest.raises(ValueError, match=r"test\.yaml: no `frames`"):
        count_test_frames(path)


def test_keyframes_as_test_frames_through_the_frame_map(tmp_path):
    """A video with a keyframe every 5 frames, recorded from test frame 2 on with video frame 6
    dropped: its keyframes 0, 5, 10, 15 are test frames 2, 7, 13, 18; only the asked range is read."""
    path = tmp_path / "gop.mp4"
    with VideoWriter(path, 64, 48, FPS, gop=5) as w:
        for k in range(20):  # a dark square drifting slowly: no scene cut, keyframes by the GOP only
            img = np.full((48, 64), 200, np.uint8)
            img[20:28, 10 + k : 18 + k] = 40
            w.write(img)
    assert keyframe_indices(path).tolist() == [0, 5, 10, 15]
    assert keyframe_indices(path, 6, 15).tolist() == [10]
    fmap = frame_map(CameraTiming("cam01", FPS, start_offset_s=0.2, dropped_frames=(8,)), 22, 20)
    shown = fmap.set_index("frame")["video_index"]
    assert [int(shown[k]) for k in (2, 7, 13, 18)] == [0, 5, 10, 15]
    assert keyframe_test_frames(path, fmap, 0, 22).tolist() == [2, 7, 13, 18]
    assert keyframe_test_frames(path, fmap, 8, 14).tolist() == [13]


def test_fast_mode_decodes_only_the_processed_frames(tmp_path):
    """ProcessedTestFrames: at the processed frames (and the first, the labelled one) the very
    images of full decoding, None at every other frame, in the same order; far fewer frames
    decoded (counted). The camera starts at test frame 2 and dropped its nominal frame 6 (test
    frame 8); keyframes every 5 video frames (test frames 2, 7, 13, 18, 23)."""
    path = tmp_path / "gop.mp4"
    rng = np.random.default_rng(5)
    with VideoWriter(path, 64, 48, FPS, gop=5, recorder=True) as w:
        for k in range(25):
            img = rng.integers(60, 200, (48, 64)).astype(np.uint8)  # noise: every frame differs
            img[20:28, 10 + k : 18 + k] = 20
            w.write(img, keyframe=k % 5 == 0)
    fmap = frame_map(CameraTiming("cam01", FPS, start_offset_s=0.2, dropped_frames=(6,)), 28, 25)
    assert keyframe_test_frames(path, fmap, 0, 28).tolist() == [2, 7, 13, 18, 23]
    full = [(k, None if img is None else img.copy()) for k, img in iter_test_frames(path, fmap, 1, 28)]
    processed = [7, 8, 9, 18, 24, 30]  # 8 was dropped; 30 is past the range
    fast = ProcessedTestFrames(path, fmap, 1, 28, processed)
    got = [(k, None if img is None else img.copy()) for k, img in fast]
    assert [k for k, _ in got] == [k for k, _ in full] == list(range(1, 28))
    shown = {1, 7, 9, 18, 24}  # and 1, the first (labelled) frame, but the camera starts at 2
    for (k, img), (_, ref) in zip(got, full, strict=True):
        if k in shown and ref is not None:
            assert np.array_equal(img, ref), f"test frame {k}"
        else:
            assert img is None, f"test frame {k}"
    # 7 (a keyframe) and 9 (decoded on); 18 (a keyframe); 24 from keyframe 23; against 25
    assert (fast.decoded, fast.seeks) == (2 + 1 + 2, 3)
    assert fast.decoded < sum(img is not None for _, img in full) == 25
