"""Which frame of a camera's video shows test frame k (the frame map), and reading by test frame.

The clocks (times in seconds):

* test frame ``k`` (0, 1, ..., ``frames - 1``) is at time ``k / fps`` on the test clock, ``fps``
  being test.yaml's frame rate;
* test.yaml may give per camera ``start_offset_s``: the test-clock time of the camera's first
  recorded frame (positive: the camera started late; negative: it started early), default 0;
* and ``dropped_frames``: the camera's nominal frame numbers ``n`` (0-based, counted as if
  nothing had been dropped) that are absent from its video file, default none.

So nominal frame ``n`` was taken at test-clock time ``start_offset_s + n / fps`` and is test
frame ``k = n + m``, ``m = round(start_offset_s * fps)``; the video file holds the nominal
frames that were not dropped, in order, so nominal frame ``n`` is file index
``j = n - (number of dropped frames < n)``. A test frame has no video frame when ``n < 0``
(``before_start``), when ``n`` is dropped (``dropped``, even past the end of the file: the
recorder logged it), or when ``j`` is beyond the last frame of the file (``after_end``).
Nominal frames before test frame 0 (a camera that started early) are simply not used.

A camera whose ``start_offset_s * fps`` is more than ``SUBFRAME_TOL_FRAMES`` from an integer
records between the test frames: it is mapped to the nearest test frame, a warning says so,
and the map's ``video_time_s`` (the test-clock time the video frame was taken) differs from
``time_s`` by the residual ``start_offset_s - m / fps``.

The frame map is a table (:data:`triaxtrack.tables.FRAME_MAP`), one row per test frame:
``frame`` (int, k), ``time_s`` (k / fps), ``video_index`` (int, j; -1 when missing),
``missing`` (bool), ``reason`` (``before_start``, ``dropped``, ``after_end`` or ``''``),
``video_time_s`` (NaN when missing). Rule frame_map writes it (:func:`run_frame_map`).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.tables import FRAME_MAP, conform, write_table
from triaxtrack.testfolder import read_test_cameras, read_test_frames
from triaxtrack.video import SparseFrames, iter_frames, keyframe_indices, probe_video

SUBFRAME_TOL_FRAMES = 0.05  # |start_offset_s * fps - m| above this: the camera is off the test frames
REASONS = ("before_start", "dropped", "after_end")


@dataclass(frozen=True)
class CameraTiming:
    """A camera's clock relative to the test clock (module docstring); seconds, frames/s."""

    camera: str
    fps: float
    start_offset_s: float = 0.0
    dropped_frames: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if not self.fps > 0:
            raise ValueError(f"camera {self.camera}: fps must be positive, not {self.fps}")
        if not np.isfinite(self.start_offset_s):
            raise ValueError(f"camera {self.camera}: start_offset_s must be finite")
        drops = list(self.dropped_frames)
        if any(int(n) != n or n < 0 for n in drops) or len(set(drops)) != len(drops):
            raise ValueError(
                f"camera {self.camera}: dropped_frames must be distinct frame numbers >= 0, not {drops}"
            )
        object.__setattr__(self, "dropped_frames", tuple(sorted(int(n) for n in drops)))

    @property
    def offset_frames(self) -> int:
        """m: the test frame of the camera's nominal frame 0 (rounded to the nearest)."""
        return round(self.start_offset_s * self.fps)

    @property
    def offset_residual_s(self) -> float:
        """``start_offset_s - m / fps``: how far the camera's frames are from the test frames."""
        return self.start_offset_s - self.offset_frames / self.fps

    @property
    def subframe(self) -> bool:
        """True when the offset is not a whole number of frames (within ``SUBFRAME_TOL_FRAMES``)."""
        return abs(self.offset_residual_s * self.fps) > SUBFRAME_TOL_FRAMES


def read_camera_timing(test_yaml: str | Path, camera: str) -> CameraTiming:
    """The timing of one camera from a test.yaml (cameras given as names or mappings);
    ValueError naming the file when it is unreadable or does not list the camera."""
    path = Path(test_yaml)
    fps, entries = read_test_cameras(path)
    entry = next((c for c in entries if c.get("name") == camera), None)
    if entry is None:
        raise ValueError(f"{path}: camera {camera!r} is not listed in cameras")
    try:
        return CameraTiming(
            camera,
            fps,
            float(entry.get("start_offset_s", 0.0)),
            tuple(entry.get("dropped_frames", ()) or ()),
        )
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: {err}") from err


def count_test_frames(test_yaml: str | Path, video: str | Path | None = None) -> int:
    """The number of test frames: test.yaml's ``frames``, else the frame count of ``video``
    (the workflow passes the first camera's, as its chunking does); ValueError naming the file
    when neither is there."""
    path = Path(test_yaml)
    frames = read_test_frames(path)
    if frames is not None:
        return frames
    if video is None:
        raise ValueError(f"{path}: no `frames`, and no video to count the test frames in")
    return int(probe_video(video)["frames"])


def frame_map(timing: CameraTiming, frames: int, video_frames: int) -> pd.DataFrame:
    """The frame map of one camera for test frames ``0 .. frames - 1`` (module docstring).

    ``video_frames``: the number of frames in the camera's video file. Warns (UserWarning)
    when the camera's offset is not a whole number of frames.
    """
    if frames < 0 or video_frames < 0:
        raise ValueError(f"camera {timing.camera}: frame counts must be >= 0 ({frames}, {video_frames})")
    if timing.subframe:
        warnings.warn(
            f"camera {timing.camera}: start_offset_s = {timing.start_offset_s} s is "
            f"{timing.start_offset_s * timing.fps:.3f} frames, not a whole number; mapped to "
            f"{timing.offset_frames} frames, residual {timing.offset_residual_s:+.4f} s",
            stacklevel=2,
        )
    k = np.arange(frames, dtype=np.int64)
    n = k - timing.offset_frames
    drops = np.asarray(timing.dropped_frames, np.int64)
    j = n - np.searchsorted(drops, n, side="left")  # dropped frames before n
    dropped = np.isin(n, drops)
    reason = np.full(frames, "", dtype=object)
    reason[(j >= video_frames) & ~dropped] = "after_end"
    reason[dropped] = "dropped"
    reason[n < 0] = "before_start"
    missing = reason != ""
    df = pd.DataFrame({
        "frame": k,
        "time_s": k / timing.fps,
        "video_index": np.where(missing, -1, j),
        "missing": missing,
        "reason": reason,
        "video_time_s": np.where(missing, np.nan, timing.start_offset_s + n / timing.fps),
    })  # fmt: skip
    return conform(df, FRAME_MAP, f"frame map of {timing.camera}")


def summarize_frame_map(fmap: pd.DataFrame) -> dict:
    """Counts of a frame map: frames, present, and missing by reason."""
    counts = fmap.loc[fmap.missing, "reason"].value_counts()
    return {
        "frames": len(fmap),
        "present": int((~fmap.missing).sum()),
        **{reason: int(counts.get(reason, 0)) for reason in REASONS},
    }


def _rows(fmap: pd.DataFrame, frames: Sequence[int]) -> pd.DataFrame:
    rows = fmap.set_index("frame").reindex(list(frames))
    unknown = rows.index[rows["missing"].isna()].tolist()
    if unknown:
        raise ValueError(f"test frames {unknown[:5]} are not in the frame map (frames 0..{len(fmap) - 1})")
    return rows


def iter_test_frames(
    video_path: str | Path, fmap: pd.DataFrame, start: int, stop: int
) -> Iterator[tuple[int, np.ndarray | None]]:
    """``(k, image)`` for test frames ``start <= k < stop``, in order: the camera's decoded
    grey frame (uint8, (H, W)) or None where the frame map says it is missing.

    Decodes once, forwards from the keyframe before the first needed video frame
    (:func:`triaxtrack.video.iter_frames`), holding one frame at a time. ValueError naming the
    file if the video lacks a frame the map expects (the map does not belong to this video).
    """
    rows = _rows(fmap, range(start, stop))
    wanted = rows.loc[~rows["missing"].astype(bool), "video_index"].astype(np.int64)
    return _iter_test_frames(Path(video_path), rows, wanted)


def _iter_test_frames(
    video_path: Path, rows: pd.DataFrame, wanted: pd.Series
) -> Iterator[tuple[int, np.ndarray | None]]:
    video = iter(()) if wanted.empty else iter_frames(video_path, int(wanted.min()), int(wanted.max()) + 1)
    for k, row in zip(rows.index, rows.itertuples(index=False), strict=True):
        if row.missing:
            yield int(k), None
            continue
        for j, image in video:
            if j == row.video_index:
                yield int(k), image
                break
            if j > row.video_index:
                raise ValueError(f"{video_path}: no video frame {row.video_index} (test frame {k})")
        else:
            raise ValueError(
                f"{video_path}: the video ends before frame {row.video_index} (test frame {k}); "
                "the frame map does not match this video"
            )


class ProcessedTestFrames:
    """``(k, image)`` for test frames ``start <= k < stop``, in order, decoding only the
    ``processed`` ones (and ``start``, the labelled frame): image is the camera's grey frame
    (uint8, (H, W), read-only) for those the camera recorded, None for every other frame (not
    decoded, or missing: the tracker follows its targets across them by their velocity).

    The fast mode of tracking (``tracking.step_s`` with ``fast``): the frames are decoded by
    :class:`triaxtrack.video.SparseFrames` (a keyframe alone, any other frame from the keyframe
    at or before it), so with processed frames on keyframes the cost is one decoded frame per
    processed frame. ``decoded`` and ``seeks``: the decoder's counts so far. ValueError naming
    the file, as :func:`iter_test_frames`, if the video lacks a frame the map expects.
    """

    def __init__(
        self,
        video_path: str | Path,
        fmap: pd.DataFrame,
        start: int,
        stop: int,
        processed: Sequence[int] | np.ndarray,
    ) -> None:
        self.rows = _rows(fmap, range(start, stop))
        keep = self.rows.index.isin(np.r_[np.asarray(processed, np.int64), start])
        rec = self.rows[keep & ~self.rows["missing"].astype(bool)]
        # test frame -> video index (both increasing: the frame map is in order)
        self._video = dict(zip(rec.index.astype(int), rec["video_index"].astype(int), strict=True))
        self._reader = SparseFrames(video_path, self._video.values())

    @property
    def decoded(self) -> int:
        return self._reader.decoded

    @property
    def seeks(self) -> int:
        return self._reader.seeks

    def __iter__(self) -> Iterator[tuple[int, np.ndarray | None]]:
        pictures = iter(self._reader)
        for k in self.rows.index.astype(int):
            if k not in self._video:
                yield k, None
                continue
            j, image = next(pictures)
            if j != self._video[k]:  # SparseFrames yields exactly its indices, in order
                raise ValueError(f"{self._reader.path}: decoded frame {j} for test frame {k}")
            yield k, image


def read_test_frame(video_path: str | Path, fmap: pd.DataFrame, frame: int) -> np.ndarray | None:
    """The camera's grey image of test frame ``frame`` (uint8, (H, W)), or None if missing."""
    for _, image in iter_test_frames(video_path, fmap, frame, frame + 1):
        return image
    raise ValueError(f"{video_path}: test frame {frame} not read")  # unreachable: one row exists


def keyframe_test_frames(video_path: str | Path, fmap: pd.DataFrame, start: int, stop: int) -> np.ndarray:
    """The test frames ``start <= k < stop`` (sorted) whose picture is one of the video's
    keyframes (:func:`triaxtrack.video.keyframe_indices`, demuxing only that part of the video)."""
    rows = _rows(fmap, range(start, stop))
    rec = rows[~rows["missing"].astype(bool)]
    if rec.empty:
        return np.zeros(0, np.int64)
    video = rec["video_index"].astype(np.int64)
    keys = keyframe_indices(video_path, int(video.min()), int(video.max()) + 1)
    return np.sort(rec.index[video.isin(keys)].to_numpy(np.int64))


def run_frame_map(
    *,
    camera: str,
    video: str | Path,
    test_yaml: str | Path,
    frame_count_video: str | Path | None,
    frames: str | Path,
) -> None:
    """Rule frame_map: the frame map of ``camera`` (its timing in ``test_yaml``, its ``video``'s
    frame count) over the test's frames (test.yaml's ``frames``, else ``frame_count_video``'s;
    :func:`count_test_frames`), written to ``frames``; prints a summary. A camera off the test
    frames is warned about (:func:`frame_map`)."""
    timing = read_camera_timing(test_yaml, camera)
    n = count_test_frames(test_yaml, frame_count_video or None)
    fmap = frame_map(timing, n, probe_video(video)["frames"])
    write_table(fmap, frames, FRAME_MAP)
    print(f"{timing.camera}: {summarize_frame_map(fmap)}, offset residual {timing.offset_residual_s:+.4f} s")
