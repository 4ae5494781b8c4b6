"""Inventory of a recorded test: what each camera's video holds, and which cameras disagree; the
workflow's stages, one video probed (:func:`run_probe_video`) and the probes summarised
(:func:`run_inventory`)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from triaxtrack.jsonfile import read_json, write_json
from triaxtrack.layout import TEST_FOLDER

FPS_REL_TOL = 1e-3  # container frame rates are rationals; 1e-3 absorbs 30000/1001 vs 29.97


def summarize_probes(test: dict, probes: list[dict], name: str, *, strict: bool = True) -> dict:
    """Summarise per-camera video probes (:func:`triaxtrack.video.probe_video`) of a test.

    ``test`` is the validated ``test.yaml`` with ``cameras`` as a list of mappings (``name``,
    optional ``start_offset_s`` and ``dropped_frames``), in the order of ``probes``. The expected
    frame count is test.yaml's ``frames`` if given, else the most common count (ties: the larger);
    the expected frame size is the most common one (ties: the larger).

    Cameras whose frame count, frame rate or size differ are flagged (``flags``). A frame count
    may differ for a reason (a late start, dropped frames: see the frame maps); a frame rate
    other than test.yaml's ``fps``, or a frame size other than the other cameras', is a fault:
    each gets a message naming the video file (``problems``, per camera and in one list), and
    with ``strict`` (the default) a ValueError listing them all.
    """
    counts = Counter(p["frames"] for p in probes)
    if "frames" in test:
        expected_frames, frames_source = test["frames"], TEST_FOLDER.test_yaml
    else:
        expected_frames = max(counts, key=lambda n: (counts[n], n))
        frames_source = "most common among the videos"
    sizes = Counter((p["width"], p["height"]) for p in probes)
    expected_size = max(sizes, key=lambda s: (sizes[s], s))
    cameras = []
    for camera, probe in zip(test["cameras"], probes, strict=True):
        flags, problems = [], []
        video = probe.get("path", f"the video of camera {camera['name']}")
        if probe["frames"] != expected_frames:
            flags.append("frame_count_differs")
        if (rate := fps_problem(video, probe["fps"], test["fps"])) is not None:
            flags.append("fps_differs")
            problems.append(rate)
        if (probe["width"], probe["height"]) != expected_size:
            flags.append("size_differs")
            problems.append(
                f"{video}: frame size {probe['width']}x{probe['height']} pixels, but "
                f"{sizes[expected_size]} of the {len(probes)} cameras' videos are "
                f"{expected_size[0]}x{expected_size[1]}"
            )
        cameras.append({
            "camera": camera["name"],
            **probe,
            "start_offset_s": camera.get("start_offset_s", 0.0),
            "dropped_frames": len(camera.get("dropped_frames", [])),
            "flags": flags,
            "problems": problems,
        })  # fmt: skip
    problems = [p for c in cameras for p in c["problems"]]
    if strict and problems:
        raise ValueError(
            f"test {name!r}: {len(problems)} video(s) do not match the test:\n  " + "\n  ".join(problems)
        )
    return {
        "test": name,
        "fps": test["fps"],
        "frames": expected_frames,
        "frames_source": frames_source,
        "width": expected_size[0],
        "height": expected_size[1],
        "cameras": cameras,
        "frame_count_differs": [c["camera"] for c in cameras if "frame_count_differs" in c["flags"]],
        "flagged": [c["camera"] for c in cameras if c["flags"]],
        "problems": problems,
    }


def video_problem(path: str | Path, fps: float | None = None) -> str | None:
    """Why the video at ``path`` cannot be measured, in words naming the file (missing, empty,
    truncated, no frames, not a video, or a frame rate other than test.yaml's ``fps``
    (:func:`fps_problem`): :func:`triaxtrack.video.probe_video` on its index, so a few
    milliseconds at parse time, before any job runs), or None if it can be read."""
    from triaxtrack.video import probe_video

    try:
        info = probe_video(path, index_only=True)
    except (OSError, ValueError) as exc:
        return str(exc)
    return None if fps is None else fps_problem(path, info["fps"], fps)


def fps_problem(video: str | Path, fps: float, expected: float) -> str | None:
    """The message naming ``video`` whose frame rate ``fps`` is not test.yaml's ``expected``
    (within ``FPS_REL_TOL``), or None."""
    if abs(fps - expected) <= FPS_REL_TOL * expected:
        return None
    return f"{video}: frame rate {fps:.6g} frames/s, but test.yaml gives fps: {expected:g}"


def usable_cameras(
    videos: dict[str, str | Path], on_bad_camera: str = "skip", min_cameras: int = 8, source: str = "test",
    fps: float | None = None,
) -> tuple[list[str], dict[str, str]]:  # fmt: skip
    """``(cameras kept, {camera left out: why})`` of a recorded test from its cameras' videos
    (``{camera: path}``, in test.yaml's order): a camera whose video cannot be read, or whose
    frame rate is not test.yaml's ``fps`` (:func:`video_problem`) is left out with
    ``on_bad_camera="skip"``; with ``"fail"``, or when
    cameras are left out and fewer than ``min_cameras`` are kept (a test recorded with fewer,
    all readable, is measured with them), or fewer than two are kept, ValueError naming
    ``source`` and every camera left out and why."""
    problems = {camera: p for camera, path in videos.items() if (p := video_problem(path, fps)) is not None}
    kept = [camera for camera in videos if camera not in problems]
    listed = "".join(f"\n  {camera}: {why}" for camera, why in problems.items())
    if problems and on_bad_camera == "fail":
        raise ValueError(f"{source}: camera video(s) cannot be read (on_bad_camera: fail):{listed}")
    if len(kept) < (min_cameras if problems else 2):
        raise ValueError(f"{source}: only {len(kept)} of {len(videos)} cameras can be measured, fewer than "
                         f"min_cameras ({min_cameras}) or 2; left out:{listed or ' none'}")  # fmt: skip
    return kept, problems


def run_probe_video(*, video: str | Path, probe: str | Path) -> None:
    """Rule probe_video: :func:`triaxtrack.video.probe_video` of one recorded ``video`` (every
    packet demuxed and checked against the index: ValueError naming a broken file), written to
    ``probe`` as JSON (keys sorted); prints a one-line description."""
    from triaxtrack.video import probe_video

    info = probe_video(video)
    write_json(probe, info, sort_keys=True)
    print(f"{info['path']}: {info['frames']} frames ({info['keyframes']} keyframes), {info['fps']:.6g} fps, "
          f"{info['width']}x{info['height']}, {info['codec']}")  # fmt: skip


def run_inventory(*, probes: Sequence[str | Path], inventory: str | Path, test: dict, name: str) -> None:
    """Rule inventory: :func:`summarize_probes` of the recorded test ``name`` (``test``: its
    validated test.yaml) from its cameras' ``probes`` (rule probe_video), stamped with the
    package's version and written to ``inventory`` (JSON); prints a line per camera."""
    from triaxtrack import __version__

    summary = summarize_probes(test, [read_json(path, "video probe") for path in probes], name)
    summary = {**summary, "triaxtrack_version": __version__}
    write_json(inventory, summary)
    for c in summary["cameras"]:
        print(f"{c['camera']}: {c['frames']} frames, {c['fps']:.3f} fps, {c['flags'] or 'ok'}")
