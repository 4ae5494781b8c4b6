"""Joining separately encoded video segments into one file by stream copy (:func:`concat_videos`)."""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import av

from triaxtrack.video.probe import PathLike, _frame_index, _open_input, _stream_fps


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
