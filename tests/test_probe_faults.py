"""Broken videos stop at the probe, each with its own message naming the file: an empty file, a
truncated one (index first, "faststart", then cut; or cut before its index was written), and a
video whose frame size or frame rate does not match the test (the inventory)."""

from __future__ import annotations

import re
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest

from triaxtrack.inventory import summarize_probes
from triaxtrack.video import iter_frames, probe_video

W, H, FPS, N, GOP = 96, 64, 15, 12, 4


def write_video(path: Path, n: int = N, width: int = W, height: int = H, fps: int = FPS, *,
                faststart: bool = False) -> Path:  # fmt: skip
    """A small H.264 MP4 (a bright bar moving over noise, seeded), written by PyAV directly so the
    muxer can put the index first (``movflags=faststart``, as many recorders and exports do)."""
    rng = np.random.default_rng(7)
    options = {"movflags": "faststart"} if faststart else {}
    with av.open(str(path), mode="w", options=options) as container:
        params = f"bframes=0:keyint={GOP}:min-keyint={GOP}:scenecut=0:threads=1"
        stream = container.add_stream(
            "libx264", rate=fps, options={"preset": "ultrafast", "x264-params": params}
        )
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        for k in range(n):
            img = rng.integers(0, 60, size=(height * 3 // 2, width), dtype=np.uint8)
            img[: height // 2, (4 * k) % width :][:, :6] = 230
            frame = av.VideoFrame.from_ndarray(img, format="yuv420p")
            frame.pts, frame.time_base = k, Fraction(1, fps)
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode(None):
            container.mux(packet)
    return path


def cut(src: Path, dst: Path, share: float) -> Path:
    """The first ``share`` of ``src``'s bytes, as a copy that stopped early would leave."""
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * share)])
    return dst


def index_first(path: Path) -> bool:
    """True when the MP4's index ('moov') comes before its frames ('mdat')."""
    data = path.read_bytes()
    return 0 <= data.find(b"moov") < data.find(b"mdat")


@pytest.mark.parametrize("faststart", [False, True])
def test_a_whole_video_is_counted_packet_by_packet(tmp_path, faststart):
    path = write_video(tmp_path / "whole.mp4", faststart=faststart)
    assert index_first(path) == faststart
    info = probe_video(path)
    assert (info["frames"], info["index_frames"], info["keyframes"]) == (N, N, N // GOP)
    assert info["packets_without_pts"] == 0 and info["path"] == str(path)
    assert (info["width"], info["height"], info["fps"]) == (W, H, FPS)


def test_an_empty_file_is_called_empty(tmp_path):
    path = tmp_path / "cam07.mp4"
    path.touch()
    expected = f"{path}: the video file is empty (0 bytes): the recording or the copy failed; copy it again"
    with pytest.raises(ValueError, match=re.escape(expected)):
        probe_video(path)
    with pytest.raises(ValueError, match=re.escape(expected)):
        next(iter_frames(path))  # every reader says so, not only the probe


@pytest.mark.parametrize("share", [0.6, 0.35])
def test_a_cut_faststart_video_is_truncated_not_trusted(tmp_path, share):
    """The index survives at the front and still lists every frame; only demuxing finds that the
    frames are not all there (the index alone, as parse time reads it, is fooled)."""
    whole = write_video(tmp_path / "whole.mp4", faststart=True)
    path = cut(whole, tmp_path / "cam03.mp4", share)
    assert probe_video(path, index_only=True)["frames"] == N  # what the old probe reported
    with pytest.raises(ValueError) as err:
        probe_video(path)
    message = str(err.value)
    found = re.fullmatch(
        re.escape(f"{path}: truncated video: its index lists {N} frames but the file holds only ")
        + r"(\d+)( \(and part of one more\))?: it ends at byte (\d+), inside its 'mdat' box, which runs to "
        + rf"byte {whole.stat().st_size}; copy it again from the recorder",
        message,
    )
    assert found, message
    assert 0 < int(found[1]) < N and int(found[3]) == path.stat().st_size
    full = probe_video(whole)
    assert int(found[1]) <= round(share * N) + 1  # about the share of the frames kept
    assert full["frames"] == N


def test_a_video_cut_before_its_index_was_written(tmp_path):
    """A recorder writes the index last: a recording that stopped early has none."""
    whole = write_video(tmp_path / "whole.mp4")
    path = cut(whole, tmp_path / "cam05.mp4", 0.5)
    expected = (
        f"{path}: truncated video: it has no index (no MP4 'moov' box: a recorder writes it last) and "
        f"ends at byte {path.stat().st_size}, inside its 'mdat' box"
    )
    with pytest.raises(ValueError, match=re.escape(expected)):
        probe_video(path)


def test_a_faststart_video_cut_inside_its_index(tmp_path):
    whole = write_video(tmp_path / "whole.mp4", faststart=True)
    moov = whole.read_bytes().find(b"moov")
    path = tmp_path / "cam09.mp4"
    path.write_bytes(whole.read_bytes()[: moov + 40])
    with pytest.raises(ValueError, match=re.escape(f"{path}: truncated video: it ends at byte {moov + 40}, "
                                                   "inside its 'moov' box")):  # fmt: skip
        probe_video(path)


def test_a_file_that_is_not_a_video_is_not_called_truncated(tmp_path):
    path = tmp_path / "notes.mp4"
    path.write_bytes(b"camera 3 was moved at 14:02\n" * 20)
    with pytest.raises(ValueError, match=re.escape(f"cannot read video {path}")) as err:
        probe_video(path)
    assert "truncated" not in str(err.value)


# ---------------------------------------------------------------- the inventory: size and fps


def recorded_probes(tmp_path: Path, specs: dict[str, dict]) -> tuple[dict, list[dict]]:
    """test.yaml (fps FPS) and the probes of one video per camera, written with ``specs``."""
    probes = [probe_video(write_video(tmp_path / f"{camera}.mp4", **spec)) for camera, spec in specs.items()]
    test = {"name": "t", "fps": FPS, "cameras": [{"name": camera} for camera in specs]}
    return test, probes


def test_wrong_frame_size_and_rate_are_each_named(tmp_path):
    specs = {"cam01": {}, "cam02": {}, "cam03": {"width": 64, "height": 48}, "cam04": {"fps": 10}}
    test, probes = recorded_probes(tmp_path, specs)
    size = f"{tmp_path / 'cam03.mp4'}: frame size 64x48 pixels, but 3 of the 4 cameras' videos are {W}x{H}"
    rate = f"{tmp_path / 'cam04.mp4'}: frame rate 10 frames/s, but test.yaml gives fps: {FPS}"
    with pytest.raises(ValueError) as err:
        summarize_probes(test, probes, "t")
    assert str(err.value) == f"test 't': 2 video(s) do not match the test:\n  {size}\n  {rate}"

    inventory = summarize_probes(test, probes, "t", strict=False)
    assert inventory["problems"] == [size, rate]
    flags = {c["camera"]: c["flags"] for c in inventory["cameras"]}
    assert flags == {"cam01": [], "cam02": [], "cam03": ["size_differs"], "cam04": ["fps_differs"]}


def test_a_different_frame_count_is_only_flagged(tmp_path):
    """A late start or dropped frames shorten a video for a reason: flagged, not an error."""
    test, probes = recorded_probes(tmp_path, {"cam01": {}, "cam02": {}, "cam03": {"n": N - 3}})
    inventory = summarize_probes(test, probes, "t")
    assert inventory["frame_count_differs"] == ["cam03"] and inventory["problems"] == []
    assert inventory["cameras"][0]["index_frames"] == N


def test_a_video_without_frames_or_keyframes(tmp_path):
    """An MP4 closed before its first frame, and one whose keyframes were lost (nothing decodes)."""
    empty = tmp_path / "cam11.mp4"
    with av.open(str(empty), mode="w") as container:
        stream = container.add_stream("libx264", rate=FPS)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        container.start_encoding()
    assert empty.stat().st_size > 0
    with pytest.raises(ValueError, match=re.escape(f"no video stream in {empty}")):
        probe_video(empty)

    whole = write_video(tmp_path / "whole.mp4")
    broken = tmp_path / "cam12.mp4"
    with av.open(str(whole)) as src, av.open(str(broken), mode="w") as dst:
        out = dst.add_stream_from_template(src.streams.video[0])
        for packet in src.demux(src.streams.video[0]):
            if packet.size and not packet.is_keyframe:
                packet.stream = out
                dst.mux(packet)
    expected = f"{broken}: none of its {N - N // GOP} frames is a keyframe: none decodes; copy it again"
    with pytest.raises(ValueError, match=re.escape(expected)):
        probe_video(broken)


# ---------------------------------------------------------------- cameras left out at parse time


def test_a_missing_empty_or_broken_video_leaves_its_camera_out_by_name(tmp_path):
    """Issue 20's table on 13 cameras: one camera's video missing, empty, or with its first bytes
    zeroed (broken: FFmpeg cannot open it) is left out with why, naming the file, and the test
    goes on with 12; a video cut behind a whole index passes this quick check (its probe_video
    job stops the test); with ``on_bad_camera: fail`` the test stops listing every camera."""
    from triaxtrack.inventory import usable_cameras

    whole = write_video(tmp_path / "whole.mp4")
    videos = {f"cam{k:02d}": tmp_path / f"cam{k:02d}.mp4" for k in range(1, 14)}
    for path in videos.values():
        path.write_bytes(whole.read_bytes())
    data = bytearray(whole.read_bytes())
    data[:64] = bytes(64)
    damaged = {"missing": None, "empty": b"", "broken": bytes(data)}
    why = {"missing": "video file not found: {}", "empty": "{}: the video file is empty (0 bytes)",
           "broken": "cannot read video {}: "}  # fmt: skip
    for camera, fault in zip(("cam04", "cam05", "cam06"), damaged, strict=True):
        path = videos[camera]
        path.unlink()
        if damaged[fault] is not None:
            path.write_bytes(damaged[fault])
        kept, left_out = usable_cameras(videos, "skip", 8, "test 'x'")
        assert kept == [c for c in videos if c != camera] and list(left_out) == [camera], fault
        assert why[fault].format(path) in left_out[camera], left_out
        path.write_bytes(whole.read_bytes())
    cut(write_video(tmp_path / "fast.mp4", faststart=True), videos["cam08"], 0.6)
    assert usable_cameras(videos) == (list(videos), {})  # its index is whole ...
    with pytest.raises(ValueError, match=re.escape(f"{videos['cam08']}: truncated video")):
        probe_video(videos["cam08"])  # ... its probe_video job counts the packets
    cut(whole, videos["cam07"], 0.6)  # index last: no index, so it is left out as truncated
    _, left_out = usable_cameras(videos)
    assert list(left_out) == ["cam07"] and "truncated video" in left_out["cam07"]
    with pytest.raises(ValueError, match="on_bad_camera: fail") as err:
        usable_cameras(videos, "fail")
    assert f"cam07: {videos['cam07']}: truncated video" in str(err.value)


def test_a_video_at_another_frame_rate_is_left_out_before_any_job(tmp_path):
    """A camera recorded at 25 fps in a 15 fps test is named at parse time (its index: no job
    runs first; the inventory job stopped the test after 85 jobs had run) and left out."""
    from triaxtrack.inventory import usable_cameras

    videos = {f"cam{i:02d}": write_video(tmp_path / f"cam{i:02d}.mp4") for i in range(1, 10)}
    write_video(videos["cam08"], fps=25)
    kept, left_out = usable_cameras(videos, "skip", 8, "test 'x'", fps=FPS)
    assert list(left_out) == ["cam08"] and "cam08" not in kept and len(kept) == 8
    assert left_out["cam08"] == f"{videos['cam08']}: frame rate 25 frames/s, but test.yaml gives fps: {FPS}"
    with pytest.raises(ValueError, match="only 1 of 9 cameras can be measured"):
        usable_cameras(videos, "skip", 8, "test 'x'", fps=25.0)  # the test says 25: the others differ
