"""Reading a few frames of a long video (:class:`SparseFrames`) decodes only what they need: a
frame that is a keyframe is decoded alone (after a seek, or with the decoder's
``skip_frame = "NONKEY"`` when every requested frame is one); any other from the keyframe at or
before it. Where the keyframes are comes from the packets, demuxed, not decoded
(:func:`keyframe_indices`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from fractions import Fraction
from pathlib import Path
from typing import Any

import av
import numpy as np

from triaxtrack.video.probe import PathLike, _frame_index, _open_input, _stream_fps
from triaxtrack.video.read import _gray


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

    ``frame`` is as :func:`~triaxtrack.video.read.iter_frames` gives it (uint8 (H, W), read-only).
    The keyframes from the one at or before the first index are listed first (demuxed, not
    decoded). Then, if the indices are every keyframe from the first, only keyframes are decoded
    (``skip_frame = "NONKEY"``, after one seek to the first); otherwise, per GOP that holds
    wanted frames, one seek to its keyframe and one pass decoding on to its last wanted frame,
    the frames in between decoded and dropped (the next P frame is predicted from them).
    ``decoded`` counts every frame the decoder gave (the cost: at least ``len(indices)``),
    ``seeks`` the seeks.

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
