"""Writing 8-bit grayscale frames as H.264 / H.265 video (:class:`VideoWriter`, :func:`encode_video`).

Encoder settings are chosen so that separately encoded segments (same size, fps, codec, crf,
preset, gop) can be joined by :func:`~triaxtrack.video.concat.concat_videos` with a pure stream
copy: no B-frames (``bframes=0``, so pts == dts and there is no reordering delay or edit list),
closed GOPs, every segment starts with an IDR keyframe, and the codec headers (SPS/PPS, VPS for
H.265) are fixed by the settings alone, so the extradata is byte-identical between segments.

A writer with ``recorder=True`` encodes as a recorder's hardware encoder does: keyframes only
where the caller asks for one (``write(frame, keyframe=True)``, an IDR) or ``gop`` frames after
the last one, never at a scene cut, and no x264 mb-tree / x265 cutree (a look-ahead that moves
bits between frames by how much later frames refer to them: it makes the last frames of each
GOP coarser than the rest, which put steps in the simulated volume before every keyframe).
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable
from fractions import Fraction
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

import av
import numpy as np

from triaxtrack.video.probe import _AVCOL_RANGE_JPEG, PathLike

#: Public codec names accepted by the writers, mapped to the FFmpeg encoder used.
CODECS: dict[str, Literal["libx264", "libx265"]] = {"h264": "libx264", "h265": "libx265"}

#: Default maximum keyframe interval, in frames. Random access (``iter_frames(start=...)``)
#: decodes at most this many frames before the first requested one.
DEFAULT_GOP = 60


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
    The container is chosen from the file extension (use ``.mp4`` for
    :func:`~triaxtrack.video.concat.concat_videos`).

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
