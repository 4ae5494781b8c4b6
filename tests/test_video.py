"""Tests for triaxtrack.video (PyAV-based grayscale video I/O)."""

from __future__ import annotations

import re
from pathlib import Path

import av
import numpy as np
import pytest

from triaxtrack.video import (
    SparseFrames,
    VideoWriter,
    concat_videos,
    encode_video,
    iter_frames,
    keyframe_indices,
    probe_video,
    read_frame,
)
from triaxtrack.video.write import _encoder_options

W, H = 160, 120
FPS = 30
N = 25
# Mean absolute error tolerance (DN) between an original frame and its decoded version.
MAE_TOL = 2.0


def disc_center(k: int) -> tuple[float, float]:
    """(x, y) pixel centre of the bright disc in synthetic frame k: moves 4 px/frame in x."""
    return 20.0 + 4.0 * k, 40.0 + 2.0 * k


def make_frames(n: int = N, seed: int = 0) -> list[np.ndarray]:
    """n synthetic uint8 (H, W) frames: gradient + moving disc + frame-number-dependent bars."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W]
    base = 30.0 + 100.0 * xx / (W - 1) + 40.0 * yy / (H - 1)
    texture = rng.normal(0.0, 3.0, size=(H, W))  # fixed mild texture, same every frame
    frames = []
    for k in range(n):
        img = base + texture
        cx, cy = disc_center(k)
        img[(xx - cx) ** 2 + (yy - cy) ** 2 <= 8.0**2] = 245.0
        # frame-number code: 5 bars along the bottom, bar b dark iff bit b of k is set
        for b in range(5):
            if (k >> b) & 1:
                img[H - 12 : H - 2, 8 + 16 * b : 20 + 16 * b] = 5.0
        frames.append(np.clip(np.rint(img), 0, 255).astype(np.uint8))
    return frames


def mae(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(np.abs(a.astype(np.int16) - b.astype(np.int16))))


def measured_disc_center(img: np.ndarray) -> tuple[float, float]:
    """Centroid of pixels > 200 DN (only the disc is that bright)."""
    ys, xs = np.nonzero(img > 200)
    return float(xs.mean()), float(ys.mean())


def assert_matches(k: int, decoded: np.ndarray, originals: list[np.ndarray]) -> None:
    assert decoded.dtype == np.uint8
    assert decoded.shape == (H, W)
    err = mae(decoded, originals[k])
    assert err < MAE_TOL, f"frame {k}: mean abs error {err:.2f} DN >= {MAE_TOL}"
    # order check: the disc is where frame k put it (frames differ by 4 px in x)
    cx, cy = measured_disc_center(decoded)
    ex, ey = disc_center(k)
    assert abs(cx - ex) < 1.0 and abs(cy - ey) < 1.0, f"frame {k}: disc at {(cx, cy)}"
    # and it is closer to original k than to its neighbours
    for j in (k - 1, k + 1):
        if 0 <= j < len(originals):
            assert err < mae(decoded, originals[j])


def packet_payloads(path: Path) -> list[bytes]:
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        return [bytes(p) for p in container.demux(stream) if p.size > 0]


@pytest.fixture(scope="module")
def originals() -> list[np.ndarray]:
    return make_frames()


@pytest.mark.parametrize("codec, codec_name", [("h264", "h264"), ("h265", "hevc")])
def test_round_trip(tmp_path: Path, originals: list[np.ndarray], codec: str, codec_name: str):
    path = tmp_path / f"rt_{codec}.mp4"
    assert encode_video(originals, path, FPS, codec=codec) == N

    info = probe_video(path)
    assert info["frames"] == N
    assert info["fps"] == pytest.approx(FPS)
    assert (info["width"], info["height"]) == (W, H)
    assert info["codec"] == codec_name
    assert info["duration_s"] == pytest.approx(N / FPS, abs=1e-6)

    decoded = list(iter_frames(path))
    assert [k for k, _ in decoded] == list(range(N))
    for k, img in decoded:
        assert_matches(k, img, originals)


def test_iter_frames_range(tmp_path: Path, originals: list[np.ndarray]):
    path = tmp_path / "range.mp4"
    # gop=8: keyframes at 0, 8, 16, 24, so start=13 seeks to keyframe 8 and must decode and
    # drop frames 8..12.
    with VideoWriter(path, W, H, FPS, gop=8) as w:
        for img in originals:
            w.write(img)
    got = list(iter_frames(path, start=13, stop=20))
    assert [k for k, _ in got] == list(range(13, 20))
    for k, img in got:
        assert_matches(k, img, originals)
    # start past a keyframe boundary and stop=None runs to the end
    assert [k for k, _ in iter_frames(path, start=17)] == list(range(17, N))
    assert list(iter_frames(path, start=5, stop=5)) == []
    assert_matches(24, read_frame(path, 24), originals)
    assert_matches(24, read_frame(path, -1), originals)
    with pytest.raises(IndexError):
        read_frame(path, N)


@pytest.mark.parametrize("codec", ["h264", "h265"])
def test_concat_segments(tmp_path: Path, originals: list[np.ndarray], codec: str):
    bounds = [(0, 10), (10, 20), (20, 25)]
    segs = []
    for i, (a, b) in enumerate(bounds):
        seg = tmp_path / f"seg{i}.mp4"
        assert encode_video(originals[a:b], seg, FPS, codec=codec) == b - a
        segs.append(seg)
    out = tmp_path / "joined.mp4"
    assert concat_videos(segs, out) == N
    # stream copy, not re-encoding: the output packets are the segments' packets, byte for byte
    seg_payloads = [p for seg in segs for p in packet_payloads(seg)]
    assert packet_payloads(out) == seg_payloads

    info = probe_video(out)
    assert info["frames"] == N
    assert info["fps"] == pytest.approx(FPS)
    assert info["duration_s"] == pytest.approx(N / FPS, abs=1e-6)

    decoded = list(iter_frames(out))
    assert [k for k, _ in decoded] == list(range(N))
    for k, img in decoded:
        assert_matches(k, img, originals)
    # random access into the second and third segment works (each starts with a keyframe)
    assert_matches(12, read_frame(out, 12), originals)
    assert [k for k, _ in iter_frames(out, start=21, stop=23)] == [21, 22]


def test_concat_rejects_different_size(tmp_path: Path, originals: list[np.ndarray]):
    a = tmp_path / "a.mp4"
    b = tmp_path / "b_small.mp4"
    encode_video(originals[:5], a, FPS)
    encode_video([img[: H // 2, : W // 2].copy() for img in originals[5:10]], b, FPS)
    out = tmp_path / "bad.mp4"
    with pytest.raises(ValueError, match=re.escape("b_small.mp4")):
        concat_videos([a, b], out)
    assert not out.exists()


def test_concat_rejects_different_codec_settings(tmp_path: Path, originals: list[np.ndarray]):
    a = tmp_path / "a.mp4"
    b = tmp_path / "b_h265.mp4"
    encode_video(originals[:5], a, FPS, codec="h264")
    encode_video(originals[5:10], b, FPS, codec="h265")
    with pytest.raises(ValueError, match=re.escape("b_h265.mp4")):
        concat_videos([a, b], tmp_path / "bad.mp4")


def test_probe_missing_file(tmp_path: Path):
    missing = tmp_path / "does_not_exist.mp4"
    with pytest.raises(FileNotFoundError, match=re.escape("does_not_exist.mp4")):
        probe_video(missing)
    with pytest.raises(FileNotFoundError, match=re.escape("does_not_exist.mp4")):
        iter_frames(missing)


def test_probe_unreadable_file(tmp_path: Path):
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"this is not a video" * 50)
    with pytest.raises(ValueError, match=re.escape("junk.mp4")):
        probe_video(junk)


def test_writer_validates_frames(tmp_path: Path):
    path = tmp_path / "v.mp4"
    with VideoWriter(path, W, H, FPS) as w:
        with pytest.raises(ValueError, match=re.escape("v.mp4")):
            w.write(np.zeros((H, W), dtype=np.float32))
        with pytest.raises(ValueError, match=re.escape("v.mp4")):
            w.write(np.zeros((H + 2, W), dtype=np.uint8))
        w.write(np.full((H, W), 77, dtype=np.uint8))
    assert probe_video(path)["frames"] == 1
    assert abs(float(read_frame(path, 0).mean()) - 77.0) < 0.5
    with pytest.raises(ValueError, match="even"):
        VideoWriter(tmp_path / "odd.mp4", W + 1, H, FPS)
    with pytest.raises(ValueError, match="codec"):
        VideoWriter(tmp_path / "x.mp4", W, H, FPS, codec="vp9")


def _gray_by_conversion(path: Path) -> list[np.ndarray]:
    with av.open(str(path)) as container:
        return [f.to_ndarray(format="gray") for f in container.decode(video=0)]


def test_full_range_frames_are_the_luma_plane_itself(tmp_path: Path):
    """A full-range video (the project's own): each frame is the decoder's luma plane, read-only
    (the decoder may still predict from it), with the values of to_ndarray(format='gray'), also
    where the plane's rows are padded (line_size > width)."""
    path = tmp_path / "full.mp4"
    encode_video(make_frames(4), path, FPS, codec="h264")
    with av.open(str(path)) as container:
        frame = next(container.decode(video=0))
        assert frame.format.name == "yuvj420p" and frame.planes[0].line_size > W
    got = [img for _, img in iter_frames(path)]
    assert len(got) == 4 and all(not img.flags.writeable and img.shape == (H, W) for img in got)
    for img, ref in zip(got, _gray_by_conversion(path), strict=True):
        assert np.array_equal(img, ref)


def test_limited_range_frames_are_converted(tmp_path: Path):
    """A limited-range video (most cameras' yuv420p): the frames are to_ndarray(format='gray')'s,
    16..235 stretched to 0..255, not the raw luma plane."""
    path = tmp_path / "tv.mp4"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=FPS)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        for img in make_frames(3):
            frame = av.VideoFrame.from_ndarray(img, format="gray").reformat(format="yuv420p")
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    got = [img for _, img in iter_frames(path)]
    ref = _gray_by_conversion(path)
    assert len(got) == 3 and all(np.array_equal(a, b) for a, b in zip(got, ref, strict=True))
    assert min(int(img.min()) for img in got) < 16  # stretched: the raw luma plane holds 16..235


@pytest.mark.parametrize("codec", ["h264", "h265"])
def test_recorder_puts_keyframes_where_asked_and_every_gop_after(
    tmp_path: Path, originals: list[np.ndarray], codec: str
):
    """recorder=True: an IDR where write(keyframe=True) says (even 2 frames after the last),
    else gop frames after the last keyframe; no scene-cut keyframes (the disc jumps 4 px and the
    frame-number bars change every frame); and no mb-tree / cutree."""
    path = tmp_path / f"rec_{codec}.mp4"
    with VideoWriter(path, W, H, FPS, codec=codec, gop=12, recorder=True) as w:
        for k, img in enumerate(originals):
            w.write(img, keyframe=k in (2, 9))
    assert keyframe_indices(path).tolist() == [0, 2, 9, 21]
    for k, img in iter_frames(path):
        assert_matches(k, img, originals)
    tree = {"h264": "mbtree=0", "h265": "cutree=0"}[codec]
    params = _encoder_options(codec, 14, "veryfast", 12, recorder=True)[f"x{codec[1:]}-params"]
    assert tree in params.split(":") and "scenecut=0" in params.split(":")
    assert tree not in _encoder_options(codec, 14, "veryfast", 12)[f"x{codec[1:]}-params"]


@pytest.mark.parametrize("codec", ["h264", "h265"])
def test_sparse_frames_are_the_decoded_frames_and_cost_fewer_decodes(
    tmp_path: Path, originals: list[np.ndarray], codec: str
):
    """SparseFrames gives exactly the frames full decoding gives at the indices asked for, and
    decodes (counted, not timed) one frame per keyframe asked for, and from the keyframe at or
    before any other frame."""
    path = tmp_path / f"sparse_{codec}.mp4"
    with VideoWriter(path, W, H, FPS, codec=codec, gop=5, recorder=True) as w:
        for k, img in enumerate(originals):
            w.write(img, keyframe=k % 5 == 0)
    assert keyframe_indices(path).tolist() == [0, 5, 10, 15, 20]
    full = {k: img.copy() for k, img in iter_frames(path)}
    cases = [  # wanted, frames decoded, seeks
        ([0, 5, 10, 15, 20], 5, 1),  # every keyframe: skip_frame NONKEY after one seek
        ([5, 15], 2, 2),  # some keyframes: a seek to each
        ([3, 5, 13, 24], 4 + 1 + 4 + 5, 4),  # from the keyframe at or before each
        ([7, 8, 9], 5, 1),  # one GOP: decoded on
        ([24], 5, 1),
    ]
    for wanted, decoded, seeks in cases:
        reader = SparseFrames(path, wanted)
        got = [(k, img.copy()) for k, img in reader]
        assert [k for k, _ in got] == wanted
        for k, img in got:
            assert np.array_equal(img, full[k]), f"frame {k}"
        assert (reader.decoded, reader.seeks) == (decoded, seeks), wanted
    assert list(SparseFrames(path, [])) == []
    with pytest.raises(ValueError, match="no frame 25"):
        list(SparseFrames(path, [3, 25]))
