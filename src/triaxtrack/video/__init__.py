"""Video I/O for 8-bit grayscale frames, through PyAV only (no system ffmpeg).

Conventions used throughout this package:

* A frame is a ``numpy.ndarray`` of dtype ``uint8`` and shape ``(H, W)`` (rows, columns),
  values in digital numbers (DN) 0..255, full range (0 = black, 255 = white).
* Frame ``k`` (0-based) of a video has presentation time ``k / fps`` seconds. Frame indices
  reported by the readers are derived from the presentation timestamp
  (``round((pts - start_time) * time_base * fps)``), so they are exact rather than counted.
* Videos are written as H.264 (``libx264``) or H.265 (``libx265``), ``yuv420p`` with the
  full-range flag set: the gray values go straight into the luma plane (no 16..235 range
  squeeze) and the chroma planes are constant 128. Width and height must be even.

Modules:

* :mod:`~triaxtrack.video.probe`: opening a file (errors naming it, and what a cut-off MP4
  lacks), a stream's frame rate and the frame index of a timestamp, and :func:`probe_video`;
* :mod:`~triaxtrack.video.write`: :class:`VideoWriter` and :func:`encode_video`, with encoder
  settings that let separately encoded segments be joined by stream copy;
* :mod:`~triaxtrack.video.read`: :func:`iter_frames` and :func:`read_frame`;
* :mod:`~triaxtrack.video.concat`: :func:`concat_videos` (stream copy, no re-encoding);
* :mod:`~triaxtrack.video.sparse`: a few frames of a long video, decoding only what they need
  (:class:`SparseFrames`, :func:`keyframe_indices`).
"""

from triaxtrack.video.concat import concat_videos
from triaxtrack.video.probe import probe_video
from triaxtrack.video.read import iter_frames, read_frame
from triaxtrack.video.sparse import SparseFrames, keyframe_indices
from triaxtrack.video.write import CODECS, DEFAULT_GOP, VideoWriter, encode_video

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
