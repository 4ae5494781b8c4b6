"""Decoding grayscale frames: a range of them (:func:`iter_frames`, seeking to the keyframe at or
before the first) or one (:func:`read_frame`)."""

from __future__ import annotations

from collections.abc import Iterator
from fractions import Fraction
from pathlib import Path
from typing import Any

import av
import numpy as np

from triaxtrack.video.probe import (
    _AVCOL_RANGE_JPEG,
    PathLike,
    _frame_index,
    _open_input,
    _stream_fps,
    probe_video,
)


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
