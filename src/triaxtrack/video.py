"""Video I/O for 8-bit grayscale frames, through PyAV only (no system ffmpeg).

Conventions used throughout this module:

* A frame is a ``numpy.ndarray`` of dtype ``uint8`` and shape ``(H, W)`` (rows, columns),
  values in digital numbers (DN) 0..255, full range (0 = black, 255 = white).
* Frame ``k`` (0-based) of a video has presentation time ``k / fps`` seconds. Frame indices
  reported by the readers are derived from the presentation timestamp
  (``round((pts - start_time) * time_base * fps)``), so they are exact rather than counted.
* Videos are written as H.264 (``libx264``) or H.265 (``libx265``), ``yuv420p`` with the
  full-range flag set: the gray values go straight into the luma plane (no 16..235 range
  squeeze) and the chroma planes are constant 128. Width and height must be even.

Encoder settings are chosen so that separately encoded segments (same size, fps, codec, crf,
preset, gop) can be joined by :func:`concat_videos` with a pure stream copy: no B-frames
(``bframes=0``, so pts == dts and there is no reordering delay or edit list), closed GOPs,
every segment starts with an IDR keyframe, and the codec headers (SPS/PPS, VPS for H.265)
are fixed by the settings alone, so the extradata is byte-identical between segments.

A writer with ``recorder=True`` encodes as a recorder's hardware encoder does: keyframes only
where the caller asks for one (``write(frame, keyframe=True)``, an IDR) or ``gop`` frames after
the last one, never at a scene cut, and no x264 mb-tree / x265 cutree (a look-ahead that moves
bits between frames by how much later frames refer to them: it makes the last frames of each
GOP coarser than the rest, which put steps in the simulated volume before every keyframe).

Reading a few frames of a long video (:class:`SparseFrames`) decodes only what they need: a
frame that is a keyframe is decoded alone (after a seek, or with the decoder's
``skip_frame = "NONKEY"`` when every requested frame is one); any other from the keyframe at or
before it.
"""

from __future__ import annotations

import numbers
import os
from collections.abc import Iterable, Iterator, Sequence
from fractions import Fraction
from pathlib import Path
from types import TracebackType
from typing import Any

import av
import numpy as np

__all__ = [
    "CODECS",
    "DEFAULT_GOP",
    "SparseFrames",
    "VideoWriter",
    "concat_videos",
    "encode_video",
    "iter_frames",
    "keyframe_indices",
    "probe_video",
    "read_frame",
]

PathLike = str | os.PathLike[str]

#: Public codec names accepted by the writers, mapped to the FFmpeg encoder used.
CODECS: dict[str, str] = {"h264": "libx264", "h265": "libx265"}

#: Default maximum keyframe interval, in frames. Random access (``iter_frames(start=...)``)
#: decodes at most this many frames before the first requested one.
DEFAULT_GOP = 60

_AVCOL_RANGE_JPEG = 2  # AVColorRange value for full range (0..255)
_MP4_HEADER = 8  # bytes of an MP4 box header: 32-bit size, 4-character type (size 1: 64-bit size follows)
_RECOPY = "copy it again from the recorder"  # what a user can do about a damaged video


def _as_fps(fps: float | Fraction) -> Fraction:
    """Convert a frame rate in frames/s to an exact positive ``Fraction``.

    Floats are snapped to the nearest fraction with denominator <= 100000, so e.g.
    ``30000 / 1001`` round-trips to ``Fraction(30000, 1001)``.
    """
    if isinstance(fps, bool) or not isinstance(fps, numbers.Real):
        raise TypeError(f"fps must be a real number, got {type(fps).__name__}")
    if isinstance(fps, numbers.Rational):
        frac = Fraction(int(fps.numerator), int(fps.denominator))
    else:
        value = float(fps)
        if not np.isfinite(value):
            raise ValueError(f"fps must be finite, got {fps}")
        frac = Fraction(value).limit_denominator(100_000)
    if frac <= 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    return frac


ENCODER_THREADS = 1  # workflow jobs declare threads: 1; the encoder must not take every core


def _encoder_options(codec: str, crf: int, preset: str, gop: int, recorder: bool = False) -> dict[str, str]:
    """Encoder private options (x264/x265) for the given settings; see the module docstring.

    ``recorder``: no scene-cut keyframes (``scenecut=0``) and no x264 mb-tree / x265 cutree.
    ``forced-idr=1`` (an option of FFmpeg's wrappers, not of the stream: the headers are the
    same): a frame written with ``keyframe=True`` is an IDR, where a stream copy may cut."""
    tree = "mbtree" if codec == "h264" else "cutree"
    recorder_params = f":scenecut=0:{tree}=0" if recorder else ""
    if codec == "h264":
        # bframes=0: no reordering, pts == dts, no edit list, every packet is one frame.
        # open-gop=0 (x264 default, stated explicitly): segments start with a real IDR.
        params = f"bframes=0:keyint={gop}:open-gop=0:threads={ENCODER_THREADS}{recorder_params}"
        return {"crf": str(crf), "preset": preset, "forced-idr": "1", "x264-params": params}
    # x265 defaults to open GOP (CRA) and B-frames; turn both off, and keep it quiet.
    # info=0 drops x265's informational SEI from the headers: it lists every option incl.
    # the machine-dependent thread counts, which would make the extradata of segments encoded
    # on different machines differ (and concat_videos refuse them).
    params = (
        f"bframes=0:keyint={gop}:open-gop=0:info=0:log-level=error"
        f":pools={ENCODER_THREADS}:frame-threads={ENCODER_THREADS}{recorder_params}"
    )
    return {"crf": str(crf), "preset": preset, "forced-idr": "1", "x265-params": params}


class VideoWriter:
    """Write 8-bit grayscale frames to a video file (context manager).

    Frame ``k`` written gets pts ``k`` in time base ``1 / fps``, i.e. time ``k / fps`` s.
    The container is chosen from the file extension (use ``.mp4`` for :func:`concat_videos`).

    Args:
        path: output file path (parent directory must exist; an existing file is replaced).
        width: frame width W in pixels (even, > 0).
        height: frame height H in pixels (even, > 0).
        fps: frame rate in frames/s (> 0; int, float or Fraction).
        codec: ``"h264"`` (libx264) or ``"h265"`` (libx265).
        crf: constant rate factor, 0 (lossless for x264) .. 51; lower = better quality.
        preset: x264/x265 speed preset (e.g. ``"ultrafast"``, ``"veryfast"``, ``"medium"``).
        gop: maximum keyframe interval in frames (keyword only).
        recorder: encode as a recorder does (keyword only; module docstring): keyframes only
            where :meth:`write` is told or ``gop`` frames after the last, no mb-tree/cutree.

    Example::

        with VideoWriter("out.mp4", 640, 480, fps=30) as w:
            for img in frames:  # uint8 (480, 640)
                w.write(img)
    """

    def __init__(
        self,
        path: PathLike,
        width: int,
        height: int,
        fps: float | Fraction,
        codec: str = "h264",
        crf: int = 14,
        preset: str = "veryfast",
        *,
        gop: int = DEFAULT_GOP,
        recorder: bool = False,
    ) -> None:
        self.path = Path(path)
        if codec not in CODECS:
            raise ValueError(f"{self.path}: codec must be one of {sorted(CODECS)}, got {codec!r}")
        for name, value in (("width", width), ("height", height)):
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value <= 0:
                raise ValueError(f"{self.path}: {name} must be a positive int, got {value!r}")
            if value % 2:
                raise ValueError(f"{self.path}: {name} must be even for yuv420p, got {value}")
        if not 0 <= crf <= 51:
            raise ValueError(f"{self.path}: crf must be in 0..51, got {crf}")
        if gop < 1:
            raise ValueError(f"{self.path}: gop must be >= 1, got {gop}")
        self.width = int(width)
        self.height = int(height)
        self.fps = _as_fps(fps)
        self.codec = codec
        self.frames_written = 0
        self._time_base = 1 / self.fps
        # yuv420p staging buffer, shape (3H/2, W): luma rows on top, constant-128 chroma below.
        self._yuv = np.full((self.height * 3 // 2, self.width), 128, dtype=np.uint8)
        self._closed = False

        try:
            self._container: Any = av.open(str(self.path), mode="w")
        except (av.FFmpegError, OSError) as exc:
            raise ValueError(f"cannot open {self.path} for writing: {exc}") from exc
        try:
            stream = self._container.add_stream(
                CODECS[codec],
                rate=self.fps,
                options=_encoder_options(codec, int(crf), preset, int(gop), bool(recorder)),
            )
            stream.width = self.width
            stream.height = self.height
            stream.pix_fmt = "yuv420p"
            stream.time_base = self._time_base
            stream.codec_context.time_base = self._time_base
            stream.codec_context.color_range = _AVCOL_RANGE_JPEG
            # Open the encoder now so bad options fail here rather than on the first write.
            stream.codec_context.open()
        except av.FFmpegError as exc:
            self._container.close()
            raise ValueError(f"cannot set up {CODECS[codec]} encoder for {self.path}: {exc}") from exc
        except Exception:
            self._container.close()
            raise
        self._stream = stream

    def write(self, frame: np.ndarray, keyframe: bool = False) -> None:
        """Encode one grayscale frame, uint8 of shape ``(height, width)``; gets the next index.
        ``keyframe``: code it as an IDR keyframe (the first frame written always is one)."""
        if self._closed:
            raise ValueError(f"{self.path}: writer is closed")
        if not isinstance(frame, np.ndarray):
            raise ValueError(f"{self.path}: frame must be a numpy array, got {type(frame)}")
        if frame.dtype != np.uint8:
            raise ValueError(f"{self.path}: frame dtype must be uint8, got {frame.dtype}")
        if frame.shape != (self.height, self.width):
            raise ValueError(
                f"{self.path}: frame shape must be (H, W) = {(self.height, self.width)}, got {frame.shape}"
            )
        self._yuv[: self.height] = frame
        vf = av.VideoFrame.from_ndarray(self._yuv, format="yuv420p")  # copies the buffer
        vf.pts = self.frames_written
        vf.time_base = self._time_base
        vf.duration = 1
        vf.color_range = _AVCOL_RANGE_JPEG
        if keyframe:
            vf.pict_type = av.video.frame.PictureType.I  # with forced-idr=1: an IDR
        for packet in self._stream.encode(vf):
            self._container.mux(packet)
        self.frames_written += 1

    def close(self) -> None:
        """Flush the encoder (no frame is lost) and finalize the file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            for packet in self._stream.encode(None):
                self._container.mux(packet)
        finally:
            self._container.close()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def encode_video(
    frames: Iterable[np.ndarray],
    path: PathLike,
    fps: float | Fraction,
    codec: str = "h264",
    crf: int = 14,
    *,
    preset: str = "veryfast",
    gop: int = DEFAULT_GOP,
) -> int:
    """Encode grayscale frames (uint8, all of shape ``(H, W)``) to ``path``.

    The frame size is taken from the first frame; frames are consumed lazily (streaming).
    Frame ``k`` gets time ``k / fps`` s. Returns the number of frames written (>= 1).
    Raises ValueError if ``frames`` is empty or a frame has the wrong shape/dtype.
    """
    writer: VideoWriter | None = None
    try:
        for frame in frames:
            if writer is None:
                if not isinstance(frame, np.ndarray) or frame.ndim != 2:
                    raise ValueError(
                        f"{path}: frames must be 2-D (H, W) uint8 arrays, got "
                        f"{getattr(frame, 'shape', type(frame))}"
                    )
                h, w = frame.shape
                writer = VideoWriter(path, w, h, fps, codec=codec, crf=crf, preset=preset, gop=gop)
            writer.write(frame)
    finally:
        if writer is not None:
            writer.close()
    if writer is None:
        raise ValueError(f"{path}: no frames to encode")
    return writer.frames_written


# --------------------------------------------------------------------------- reading


def _open_input(path: PathLike) -> Any:
    """Open ``path``; FileNotFoundError / ValueError naming the file (empty, cut off) on failure."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"video file not found: {p}")
    if p.stat().st_size == 0:
        raise ValueError(
            f"{p}: the video file is empty (0 bytes): the recording or the copy failed; {_RECOPY}"
        )
    try:
        container = av.open(str(p), mode="r")
    except av.FFmpegError as exc:
        raise _unreadable(p, f"cannot read video {p}: {exc}") from exc
    if not container.streams.video:
        container.close()
        raise _unreadable(p, f"no video stream in {p}")
    return container


def _unreadable(p: Path, message: str) -> ValueError:
    """The error for a file FFmpeg cannot use: ``message``, unless it is a cut-off MP4."""
    damage = _mp4_damage(p)
    return ValueError(f"{p}: truncated video: {damage}; {_RECOPY}" if damage else message)


def _mp4_boxes(path: Path) -> list[tuple[str, int]]:
    """Top-level MP4 boxes: (type, declared end in bytes), up to a cut or impossible header."""
    size = path.stat().st_size
    boxes: list[tuple[str, int]] = []
    offset = 0
    with open(path, "rb") as f:
        while offset + _MP4_HEADER <= size:
            f.seek(offset)
            head = f.read(2 * _MP4_HEADER)
            n, kind = int.from_bytes(head[:4], "big"), head[4:8].decode("latin-1")
            if n == 1 and len(head) == 2 * _MP4_HEADER:
                n = int.from_bytes(head[8:], "big")
            elif n == 0:  # the box runs to the end of the file
                n = size - offset
            if n < _MP4_HEADER:
                break
            boxes.append((kind, offset + n))
            offset += n
    return boxes


def _mp4_damage(path: Path) -> str:
    """What a cut-off MP4 (first box ``ftyp``) lacks: its index (``moov``) and where it ends
    early; "" for a whole MP4 or another kind of file."""
    boxes = _mp4_boxes(path)
    if not boxes or boxes[0][0] != "ftyp":
        return ""
    size = path.stat().st_size
    problems = []
    if all(kind != "moov" for kind, _ in boxes):
        problems.append("it has no index (no MP4 'moov' box: a recorder writes it last)")
    kind, end = boxes[-1]
    if end > size:
        it = "" if problems else "it "
        problems.append(f"{it}ends at byte {size}, inside its {kind!r} box, which runs to byte {end}")
    return " and ".join(problems)


def _stream_fps(stream: Any, path: PathLike) -> Fraction:
    """Exact frame rate (frames/s) of a video stream: average rate, else guessed/base rate."""
    for rate in (stream.average_rate, stream.guessed_rate, stream.base_rate):
        if rate is not None and rate > 0:
            return Fraction(rate)
    raise ValueError(f"cannot determine the frame rate of {path}")


def _count_packets(container: Any, stream: Any) -> dict[str, int]:
    """Demux every packet of ``stream``: count whole (non-empty) ``packets``, ``keyframes``,
    ``without_pts`` and ``partial`` ones (the file ends inside: FFmpeg's corrupt flag)."""
    counts = {"packets": 0, "keyframes": 0, "without_pts": 0, "partial": 0}
    for packet in container.demux(stream):
        if packet.size == 0:
            continue  # the demuxer's end-of-stream flush packet
        if packet.is_corrupt:
            counts["partial"] += 1
            continue
        counts["packets"] += 1
        counts["keyframes"] += int(packet.is_keyframe)
        counts["without_pts"] += int(packet.pts is None)
    return counts


def probe_video(path: PathLike, *, index_only: bool = False) -> dict[str, Any]:
    """Describe the first video stream of ``path``, demuxing every packet (no decoding), and
    check the file against its own index.

    Returns a dict: ``path`` (str); ``frames`` (int, whole packets counted, one per frame);
    ``index_frames`` (int, the count the container's index claims, or None if it does not
    say); ``keyframes`` and ``packets_without_pts`` (int, counted); ``fps`` (float, frames/s);
    ``width``, ``height`` (int, pixels); ``codec`` (str, FFmpeg's name: ``"h264"``, ``"hevc"``);
    ``duration_s`` (float, seconds; ``frames / fps`` for CFR video).

    Raises FileNotFoundError (missing file) or ValueError naming the file, its own message for
    an empty file, a truncated one (no index, or one listing frames the file lacks: "faststart"
    MP4s cut short), no frames, no keyframe, or any other unreadable file. ``index_only``: trust
    the index, if any, without demuxing (parse time); ``keyframes``, ``packets_without_pts``: None.
    """
    p = Path(path)
    with _open_input(p) as container:
        stream = container.streams.video[0]
        fps = _stream_fps(stream, p)
        index_frames = int(stream.frames or 0) or None
        try:
            counts = (
                dict(packets=index_frames, keyframes=None, without_pts=None, partial=0)
                if index_only and index_frames
                else _count_packets(container, stream)
            )
        except av.FFmpegError as exc:
            raise ValueError(f"cannot read video {p}: {exc}") from exc
        frames = counts["packets"]
        if index_frames is not None and frames < index_frames:
            damage = _mp4_damage(p) or f"it has {p.stat().st_size} bytes"
            partial = " (and part of one more)" if counts["partial"] else ""
            raise ValueError(
                f"{p}: truncated video: its index lists {index_frames} frames but the file holds only "
                f"{frames}{partial}: {damage}; {_RECOPY}"
            )
        if frames == 0:
            raise ValueError(f"{p}: the video holds no frames (its video stream has no packets); {_RECOPY}")
        if counts["keyframes"] == 0:
            raise ValueError(f"{p}: none of its {frames} frames is a keyframe: none decodes; {_RECOPY}")
        duration_s = float(stream.duration * stream.time_base if stream.duration and stream.time_base
                           else frames / fps)  # fmt: skip
        ctx = stream.codec_context
        return {
            "path": str(p),
            "frames": frames,
            "index_frames": index_frames,
            "keyframes": counts["keyframes"],
            "packets_without_pts": counts["without_pts"],
            "fps": float(fps),
            "width": int(ctx.width),
            "height": int(ctx.height),
            "codec": str(ctx.name),
            "duration_s": duration_s,
        }


def _frame_index(pts: int, start: int, time_base: Fraction, fps: Fraction) -> int:
    """Frame index of a timestamp: ``round((pts - start) * time_base * fps)``."""
    return round((pts - start) * time_base * fps)


def iter_frames(path: PathLike, start: int = 0, stop: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """Stream decoded grayscale frames ``(k, frame)`` for ``start <= k < stop``.

    ``frame`` is uint8 of shape ``(H, W)``; ``k`` is the exact frame index derived from the
    pts (frame ``k`` is at ``k / fps`` s). For ``start > 0`` the reader seeks to the keyframe
    at or before frame ``start`` and decodes forward, dropping earlier frames. ``stop=None``
    reads to the end. Only one frame is held at a time (plus decoder buffers).

    The file's existence and the arguments are checked immediately (FileNotFoundError /
    ValueError); other read errors surface on iteration as ValueError naming the file.
    """
    if start < 0:
        raise ValueError(f"start must be >= 0, got {start}")
    if stop is not None and stop < 0:
        raise ValueError(f"stop must be >= 0 or None, got {stop}")
    if not Path(path).is_file():
        raise FileNotFoundError(f"video file not found: {path}")
    return _iter_frames(path, int(start), None if stop is None else int(stop))


_LUMA_FIRST = ("yuv420p", "yuvj420p", "nv12", "yuv422p", "yuvj422p", "yuv444p", "yuvj444p")  # 8-bit


def _gray(frame: Any) -> np.ndarray:
    """A decoded frame as grey levels (uint8, (H, W)). A full-range frame whose first plane is
    the 8-bit luma (the project's own videos) is that plane itself, read-only (the decoder may
    still predict from it; ``.copy()`` for an array of one's own): no conversion, no copy. Any
    other frame goes through ``to_ndarray(format="gray")``, which for limited-range video
    stretches 16..235 to 0..255, so that the values are the same either way."""
    name = frame.format.name
    full = name.startswith("yuvj") or frame.color_range == _AVCOL_RANGE_JPEG
    if name == "gray" or (name in _LUMA_FIRST and full):
        plane, h, w = frame.planes[0], frame.height, frame.width
        luma = np.frombuffer(plane, np.uint8, h * plane.line_size).reshape(h, plane.line_size)
        luma = luma[:, :w] if plane.line_size != w else luma
        luma.flags.writeable = False
        return luma
    return frame.to_ndarray(format="gray")


def _iter_frames(path: PathLike, start: int, stop: int | None) -> Iterator[tuple[int, np.ndarray]]:
    """The frames of :func:`iter_frames`, as :func:`_gray` gives them."""
    if stop is not None and stop <= start:
        return
    seek = start > 0
    while True:
        with _open_input(path) as container:
            stream = container.streams.video[0]
            stream.thread_type = "AUTO"
            fps = _stream_fps(stream, path)
            time_base = Fraction(stream.time_base)
            t0 = int(stream.start_time or 0)
            if seek:
                # Timestamp of frame `start` (floored); backward=True lands on the keyframe
                # at or before it.
                target = t0 + int(Fraction(start) / fps / time_base)
                try:
                    container.seek(target, stream=stream, backward=True)
                except av.FFmpegError:
                    seek = False  # unseekable: decode from the beginning instead
            first = True
            k = -1
            try:
                for frame in container.decode(stream):
                    if frame.pts is None:
                        k += 1  # no timestamp: assume the next frame
                    else:
                        k = _frame_index(frame.pts, t0, time_base, fps)
                    if first and seek and k > start:
                        break  # the seek overshot: retry from the beginning without seeking
                    first = False
                    if k < start:
                        continue
                    if stop is not None and k >= stop:
                        return
                    yield k, _gray(frame)
                else:
                    return
            except av.FFmpegError as exc:
                raise ValueError(f"error decoding {path}: {exc}") from exc
        seek = False


def read_frame(path: PathLike, index: int) -> np.ndarray:
    """Decode the single grayscale frame ``index`` (uint8, ``(H, W)``) of ``path``.

    Negative indices count from the end (uses :func:`probe_video`). Raises IndexError if the
    video has no frame with that index.
    """
    if index < 0:
        n = probe_video(path)["frames"]
        if index + n < 0:
            raise IndexError(f"frame index {index} out of range for {path} ({n} frames)")
        index += n
    for k, frame in iter_frames(path, index, index + 1):
        if k == index:
            return frame
    raise IndexError(f"frame index {index} not found in {path}")


# --------------------------------------------------------------------------- concatenation


def _segment_signature(path: PathLike) -> dict[str, Any]:
    """Stream parameters that must match for stream-copy concatenation; checks keyframe start."""
    with _open_input(path) as container:
        stream = container.streams.video[0]
        ctx = stream.codec_context
        sig = {
            "codec": ctx.name,
            "size": (int(ctx.width), int(ctx.height)),
            "pix_fmt": ctx.pix_fmt,
            "fps": _stream_fps(stream, path),
            "extradata": bytes(ctx.extradata or b""),
        }
        for packet in container.demux(stream):
            if packet.size > 0:
                if not packet.is_keyframe:
                    raise ValueError(f"segment {path} does not start with a keyframe")
                break
        else:
            raise ValueError(f"segment {path} has no video packets")
    return sig


def concat_videos(segments: Sequence[PathLike], out_path: PathLike) -> int:
    """Join video segments into one file by stream copy (no re-encoding); return frame count.

    The segments must have been encoded separately with identical settings (e.g. by
    :class:`VideoWriter` with the same size, fps, codec, crf, preset, gop); they are checked
    to share codec, size, pixel format, frame rate and codec extradata (SPS/PPS/VPS), and to
    start with a keyframe, before anything is written; a mismatch raises ValueError naming
    the offending file. Packets are re-timestamped so that segment ``i``'s frames follow
    segment ``i-1``'s: frame ``j`` of segment ``i`` becomes frame
    ``sum(len(segment) for earlier segments) + j`` at time ``that_index / fps`` s.
    The output container is chosen from ``out_path``'s extension (normally ``.mp4``).
    """
    if len(segments) == 0:
        raise ValueError("concat_videos: no segments given")
    out = Path(out_path)
    for seg in segments:
        if Path(seg).exists() and out.exists() and Path(seg).resolve() == out.resolve():
            raise ValueError(f"output {out} is also an input segment")

    ref = _segment_signature(segments[0])
    for seg in segments[1:]:
        sig = _segment_signature(seg)
        for key, label in (
            ("codec", "codec"),
            ("size", "frame size (W, H)"),
            ("pix_fmt", "pixel format"),
            ("fps", "frame rate"),
            ("extradata", "codec extradata (SPS/PPS: encoder settings)"),
        ):
            if sig[key] != ref[key]:
                shown = (
                    (f"{len(sig[key])} bytes", f"{len(ref[key])} bytes")
                    if key == "extradata"
                    else (sig[key], ref[key])
                )
                raise ValueError(
                    f"segment {seg} does not match {segments[0]}: {label} {shown[0]} != {shown[1]}"
                )

    fps: Fraction = ref["fps"]
    out_tb = 1 / fps
    n_packets = 0
    offset = 0  # index of the first frame of the current segment in the output
    try:
        with av.open(str(out), mode="w") as output:
            with _open_input(segments[0]) as first:
                ostream = output.add_stream_from_template(first.streams.video[0])
            ostream.time_base = out_tb
            for seg in segments:
                with _open_input(seg) as container:
                    stream = container.streams.video[0]
                    tb = Fraction(stream.time_base)
                    t0 = int(stream.start_time or 0)
                    seg_fps = _stream_fps(stream, seg)
                    last = -1
                    for packet in container.demux(stream):
                        if packet.size == 0 or (packet.pts is None and packet.dts is None):
                            continue  # demuxer's end-of-stream flush packet
                        pts = packet.pts if packet.pts is not None else packet.dts
                        dts = packet.dts if packet.dts is not None else pts
                        k_pts = _frame_index(pts, t0, tb, seg_fps)
                        k_dts = _frame_index(dts, t0, tb, seg_fps)
                        packet.stream = ostream
                        packet.time_base = out_tb
                        packet.pts = offset + k_pts
                        packet.dts = offset + k_dts
                        packet.duration = 1
                        output.mux(packet)
                        n_packets += 1
                        last = max(last, k_pts)
                    offset += last + 1
    except av.FFmpegError as exc:
        out.unlink(missing_ok=True)
        raise ValueError(f"concatenation into {out} failed: {exc}") from exc
    except BaseException:
        out.unlink(missing_ok=True)
        raise
    return n_packets


def keyframe_indices(path: PathLike, start: int = 0, stop: int | None = None) -> np.ndarray:
    """Frame indices (sorted, int64) of the keyframes (intra-coded frames) among frames
    ``start <= k < stop`` of ``path``'s first video stream, from its packets (demuxed, not
    decoded; from the keyframe at or before ``start``, so a chunk reads only its own part of a
    long video). ValueError naming the file if it cannot be read."""
    keys = _keyframes_from(Path(path), start, stop)
    return keys[keys >= start]


def _keyframes_from(p: Path, start: int, stop: int | None) -> np.ndarray:
    """The keyframes (sorted int64) of frames ``< stop`` from the one at or before ``start``
    (demuxed, not decoded), that one included."""
    keys = []
    with _open_input(p) as container:
        stream = container.streams.video[0]
        fps = _stream_fps(stream, p)
        tb = Fraction(stream.time_base)
        t0 = int(stream.start_time or 0)
        try:
            if start > 0:
                container.seek(t0 + int(Fraction(start) / fps / tb), stream=stream, backward=True)
            k = -1
            for packet in container.demux(stream):
                if packet.size == 0:
                    continue  # the demuxer's end-of-stream flush packet
                k = k + 1 if packet.pts is None else _frame_index(packet.pts, t0, tb, fps)
                if stop is not None and k >= stop:
                    break
                if packet.is_keyframe:
                    keys.append(k)
        except av.FFmpegError as exc:
            raise ValueError(f"cannot read video {p}: {exc}") from exc
    return np.unique(np.asarray(keys, np.int64))


class SparseFrames:
    """The decoded grey frames ``(j, frame)`` of a few frame indices of a video, in order,
    decoding as few frames as they need (module docstring).

    ``frame`` is as :func:`iter_frames` gives it (uint8 (H, W), read-only). The keyframes from
    the one at or before the first index are listed first (demuxed, not decoded). Then, if the
    indices are every keyframe from the first, only keyframes are decoded (``skip_frame =
    "NONKEY"``, after one seek to the first); otherwise, per GOP that holds wanted frames, one
    seek to its keyframe and one pass decoding on to its last wanted frame, the frames in
    between decoded and dropped (the next P frame is predicted from them). ``decoded`` counts
    every frame the decoder gave (the cost: at least ``len(indices)``), ``seeks`` the seeks.

    Args:
        path: the video.
        indices: the frame indices wanted (int, >= 0; sorted and made unique here).

    FileNotFoundError for a missing file; ValueError naming the file if it cannot be read or
    lacks a requested frame.
    """

    def __init__(self, path: PathLike, indices: Iterable[int]) -> None:
        self.path = Path(path)
        self.indices = np.unique(np.asarray(list(indices), np.int64))
        if len(self.indices) and self.indices[0] < 0:
            raise ValueError(f"{self.path}: frame indices must be >= 0, got {self.indices[0]}")
        if not self.path.is_file():
            raise FileNotFoundError(f"video file not found: {self.path}")
        self.decoded = 0
        self.seeks = 0

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        if not len(self.indices):
            return
        wanted = self.indices
        keys = _keyframes_from(self.path, int(wanted[0]), int(wanted[-1]) + 1)
        with _open_input(self.path) as container:
            stream = container.streams.video[0]
            # no frame threading: it decodes packets ahead of each frame it gives, which a seek
            # then throws away (on the slow test's 720p H.264 the 49 frames of 20 GOPs took 1.39 s
            # with "AUTO", 0.91 s with "SLICE")
            stream.thread_type = "SLICE"
            clock = (_stream_fps(stream, self.path), Fraction(stream.time_base), int(stream.start_time or 0))
            try:
                if np.array_equal(wanted, keys[keys >= wanted[0]]):  # every keyframe, nothing else
                    stream.codec_context.skip_frame = "NONKEY"
                    yield from self._decode(container, stream, clock, wanted, int(wanted[0]))
                    return
                # one pass per GOP that holds wanted frames: seek to its keyframe, decode on
                gop = np.searchsorted(keys, wanted, side="right") - 1  # the GOP of each
                if (gop < 0).any():
                    raise ValueError(f"{self.path}: no keyframe at or before frame {int(wanted[0])}")
                for g in np.unique(gop):
                    yield from self._decode(container, stream, clock, wanted[gop == g], int(keys[g]))
            except av.FFmpegError as exc:
                raise ValueError(f"error decoding {self.path}: {exc}") from exc

    def _decode(
        self, container: Any, stream: Any, clock: tuple, wanted: np.ndarray, seek_to: int
    ) -> Iterator[tuple[int, np.ndarray]]:
        """The ``wanted`` (sorted) frames, decoding on from a seek to keyframe ``seek_to``
        (PyAV's seek flushes the decoder)."""
        fps, tb, t0 = clock
        container.seek(t0 + int(Fraction(seek_to) / fps / tb), stream=stream, backward=True)
        self.seeks += 1
        n = 0
        k = -1
        for frame in container.decode(stream):
            self.decoded += 1
            if frame.pts is None:
                raise ValueError(f"{self.path}: a frame without a timestamp: read it with iter_frames")
            k = _frame_index(frame.pts, t0, tb, fps)
            if k > wanted[n]:
                break
            if k == wanted[n]:
                yield k, _gray(frame)
                n += 1
                if n == len(wanted):
                    return
        raise ValueError(f"{self.path}: no frame {int(wanted[n])} (decoding reached frame {k})")
