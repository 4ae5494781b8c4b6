"""Opening a video file, and what it holds: ``FileNotFoundError`` / ``ValueError`` naming the file
(for a cut-off MP4, what it lacks), a stream's exact frame rate, the frame index of a timestamp
(``round((pts - start_time) * time_base * fps)``), and :func:`probe_video`, which checks a file
against its own index by demuxing every packet (no decoding)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from fractions import Fraction
from pathlib import Path
from typing import Any

import av

PathLike = str | os.PathLike[str]

_AVCOL_RANGE_JPEG = 2  # AVColorRange value for full range (0..255)
_MP4_HEADER = 8  # bytes of an MP4 box header: 32-bit size, 4-character type (size 1: 64-bit size follows)
_RECOPY = "copy it again from the recorder"  # what a user can do about a damaged video


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
            counts: Mapping[str, int | None] = (
                dict(packets=index_frames, keyframes=None, without_pts=None, partial=0)
                if index_only and index_frames
                else _count_packets(container, stream)
            )
        except av.FFmpegError as exc:
            raise ValueError(f"cannot read video {p}: {exc}") from exc
        frames = int(counts["packets"] or 0)  # (an int in both branches)
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
