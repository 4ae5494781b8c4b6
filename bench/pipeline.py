"""Benchmarks that print figures (they assert nothing): ``python bench/pipeline.py [what ...]``, or
``make bench BENCH_ARGS="[what ...] [options]"``.

``tracking`` (the default): the first ``--frames`` frames (default 72) of one camera of a simulated
``--test-frames``-frame test (default 100, as the workflow's demo: the dots move as fast per frame)
are rendered at ``--size`` (default 3840x2160) and written as H.264 (the simulation defaults: crf 14,
veryfast, as a recorder: a keyframe every ``--gop`` frames, default 6), and the same frames
re-encoded as H.265 (``--codecs``; all in a child process); this prints

* per codec, the decode-only frame rate (decoding to grey frames as the pipeline does,
  :func:`triaxtrack.frames.iter_test_frames`), and the whole pipeline's (decoding and
  :func:`triaxtrack.track.track_frames` on the same stream, from the first frame's labels of
  :func:`triaxtrack.identify.label_frame`, with the kit's membrane grid for completion as the
  workflow's default ``tracking.complete_grid`` has it), and their ratio (the tracker's compiled kernels are
  loaded, or compiled, before any timing: once per process);
* the tracking cost per camera-frame beyond decoding: (pipeline - decode) / frames, and timed
  directly on a few frames held in memory (``--hold``), with the share of ``_step`` and
  ``measure_targets``;
* per codec, the cost per processed frame in fast mode (processed frames on every keyframe, one
  step a GOP: :class:`triaxtrack.frames.ProcessedTestFrames` and ``track_frames``, the frames
  decoded counted) against every-frame mode (the pipeline's time over the same processed
  frames), and how far apart their centroids are at the processed frames;
* from those per-frame costs, the wall time to track a 3.3 h test of 16 cameras at 15 fps (at
  the bench's frame size) on 2 and on 64 cores: every frame, and one frame per 2 s (fast mode;
  every-frame mode costs as much as every frame);
* the brute-force alternative: ``label_frame`` (detection and identification) on every frame;
* the same linking step by trackpy (``trackpy.link`` on every frame's ``detect_blobs``; optional:
  ``pip install -e '.[bench]'``), with how many of its links break or swap our IDs;
* the peak memory of this process (and of each stage), and per workflow rule the largest
  ``max_rss`` in Snakemake's benchmark files (``benchmarks/<test>/<rule>...tsv``).

``simulate``: seconds per camera-frame to render and encode a simulated test, per ``--sizes``.
``identify``: seconds to detect and label every target of one frame (one core), per ``--sizes``,
with the number of targets labelled (frames rendered by the simulator, exact truth cameras).
"""

from __future__ import annotations

import argparse
import itertools
import resource
import subprocess
import sys
import tempfile
import time
import tracemalloc
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    from triaxtrack.track import TrackingConfig

KIT_DESIGN = Path(__file__).resolve().parents[1] / "config" / "kit.yaml"
_CODEC_NAMES = {"h264": "H.264", "h265": "H.265"}


def bench_simulate(width: int, height: int, frames: int, cameras: int = 2) -> dict:
    from triaxtrack.kit import export_kit, load_design
    from triaxtrack.simulate import CameraRenderer, SimulationConfig, load_scene, make_scene
    from triaxtrack.video import VideoWriter

    design = KIT_DESIGN
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        export_kit(load_design(design), tmp / "kit")
        cfg = SimulationConfig(cameras=cameras, frames=frames, width=width, height=height)
        make_scene(cfg, tmp / "kit", tmp / "t", "bench")
        scene = load_scene(tmp / "t")
        render_s = encode_s = 0.0
        tracemalloc.start()
        for cam in list(scene.cameras)[:cameras]:
            rend = CameraRenderer(scene, cam)
            with VideoWriter(tmp / f"{cam}.mp4", width, height, cfg.fps) as vw:
                for k in range(frames):
                    t0 = time.perf_counter()
                    img, _ = rend.render(k)
                    t1 = time.perf_counter()
                    vw.write(img)
                    encode_s += time.perf_counter() - t1
                    render_s += t1 - t0
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    n = cameras * frames
    return {"size": f"{width}x{height}", "camera_frames": n, "render_s_per_frame": render_s / n,
            "encode_s_per_frame": encode_s / n, "peak_python_mb": peak / 2**20}  # fmt: skip


def bench_identify(width: int, height: int, repeat: int = 3) -> dict:
    import cv2

    from triaxtrack.identify import label_frame
    from triaxtrack.kit import ct_codes, export_kit, load_design, load_kit_design, target_table
    from triaxtrack.simulate import CameraRenderer, SimulationConfig, load_scene, make_scene

    cv2.setNumThreads(1)
    design = KIT_DESIGN
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        export_kit(load_design(design), tmp / "kit")
        cfg = SimulationConfig(cameras=2, frames=2, width=width, height=height, seed=3)
        make_scene(cfg, tmp / "kit", tmp / "t", "bench")
        scene = load_scene(tmp / "t")
        kit = load_kit_design(tmp / "kit")
        codes = ct_codes(kit, target_table(kit))
        name = next(iter(scene.cameras))
        img, _ = CameraRenderer(scene, name).render(0)
        times, labelled = [], 0
        for _ in range(repeat):
            t0 = time.perf_counter()
            labels = label_frame(img, scene.cameras[name], kit, codes)
            times.append(time.perf_counter() - t0)
            labelled = int((labels.id > 0).sum())
    return {"size": f"{width}x{height}", "seconds": min(times), "labelled": labelled}


# ------------------------------------------------------------------ tracking vs decoding


def _maxrss_mb(who: int = resource.RUSAGE_SELF) -> float:
    """Peak resident memory (ru_maxrss) of this process or of its waited-for children, MiB."""
    rss = resource.getrusage(who).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 1024  # bytes on macOS, KiB on Linux


_PEAK_BEFORE_RESETS = [0.0]  # ru_maxrss before the last reset (a reset lowers ru_maxrss too), MiB


def _reset_peak() -> None:
    """Reset this process's peak resident memory (VmHWM; Linux >= 4.0), when possible, keeping the
    peak so far for :func:`_process_peak_mb`."""
    _PEAK_BEFORE_RESETS[0] = max(_PEAK_BEFORE_RESETS[0], _maxrss_mb())
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass


def _process_peak_mb() -> float:
    """This process's peak resident memory (ru_maxrss) over its whole life, resets included, MiB."""
    return max(_PEAK_BEFORE_RESETS[0], _maxrss_mb())


def _peak_mb() -> float:
    """VmHWM of this process since the last :func:`_reset_peak`, MiB (NaN if not on Linux)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except (OSError, ValueError):
        pass
    return float("nan")


def _log(msg: str) -> None:
    print(f"[bench] {msg}", file=sys.stderr, flush=True)


def _simulate_clip(tmp: str, width: str, height: str, frames: str, test_frames: str, seed: str,
                   h265: str, gop: str) -> None:  # fmt: skip
    """Run in a child process by :func:`_render_video` (arguments as strings): export the kit,
    write the scene and render the clip of the first camera (and re-encode it as H.265)."""
    from triaxtrack.kit import export_kit, load_design
    from triaxtrack.simulate import camera_names, make_scene, render_chunk
    from triaxtrack.video import VideoWriter, iter_frames

    root = Path(tmp)
    export_kit(load_design(KIT_DESIGN), root / "kit")
    cfg = _clip_config(int(width), int(height), int(frames), int(test_frames), int(seed), int(gop))
    make_scene(cfg, root / "kit", root / "test", "bench")
    camera = camera_names(cfg.cameras)[0]
    render_chunk(root / "test", camera, 0, int(frames), root / "video.mp4", root / "truth.parquet")
    if h265 == "1":
        with VideoWriter(root / "video265.mp4", cfg.width, cfg.height, cfg.fps, "h265", cfg.crf,
                         gop=int(gop), recorder=True) as writer:  # fmt: skip
            for k, img in iter_frames(root / "video.mp4"):
                writer.write(img, keyframe=k % int(gop) == 0)


def _clip_config(width: int, height: int, frames: int, test_frames: int, seed: int, gop: int):
    from triaxtrack.simulate import SimulationConfig

    fps = SimulationConfig().fps
    return SimulationConfig(frames=max(frames, test_frames), width=width, height=height, seed=seed,
                            gop_s=gop / fps)  # fmt: skip


def _render_video(tmp: Path, width: int, height: int, frames: int, test_frames: int, seed: int,
                  h265: bool = False, gop: int = 6) -> dict:  # fmt: skip
    """The first ``frames`` frames of one camera of a simulated test of ``test_frames`` frames (the
    simulation defaults otherwise: the dots move as fast per frame as in the workflow's demo), and
    with ``h265`` the same frames re-encoded as H.265, made in a child process (the kit export's
    and renderer's memory do not count in this one's)."""
    from triaxtrack.simulate import camera_names

    cfg = _clip_config(width, height, frames, test_frames, seed, gop)
    camera = camera_names(cfg.cameras)[0]
    _log(f"rendering {frames} frames of {camera} at {width}x{height} ...")
    t0 = time.perf_counter()
    # this file is a script, not a module of the package: the child runs it by path (not as __main__)
    code = "import runpy, sys; runpy.run_path(sys.argv[1])['_simulate_clip'](*sys.argv[2:])"
    argv = [str(x) for x in (tmp, width, height, frames, test_frames, seed, int(h265), gop)]
    subprocess.run([sys.executable, "-c", code, str(Path(__file__).resolve()), *argv], check=True)
    return {"cfg": cfg, "camera": camera, "test": tmp / "test", "video": tmp / "video.mp4",
            "video265": tmp / "video265.mp4", "observations": tmp / "truth.parquet",
            "render_s": time.perf_counter() - t0}  # fmt: skip


class _Timed:
    """Wraps a function of a module, adding up the seconds spent in it (while installed)."""

    def __init__(self, module, name: str):
        self.module, self.name, self.fn, self.seconds = module, name, getattr(module, name), 0.0

    def __enter__(self) -> _Timed:
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return self.fn(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - t0

        setattr(self.module, self.name, wrapper)
        return self

    def __exit__(self, *exc) -> None:
        setattr(self.module, self.name, self.fn)


def _link_errors(linked: pd.DataFrame, tracks: pd.DataFrame, tol_px: float = 1.0) -> dict:
    """trackpy's links against our IDs: every step k -> k+1 of a target we report at both frames
    (matched to a detection within ``tol_px`` of our centroid) is ``agree`` (same trackpy
    particle), ``wrong`` (the particle goes on to another detection) or ``broken`` (it ends)."""
    from scipy.spatial import cKDTree

    linked = linked.reset_index(drop=True)
    det_id = np.full(len(linked), -1, np.int64)
    ours = tracks[tracks["reason"] == ""]
    for k, rows in linked.groupby("frame").indices.items():
        mine = ours[ours["frame"] == k]
        if mine.empty:
            continue
        d, j = cKDTree(mine[["u_px", "v_px"]].to_numpy()).query(
            linked.loc[rows, ["x", "y"]].to_numpy(), distance_upper_bound=tol_px
        )
        hit = np.isfinite(d)
        det_id[rows[hit]] = mine["id"].to_numpy()[j[hit]]
    m = linked.assign(id=det_id)[det_id > 0].drop_duplicates(["id", "frame"])
    now = m.set_index(["id", "frame"])["particle"].rename("p0")
    nxt = m.assign(frame=m["frame"] - 1).set_index(["id", "frame"])["particle"].rename("p1")
    steps = pd.concat([now, nxt], axis=1, join="inner")
    differ = steps[steps["p0"] != steps["p1"]]
    present = set(zip(linked["frame"].to_numpy(), linked["particle"].to_numpy(), strict=True))
    wrong = sum((k + 1, p) in present for (_, k), p in differ["p0"].items())
    return {
        "steps": len(steps),
        "agree": len(steps) - len(differ),
        "wrong": wrong,
        "broken": len(differ) - wrong,
    }


@dataclass(frozen=True)
class _Clip:
    """The rendered clip and what tracking it needs: ``video`` (H.264) and ``videos`` (per codec
    benchmarked), the ``fmap`` of its ``n`` frames (:func:`triaxtrack.frames.frame_map`), the
    ``camera`` name and its truth model ``cam``, the ``kit`` design with its CT ``codes``, the
    tracking settings ``tcfg`` and the membrane ``grid`` that completion takes dots on from (the
    workflow's default, ``tracking.complete_grid``)."""

    video: Path
    videos: dict[str, Path]
    camera: str
    fmap: pd.DataFrame
    n: int
    cam: Any
    kit: dict
    codes: Any
    tcfg: TrackingConfig
    grid: Any


def _load_clip(sim: dict, codecs: tuple) -> tuple[_Clip, dict]:
    """The rendered clip of :func:`_render_video` (``sim``) read back for tracking, and its
    figures: ``camera``, ``sim`` (the simulation settings), ``render_s``, ``render_peak_mb``, the
    ``video``'s probe, ``video_mb`` and per codec the video's size in MB (``codecs``)."""
    from triaxtrack.completion import dot_grid
    from triaxtrack.frames import CameraTiming, frame_map
    from triaxtrack.kit import ct_codes, load_kit_design, target_table
    from triaxtrack.layout import TEST_FOLDER
    from triaxtrack.optics import read_cameras
    from triaxtrack.track import TrackingConfig
    from triaxtrack.video import probe_video

    video, camera, cfg = sim["video"], sim["camera"], sim["cfg"]
    videos = {c: sim["video265" if c == "h265" else "video"] for c in codecs}
    figures = dict(
        camera=camera,
        sim=cfg,
        render_s=sim["render_s"],
        render_peak_mb=_maxrss_mb(resource.RUSAGE_CHILDREN),
        video=probe_video(video),
        video_mb=video.stat().st_size / 2**20,
        codecs={c: videos[c].stat().st_size / 2**20 for c in codecs},
    )
    n = figures["video"]["frames"]
    fmap = frame_map(CameraTiming(camera, cfg.fps), n, n)
    cam = read_cameras(sim["test"] / TEST_FOLDER.truth.cameras)[camera]
    kit = load_kit_design(sim["test"] / TEST_FOLDER.kit)
    codes = ct_codes(kit, target_table(kit))
    return _Clip(video, videos, camera, fmap, n, cam, kit, codes, TrackingConfig(), dot_grid(kit)), figures


def _label_first_frame(clip: _Clip) -> tuple[pd.DataFrame, dict]:
    """The first frame's labels (:func:`triaxtrack.identify.label_frame`), and the figures:
    ``label_s`` (seconds), ``labelled`` (targets), ``detections``, ``spacing_px`` (per label, to
    the nearest detection) and ``warmup_s`` (seconds to load, or compile, the tracker's kernels,
    tracking the first frame once)."""
    import triaxtrack.track as track
    from triaxtrack.frames import iter_test_frames
    from triaxtrack.identify import label_frame

    _log("labelling the first frame ...")
    first = next(iter_test_frames(clip.video, clip.fmap, 0, 1))[1]
    t0 = time.perf_counter()
    labels = label_frame(first, clip.cam, clip.kit, clip.codes)
    label_s = time.perf_counter() - t0
    own = labels[labels["id"] > 0]
    spacing_px = track._init_state(labels, clip.tcfg).spacing
    t0 = time.perf_counter()  # the compiled kernels: loaded from numba's cache (or compiled)
    track.track_frames([(0, first)], labels, clip.camera, [0], clip.tcfg, clip.grid)
    return labels, {"label_s": label_s, "labelled": own["id"].nunique(), "detections": len(labels),
                    "spacing_px": spacing_px, "warmup_s": time.perf_counter() - t0}  # fmt: skip


def _time_modes(clip: _Clip, labels: pd.DataFrame, repeat: int, codecs: tuple) -> tuple[dict, dict]:
    """Per codec, decoding only, the pipeline (decoding and ``track_frames`` on every frame) and
    fast mode (one processed frame a GOP, on every keyframe), ``repeat`` times each, alternated.
    Returns the figures (best seconds ``decode_s``, ``pipeline_s``, ``fast_s``; fast mode's
    ``keys`` and frames ``decoded``; ``fast_vs_every_px`` (:func:`_largest_difference`); the first
    codec's every-frame ``tracks``) and the peak memory of each stage (MiB)."""
    import triaxtrack.track as track
    from triaxtrack.frames import ProcessedTestFrames, iter_test_frames, keyframe_test_frames

    fmap, n, camera, tcfg, videos, grid = clip.fmap, clip.n, clip.camera, clip.tcfg, clip.videos, clip.grid

    def decode(path: Path) -> int:
        return sum(img is not None for _, img in iter_test_frames(path, fmap, 0, n))

    def pipeline(path: Path) -> pd.DataFrame:
        return track.track_frames(iter_test_frames(path, fmap, 0, n), labels, camera, range(n), tcfg, grid)

    # fast mode: one processed frame a GOP, on every keyframe (as step_s = gop_s)
    keys = {c: keyframe_test_frames(p, fmap, 0, n) for c, p in videos.items()}
    decoded: dict[str, int] = {}

    def fast(path: Path) -> pd.DataFrame:
        codec = next(c for c, p in videos.items() if p == path)
        sparse = ProcessedTestFrames(path, fmap, 0, n, keys[codec])
        out = track.track_frames(sparse, labels, camera, keys[codec], tcfg, grid)
        decoded[codec] = sparse.decoded
        return out

    _log(f"decode only, decode + tracking and fast mode, {repeat} times each ({', '.join(codecs)}) ...")
    times: dict[tuple, list[float]] = {}
    peak_mb: dict[str, float] = {}
    stages = (("decode", decode), ("pipeline", pipeline), ("fast mode", fast))
    every_tracks: dict[str, pd.DataFrame] = {}
    fast_tracks: dict[str, pd.DataFrame] = {}
    for _ in range(repeat):  # alternate, so that a slow spell of the machine hits both
        for (codec, path), (name, fn) in itertools.product(videos.items(), stages):
            _reset_peak()
            t0 = time.perf_counter()
            out = fn(path)
            times.setdefault((codec, name), []).append(time.perf_counter() - t0)
            stage = name if codec == "h264" else f"{name} {_CODEC_NAMES[codec]}"
            peak_mb[stage] = max(peak_mb.get(stage, 0.0), _peak_mb())
            if (codec, name) == (codecs[0], "pipeline"):
                tracks = out
            if name == "pipeline":
                every_tracks[codec] = out
            if name == "fast mode":
                fast_tracks[codec] = out
    figures = {
        "decode_s": {c: min(times[c, "decode"]) for c in codecs},
        "pipeline_s": {c: min(times[c, "pipeline"]) for c in codecs},
        "fast_s": {c: min(times[c, "fast mode"]) for c in codecs},
        "keys": keys,
        "decoded": decoded,
        "fast_vs_every_px": {c: _largest_difference(fast_tracks[c], every_tracks[c]) for c in codecs},
        "tracks": tracks,
    }
    return figures, peak_mb


def _time_held(clip: _Clip, labels: pd.DataFrame, held: list[tuple[int, np.ndarray]]) -> tuple[dict, float]:
    """``track_frames`` on frames already decoded (``held``), best of 3, with the seconds spent in
    ``_step`` and ``measure_targets``: the figures ``direct_s``, ``step_s``, ``measure_s``
    (seconds per frame) and the peak memory (MiB)."""
    import triaxtrack.track as track

    best = None
    _reset_peak()
    for _ in range(3):
        with _Timed(track, "_step") as step, _Timed(track, "measure_targets") as meas:
            t0 = time.perf_counter()
            track.track_frames(held, labels, clip.camera, [k for k, _ in held], clip.tcfg, clip.grid)
            total = time.perf_counter() - t0
        if best is None or total < best[0]:
            best = (total, step.seconds, meas.seconds)
    peak = _peak_mb()
    direct_s, step_s, measure_s = (x / len(held) for x in best)
    return {"direct_s": direct_s, "step_s": step_s, "measure_s": measure_s}, peak


def _time_brute_force(clip: _Clip, held: list[tuple[int, np.ndarray]]) -> tuple[float, float]:
    """Seconds per frame of ``label_frame`` (detection and identification) on each held frame,
    and the peak memory (MiB)."""
    from triaxtrack.identify import label_frame

    _log(f"label_frame on each of the {len(held)} held frames ...")
    _reset_peak()
    t0 = time.perf_counter()
    for _, img in held:
        label_frame(img, clip.cam, clip.kit, clip.codes)
    return (time.perf_counter() - t0) / len(held), _peak_mb()


def _detect_every_frame(clip: _Clip) -> tuple[pd.DataFrame, float]:
    """Every frame's ``detect_blobs`` as trackpy's input (columns ``x``, ``y`` in pixels and
    ``frame``), and the seconds per frame of detection alone."""
    from triaxtrack.detect import detect_blobs
    from triaxtrack.frames import iter_test_frames

    _log("detect_blobs on every frame, for trackpy ...")
    parts, det_s = [], 0.0
    for k, img in iter_test_frames(clip.video, clip.fmap, 0, clip.n):
        t0 = time.perf_counter()
        blobs = detect_blobs(img)
        det_s += time.perf_counter() - t0
        parts.append(pd.DataFrame({"x": blobs["u_px"], "y": blobs["v_px"], "frame": k}))
    return pd.concat(parts, ignore_index=True), det_s / clip.n


def bench_tracking(width: int, height: int, frames: int, hold: int = 6, test_frames: int = 100,
                   seed: int = 1, repeat: int = 3, codecs: tuple = ("h264", "h265"),
                   gop: int = 6) -> dict:  # fmt: skip
    """Decode vs decode + tracking on one simulated camera's video (module docstring)."""
    from triaxtrack.frames import iter_test_frames

    r: dict = {"peak_mb": {}}
    with tempfile.TemporaryDirectory(prefix="triaxtrack-bench-") as tmp:
        sim = _render_video(Path(tmp), width, height, frames, test_frames, seed, "h265" in codecs, gop)
        clip, figures = _load_clip(sim, codecs)
        r.update(figures)
        labels, figures = _label_first_frame(clip)
        r.update(figures)
        figures, peaks = _time_modes(clip, labels, repeat, codecs)
        r.update(figures, gop=gop)
        r["peak_mb"].update(peaks)

        _log(f"tracking on {hold} decoded frames held in memory ...")
        held = [(k, img) for k, img in iter_test_frames(clip.video, clip.fmap, 0, min(hold, clip.n))]
        figures, peak = _time_held(clip, labels, held)
        r.update(figures, held=len(held))
        r["peak_mb"][f"tracking {len(held)} held frames"] = peak
        r["brute_s"], r["peak_mb"]["label_frame"] = _time_brute_force(clip, held)
        del held

        dets, r["detect_s"] = _detect_every_frame(clip)
        r["detections_per_frame"] = len(dets) / clip.n
        r["search_range_px"] = float(np.median(clip.tcfg.gate * r["spacing_px"]))
        r["trackpy"] = _bench_trackpy(dets, r["tracks"], r["search_range_px"], clip.n)
        truth = pd.read_parquet(sim["observations"])
        r["truth"], r["motion_px"] = _truth_errors(r["tracks"], truth), _motion(truth)
    r["maxrss_mb"] = _process_peak_mb()
    return r


def _largest_difference(fast: pd.DataFrame, every: pd.DataFrame) -> tuple[float, int, int]:
    """Fast mode's reported centroids against every-frame mode's at the same (frame, ID): the
    largest distance (px), and the reports of each (fast, every-frame) at fast's frames."""
    ok = fast[fast["reason"] == ""]
    ref = every[(every["reason"] == "") & every["frame"].isin(fast["frame"].unique())]
    both = ok.merge(ref, on=["frame", "id"], suffixes=("", "_every"))
    d = np.hypot(both["u_px"] - both["u_px_every"], both["v_px"] - both["v_px_every"])
    return (float(d.max()) if len(d) else float("nan")), len(ok), len(ref)


# a long real test, for the wall-time projection (issue 17): 16 cameras x 15 fps x 3.3 h
LONG_TEST_CAMERAS = 16
LONG_TEST_FPS = 15.0
LONG_TEST_HOURS = 3.3
LONG_TEST_STEP_S = 2.0  # one processed frame per 2 s: a recorder's usual GOP
PROJECTION_CORES = (2, 64)


def project_wall_hours(seconds_per_frame: float, step_s: float | None, cores: int) -> float:
    """Hours of wall time to track the long test (``LONG_TEST_*``) at ``seconds_per_frame`` per
    processed camera-frame (every frame for ``step_s`` None, else one per ``step_s``), with
    one job per core all the time (the camera x chunk jobs are independent)."""
    frames = LONG_TEST_HOURS * 3600 * (LONG_TEST_FPS if step_s is None else 1 / step_s)
    return LONG_TEST_CAMERAS * frames * seconds_per_frame / cores / 3600


def _truth_errors(tracks: pd.DataFrame, truth: pd.DataFrame) -> dict:
    """Our reported centroids against the simulator's exact ones, by (frame, ID)."""
    got = tracks[tracks["reason"] == ""].merge(truth, on=["frame", "id"], suffixes=("", "_true"))
    err = np.hypot(got["u_px"] - got["u_px_true"], got["v_px"] - got["v_px_true"])
    return {"compared": len(got), "median_px": float(np.median(err)) if len(err) else float("nan"),
            "wrong": int((err > 1.0).sum())}  # fmt: skip


def _motion(truth: pd.DataFrame) -> tuple[float, float]:
    """Median and largest true displacement of a membrane dot from one frame to the next, px."""
    from triaxtrack.track import target_kind

    ok = truth[target_kind(truth["id"].to_numpy()) == 3]
    u = ok.pivot(index="id", columns="frame", values="u_px").sort_index(axis=1)
    v = ok.pivot(index="id", columns="frame", values="v_px").reindex_like(u)
    step = np.hypot(np.diff(u.to_numpy(), axis=1), np.diff(v.to_numpy(), axis=1))
    step = step[np.isfinite(step)]
    return (float(np.median(step)), float(step.max())) if len(step) else (float("nan"), float("nan"))


def workflow_peaks(root: Path) -> dict[str, dict[str, tuple[float, int]]]:
    """Per test folder of Snakemake's ``benchmarks/`` and per rule (``<rule>.tsv`` or any
    ``<rule>/**/*.tsv``): the largest ``max_rss`` (MB) and the number of benchmark files."""
    out: dict[str, dict[str, tuple[float, int]]] = {}
    for test in sorted(p for p in root.iterdir() if p.is_dir()) if root.is_dir() else []:
        rules: dict[str, list[float]] = {}
        for f in sorted(test.rglob("*.tsv")):
            rule = f.relative_to(test).parts[0].removesuffix(".tsv")
            try:
                rss = pd.to_numeric(pd.read_csv(f, sep="\t").get("max_rss"), errors="coerce")
            except (OSError, ValueError, pd.errors.EmptyDataError):
                continue
            rules.setdefault(rule, []).append(float(np.nanmax(rss)) if rss is not None and rss.notna().any()
                                              else float("nan"))  # fmt: skip
        if rules:
            out[test.name] = {k: (float(np.nanmax(v)) if np.isfinite(v).any() else float("nan"), len(v))
                              for k, v in rules.items()}  # fmt: skip
    return out


def _bench_trackpy(dets: pd.DataFrame, tracks: pd.DataFrame, search_range: float, n: int) -> dict | str:
    """trackpy.link on the detections, memory 0 and 3: seconds per frame, links against our IDs."""
    try:
        import trackpy
    except ImportError:
        return "trackpy not installed"
    trackpy.quiet()
    try:
        from trackpy.try_numba import NUMBA_AVAILABLE as numba
    except ImportError:
        numba = False
    out: dict = {"version": f"{trackpy.__version__} ({'numba' if numba else 'no numba: pure Python'})"}
    for memory in (0, 3):
        _log(f"trackpy.link, memory {memory} ...")
        _reset_peak()
        t0 = time.perf_counter()
        linked = trackpy.link(dets.copy(), search_range, memory=memory)
        seconds, peak = (time.perf_counter() - t0) / n, _peak_mb()
        out[memory] = {"seconds": seconds, "peak_mb": peak, **_link_errors(linked, tracks)}
    return out


def _table(rows: list[tuple[str, str, str, str]]) -> str:
    """Rows of (what, value, unit, note) as aligned text; a row with only ``what`` is a heading."""
    w = [max(len(r[i]) for r in rows if any(r[1:])) for i in range(3)]
    lines = []
    for r in rows:
        if not any(r[1:]):
            lines.append(r[0])
        else:
            lines.append(f"  {r[0]:<{w[0]}}  {r[1]:>{w[1]}}  {r[2]:<{w[2]}}  {r[3]}".rstrip())
    return "\n".join(lines)


def _times(ratio: float) -> str:
    return f"{ratio:.0f} x" if ratio >= 10 else f"{ratio:.1f} x"


def _clip_summary(r: dict) -> list[str]:
    """The lines that describe the benchmarked clip (:func:`bench_tracking`'s figures ``r``): its
    video(s), the simulated test it comes from, the motion of its dots, the targets labelled and
    tracked, the tracker's gate and the kernels' load time."""
    v, sim, n = r["video"], r["sim"], r["video"]["frames"]
    tracks = r["tracks"]
    ok = tracks["reason"] == ""
    per_frame = ok.groupby(tracks["frame"]).sum()
    med_step, max_step = r["motion_px"]
    t = r["truth"]
    h265 = f"; re-encoded as H.265 (libx265 crf {sim.crf}, veryfast), {r['codecs'].get('h265', 0):.1f} MB"
    return [
        f"Tracking benchmark on one video: {v['width']}x{v['height']} {v['codec']} (libx264 crf {sim.crf}, "
        f"veryfast, grey in yuv420p), {n} frames at {v['fps']:g} fps, {r['video_mb']:.1f} MB"
        + (h265 if "h265" in r["codecs"] else ""),
        f"  camera {r['camera']}, frames 0..{n - 1} of a simulated {sim.frames}-frame test (seed {sim.seed}; "
        f"axial strain {sim.axial_strain:g} and bulge {sim.bulge_mm:g} mm at its end)",
        f"  kit export, scene and rendering: {r['render_s']:.0f} s ({r['render_s'] / n:.1f} s/frame; in a "
        f"child process, peak {r['render_peak_mb']:.0f} MB)",
        f"  membrane dots move {med_step:.2f} px/frame (median), up to {max_step:.2f} px/frame (truth)",
        f"  {r['labelled']} targets labelled in frame 0 ({r['detections']} detections; label_frame "
        f"{r['label_s']:.2f} s, once per chunk, not in the figures below)",
        f"  targets tracked (reported) per frame: mean {per_frame.mean():.0f}, min {per_frame.min()}; "
        f"their centroids vs the simulator's: median {t['median_px']:.3f} px, "
        f"{t['wrong']} of {t['compared']} farther than 1 px",
        f"  spacing to the nearest detection: median {np.median(r['spacing_px']):.1f} px, so the gate "
        f"({track_gate():g} x spacing) is {r['search_range_px']:.1f} px (median)",
        f"  the tracker's compiled (numba) kernels loaded before the timings: {r['warmup_s']:.1f} s, once "
        "per process (compiled and cached on disk the first time)",
    ]


def _codec_label(r: dict, codec: str) -> str:
    """``"H.264: "`` before a figure when several codecs were benchmarked, else ``""``."""
    return "" if len(r["codecs"]) == 1 else f"{_CODEC_NAMES[codec]}: "


def _throughput_rows(r: dict) -> list[tuple[str, str, str, str]]:
    """Table rows (:func:`_table`): decoding and the pipeline in frames/s per codec, and the
    tracking cost per camera-frame beyond decoding (ms), measured and on frames held in memory."""
    v, n = r["video"], r["video"]["frames"]
    direct_ms = r["direct_s"] * 1e3
    rows, beyond = [("Throughput (same video, same run; best of the repeats)", "", "", "")], []
    for codec, dec in r["decode_s"].items():
        pipe, name = r["pipeline_s"][codec], _codec_label(r, codec)
        rows += [
            (f"{name}decode only (iter_test_frames)", f"{n / dec:.1f}", "frames/s", f"{dec:.2f} s for {n}"
             " frames"),
            (f"{name}pipeline: decode + track_frames", f"{n / pipe:.1f}", "frames/s", f"{pipe:.2f} s for {n}"
             " frames"),
            (f"{name}ratio pipeline / decode", f"{dec / pipe:.2f}", "", "aim >= 0.8"),
        ]  # fmt: skip
        beyond.append((f"{name}(pipeline - decode) / frames", f"{(pipe - dec) / n * 1e3:.1f}", "ms/frame",
                       "aim <= 3 ms"))  # fmt: skip
    rows.append((f"Tracking cost per {v['width']}x{v['height']} camera-frame beyond decoding", "", "", ""))
    rows += beyond
    rows += [
        (
            "timed on decoded frames in memory",
            f"{direct_ms:.1f}",
            "ms/frame",
            f"track_frames on {r['held']} held frames, best of 3",
        ),
        (
            "  of which _step",
            f"{r['step_s'] * 1e3:.1f}",
            "ms/frame",
            "the rest: set-up (once a chunk), table",
        ),
        ("  of which measure_targets", f"{r['measure_s'] * 1e3:.1f}", "ms/frame", "inside _step"),
    ]
    return rows


def _fast_mode_rows(r: dict) -> list[tuple[str, str, str, str]]:
    """Table rows (:func:`_table`): per codec, the cost per processed frame (ms) in fast mode and in
    every-frame mode, with the ratio here and on the long test, and how far apart their centroids
    are (px)."""
    n = r["video"]["frames"]
    rows = [(f"Cost per processed frame, one a GOP ({r['gop']} frames here) on its keyframe", "", "", "")]
    for codec, fast_s in r["fast_s"].items():
        name = _codec_label(r, codec)
        k = len(r["keys"][codec])
        every = r["pipeline_s"][codec] / k
        far, n_fast, n_every = r["fast_vs_every_px"][codec]
        rows += [
            (f"{name}fast mode (ProcessedTestFrames)", f"{fast_s / k * 1e3:.0f}", "ms/processed",
             f"{r['decoded'][codec]} frames decoded for {k} processed (with the chunk's set-up)"),
            (f"{name}every-frame mode (the pipeline)", f"{every * 1e3:.0f}", "ms/processed",
             f"{n} frames decoded; {_times(every * k / fast_s)} fast mode here, "
             f"{_times(r['pipeline_s'][codec] / n * LONG_TEST_FPS * LONG_TEST_STEP_S / (fast_s / k))} "
             f"at a {LONG_TEST_STEP_S:g} s GOP at {LONG_TEST_FPS:g} fps"),
            (f"{name}  fast vs every-frame centroids", f"{far:.4f}", "px",
             f"largest distance; {n_fast} vs {n_every} reported"),
        ]  # fmt: skip
    return rows


def _projection_rows(r: dict) -> list[tuple[str, str, str, str]]:
    """Table rows (:func:`_table`): the wall time (h) of the long test's tracking jobs
    (``LONG_TEST_*``) on ``PROJECTION_CORES`` cores, every frame and in fast mode, from the first
    codec's costs."""
    v, n = r["video"], r["video"]["frames"]
    codec = next(iter(r["fast_s"]))
    per_frame = r["pipeline_s"][codec] / n
    per_processed = r["fast_s"][codec] / len(r["keys"][codec])
    long_test = f"{LONG_TEST_HOURS:g} h x {LONG_TEST_CAMERAS} cameras x {LONG_TEST_FPS:g} fps"
    rows = [(f"Wall time for {long_test} at {v['width']}x{v['height']} ({_CODEC_NAMES[codec]}; "
             "tracking jobs only)", "", "", "")]  # fmt: skip
    for cores in PROJECTION_CORES:
        rows += [
            (f"every frame, {cores} cores", f"{project_wall_hours(per_frame, None, cores):.1f}", "h",
             f"{per_frame * 1e3:.0f} ms per camera-frame"),
            (f"one frame per {LONG_TEST_STEP_S:g} s, fast mode, {cores} cores",
             f"{project_wall_hours(per_processed, LONG_TEST_STEP_S, cores):.2f}", "h",
             f"{per_processed * 1e3:.0f} ms per processed frame (every-frame mode: as every frame)"),
        ]  # fmt: skip
    return rows


def _alternative_rows(r: dict) -> list[tuple[str, str, str, str]]:
    """Table rows (:func:`_table`): the alternatives to tracking, detecting and labelling every frame
    (ms per frame) and trackpy's linking (ms per frame, and its links against our IDs)."""
    n = r["video"]["frames"]
    rows = [
        ("Brute force: detect and label every frame", "", "", ""),
        (
            "label_frame per frame",
            f"{r['brute_s'] * 1e3:.0f}",
            "ms/frame",
            f"{_times(r['brute_s'] / r['direct_s'])} tracking (mean of {r['held']} frames)",
        ),
        (
            "  detect_blobs alone",
            f"{r['detect_s'] * 1e3:.0f}",
            "ms/frame",
            f"{_times(r['detect_s'] / r['direct_s'])} tracking (mean of {n} frames)",
        ),
    ]
    tp = r["trackpy"]
    if isinstance(tp, str):
        rows.append(("trackpy.link", "-", "", f"{tp} (pip install -e '.[bench]')"))
        return rows
    rows.append(
        (
            f"trackpy {tp['version']}: link every frame's detect_blobs "
            f"({r['detections_per_frame']:.0f} per frame)",
            "",
            "",
            "",
        )
    )
    for memory in (0, 3):
        m = tp[memory]
        rows.append(
            (
                f"trackpy.link, memory {memory}, search_range {r['search_range_px']:.1f} px",
                f"{m['seconds'] * 1e3:.1f}",
                "ms/frame",
                f"{_times(m['seconds'] / r['direct_s'])} tracking (linking alone, no detection)",
            )
        )
        rows.append(
            (
                f"  its links vs our IDs, memory {memory}",
                f"{m['agree']}/{m['steps']}",
                "agree",
                f"{m['wrong']} wrong (onto another dot), {m['broken']} broken (track ends)",
            )
        )
    return rows


def _memory_rows(r: dict) -> list[tuple[str, str, str, str]]:
    """Table rows (:func:`_table`): this process's peak memory (MB), over the run and per stage."""
    rows = [
        ("Peak memory", "", "", ""),
        (
            "this process (ru_maxrss)",
            f"{r['maxrss_mb']:.0f}",
            "MB",
            "the whole run (rendering ran in a child process); Snakemake's max_rss is per job",
        ),
    ]
    for stage, mb in r["peak_mb"].items():
        rows.append((f"  during {stage} (VmHWM)", f"{mb:.0f}", "MB", ""))
    tp = r["trackpy"]
    if not isinstance(tp, str):
        for memory in (0, 3):
            rows.append(
                (f"  during trackpy.link, memory {memory} (VmHWM)", f"{tp[memory]['peak_mb']:.0f}", "MB", "")
            )
    return rows


def _print_workflow_peaks(benchmarks: Path) -> None:
    """Print the largest ``max_rss`` per rule of each workflow run in Snakemake's ``benchmarks``
    folder (:func:`workflow_peaks`), or that there is none."""
    peaks = workflow_peaks(benchmarks)
    if not peaks:
        print(f"Workflow rules' peak memory ({benchmarks}/): no workflow run found")
        return
    print(
        f"Workflow rules' peak memory: the largest max_rss per rule in {benchmarks}/<test>/<rule>...tsv "
        "(MB; number of files)"
    )
    for test, rules in peaks.items():
        print(f"  {test}:")
        width = max(len(k) for k in rules)
        for rule, (mb, files) in sorted(rules.items()):
            print(f"    {rule:<{width}}  {mb:7.0f} MB  ({files})")


def print_tracking(r: dict, benchmarks: Path) -> None:
    """Print :func:`bench_tracking`'s figures ``r``: the clip, then one table (throughput, fast
    mode, the long test's wall time, the alternatives, peak memory), then the workflow rules' peak
    memory from Snakemake's ``benchmarks`` folder."""
    print("\n".join(_clip_summary(r)))
    print()
    rows = [*_throughput_rows(r), *_fast_mode_rows(r), *_projection_rows(r), *_alternative_rows(r),
            *_memory_rows(r)]  # fmt: skip
    print(_table(rows))
    print()
    _print_workflow_peaks(benchmarks)


def track_gate() -> float:
    from triaxtrack.track import TrackingConfig

    return TrackingConfig().gate


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"a size is WIDTHxHEIGHT, e.g. 3840x2160, not {text!r}") from err
    if w <= 0 or h <= 0 or w % 2 or h % 2:
        raise argparse.ArgumentTypeError(f"width and height must be even and positive, not {text!r}")
    return w, h


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("what", nargs="*", help="tracking (the default), simulate, identify")
    p.add_argument(
        "--size", type=_size, default=(3840, 2160), help="tracking: video size (default 3840x2160)"
    )
    # 72 frames: the figure beyond decoding is the difference of two wall times; over 24 frames
    # (about 1.1 s each) it moved by up to 2 ms between runs of the same code
    p.add_argument("--frames", type=int, default=72, help="tracking: video frames (default 72, >= 2)")
    p.add_argument(
        "--hold", type=int, default=6, help="tracking: frames held in memory for the direct timing"
    )
    p.add_argument("--test-frames", type=int, default=100,
                   help="tracking: the clip is the first --frames frames of a test this long (default 100, "
                        "the workflow demo's: the dots move as fast per frame)")  # fmt: skip
    p.add_argument("--repeat", type=int, default=3, help="tracking: runs of decode and pipeline (best taken)")
    p.add_argument("--gop", type=int, default=6,
                   help="tracking: the clip's keyframe interval in frames (default 6)")  # fmt: skip
    p.add_argument("--codecs", default="h264,h265", help="tracking: h264 (rendered) and/or h265 (re-encoded)")
    p.add_argument("--benchmarks", type=Path, default=Path("benchmarks"),
                   help="tracking: Snakemake's benchmark folder (default ./benchmarks)")  # fmt: skip
    p.add_argument("--sizes", default="1280x720,1920x1080,3840x2160", help="simulate, identify: sizes")
    p.add_argument("--sim-frames", type=int, default=10, help="simulate: frames per camera")
    args = p.parse_args(argv)
    args.what = args.what or ["tracking"]  # (no `choices`: Python 3.11 checks an empty list against them)
    if set(args.what) - {"tracking", "simulate", "identify"}:
        p.error(f"what: choose among tracking, simulate, identify, not {args.what}")
    if args.frames < 2 or args.hold < 1 or args.repeat < 1 or args.gop < 1:
        p.error("--frames must be >= 2, --hold, --repeat and --gop >= 1")
    codecs = tuple(c.strip().lower() for c in args.codecs.split(","))
    if not codecs or set(codecs) - set(_CODEC_NAMES):
        p.error(f"--codecs: h264 and/or h265, not {args.codecs!r}")
    if "tracking" in args.what:
        w, h = args.size
        print_tracking(
            bench_tracking(
                w,
                h,
                args.frames,
                args.hold,
                args.test_frames,
                repeat=args.repeat,
                codecs=codecs,
                gop=args.gop,
            ),
            args.benchmarks,
        )
    sizes = [_size(size) for size in args.sizes.split(",")]
    for w, h in sizes if "identify" in args.what else []:
        r = bench_identify(w, h)
        print(
            f"identify {r['size']:>9}: {r['seconds']:.3f} s to detect and label one frame on one core "
            f"({r['labelled']} targets labelled; best of 3)"
        )
    for w, h in sizes if "simulate" in args.what else []:
        r = bench_simulate(w, h, args.sim_frames)
        print(f"simulate {r['size']:>9}: render {r['render_s_per_frame']:.3f} s/frame, encode "
              f"{r['encode_s_per_frame']:.3f} s/frame ({r['camera_frames']} camera-frames, "
              f"peak Python memory {r['peak_python_mb']:.0f} MB)")  # fmt: skip


if __name__ == "__main__":
    main()
