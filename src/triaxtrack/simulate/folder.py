"""Writing a simulated test folder: its static part (:func:`make_scene`), the video chunks
(:func:`render_chunk`), and the whole simulation in one process (:func:`simulate_test`)."""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict
from pathlib import Path

import pandas as pd
import yaml

from triaxtrack.kit import load_kit_design
from triaxtrack.layout import TEST_FOLDER
from triaxtrack.optics import write_cameras
from triaxtrack.simulate.boards import render_calibration
from triaxtrack.simulate.cameras import make_cameras
from triaxtrack.simulate.config import (
    SimulationConfig,
    camera_names,
    gop_frames,
    recorded_frames,
    render_segments,
)
from triaxtrack.simulate.loadlog import load_frame_entry, write_load_frame
from triaxtrack.simulate.render import CameraRenderer
from triaxtrack.simulate.scene import deformation_for, load_scene
from triaxtrack.simulate.truth import finish_truth, truth_volume
from triaxtrack.tables import OBSERVATIONS, VOLUME, write_table
from triaxtrack.video import VideoWriter


def make_scene(cfg: SimulationConfig, kit_dir: str | Path, test_dir: str | Path, name: str) -> None:
    """Write the static part of a simulated test folder.

    ``test.yaml`` (with its ``load_frame`` entry when the settings have one), ``kit/`` (a copy
    of the kit export), ``truth/scene.json`` (how to rebuild the scene), ``truth/cameras.json``
    and ``truth/volume.parquet``. The load-frame log is written by :func:`write_load_frame`.
    Videos, calibration
    images and the per-target truth are written by :func:`render_chunk`,
    :func:`render_calibration` and :func:`finish_truth`.
    """
    test_dir = Path(test_dir)
    (test_dir / TEST_FOLDER.truth.root).mkdir(parents=True, exist_ok=True)
    kit = test_dir / TEST_FOLDER.kit
    if Path(kit_dir).resolve() != kit.resolve():
        shutil.copytree(kit_dir, kit, dirs_exist_ok=True, ignore=shutil.ignore_patterns(".*"))
    design = load_kit_design(kit)
    deformation = deformation_for(cfg, design)
    cams = make_cameras(cfg)
    lowest_top = deformation.current_height(1.0)  # the top cap at the end of the test
    for cam in cams:
        if not 0 < cam.center[2] < lowest_top:
            raise ValueError(
                f"camera {cam.name} at z = {cam.center[2]:.1f} mm is not between the pedestal faces "
                f"(0 and {lowest_top:.1f} mm at the end of loading): lower camera_height_mm"
            )
    test_yaml = {
        "name": name,
        "fps": float(cfg.fps),
        "frames": int(cfg.frames),
        "cameras": [_test_yaml_camera(cfg, c.name) for c in cams],
        "kit": TEST_FOLDER.kit,
        "simulated": True,
    }
    log_entry = load_frame_entry(cfg)  # the log itself: write_load_frame
    if log_entry is not None:
        test_yaml["load_frame"] = log_entry
    test_yaml_text = yaml.safe_dump(test_yaml, sort_keys=False, allow_unicode=True)
    (test_dir / TEST_FOLDER.test_yaml).write_text(test_yaml_text)
    (test_dir / TEST_FOLDER.truth.scene).write_text(json.dumps({
        "name": name,
        "simulation": asdict(cfg),
        "deformation": asdict(deformation),
        "notes": "axial_strain = (H0 - H) / H0 and volumetric_strain = (V0 - V) / V0, "
                 "compression positive; volume = soil inside the membrane's inner surface, "
                 "between the pedestal faces",
    }, indent=2))  # fmt: skip
    write_cameras(test_dir / TEST_FOLDER.truth.cameras, {c.name: c for c in cams})
    write_table(truth_volume(cfg, deformation), test_dir / TEST_FOLDER.truth.volume, VOLUME)


def _test_yaml_camera(cfg: SimulationConfig, camera: str) -> str | dict:
    """A camera's test.yaml entry: its name, or a mapping with its offset and drops if any."""
    entry: dict = {"name": camera}
    if camera in cfg.start_offset_s:
        entry["start_offset_s"] = float(cfg.start_offset_s[camera])
    if cfg.dropped_frames.get(camera):
        entry["dropped_frames"] = sorted(int(n) for n in cfg.dropped_frames[camera])
    return entry if len(entry) > 1 else camera


def render_chunk(
    test_dir: str | Path,
    camera: str,
    start: int,
    stop: int,
    video_out: str | Path,
    observations_out: str | Path,
) -> None:
    """Render test frames ``[start, stop)`` of one camera: an H.264/H.265 segment of the frames
    the camera recorded (:func:`recorded_frames`) and their truth observations (by test frame).

    The segment is encoded as a recorder does (``VideoWriter(recorder=True)``): a keyframe at
    every test frame on the GOP grid (multiples of :func:`gop_frames`) and nowhere else, but for
    the segment's first frame, always one: so ``start`` should be on the grid
    (:func:`render_segments`) unless the camera did not record that frame (it started later, or
    dropped it: its first frame after the gap is then a keyframe, as a recorder's first is).

    Every frame of the range is rendered, recorded or not, so the recorded ones are the very
    images of a camera without offset or drops. ValueError if the camera recorded none of them
    (the segment would be empty: use a larger chunk_size or a smaller offset).
    """
    scene = load_scene(test_dir)
    rend = CameraRenderer(scene, camera)
    cam = scene.cameras[camera]
    recorded = set(recorded_frames(scene.cfg, camera).tolist())
    if not recorded & set(range(start, stop)):
        raise ValueError(
            f"{camera} recorded none of test frames {start}..{stop - 1} (start_offset_s, dropped_frames): "
            "a video segment cannot be empty; use a larger chunk_size"
        )
    obs = []
    Path(video_out).parent.mkdir(parents=True, exist_ok=True)
    gop = gop_frames(scene.cfg)
    with VideoWriter(
        video_out, cam.width, cam.height, scene.cfg.fps, codec=scene.cfg.codec, crf=scene.cfg.crf,
        gop=gop, recorder=True,
    ) as vw:  # fmt: skip
        for k in range(start, stop):
            img, o = rend.render(k)
            if k in recorded:
                vw.write(img, keyframe=k % gop == 0)
                obs.append(o)
    write_table(pd.concat(obs, ignore_index=True), observations_out, OBSERVATIONS)


def simulate_test(
    cfg: SimulationConfig, kit_dir: str | Path, test_dir: str | Path, name: str, chunk_size: int = 50
) -> None:
    """The whole simulation in one process (what the workflow fans out per camera and video
    segment: :func:`render_segments`)."""
    from triaxtrack.video import concat_videos

    test_dir = Path(test_dir)
    make_scene(cfg, kit_dir, test_dir, name)
    work = test_dir / ".chunks"
    parts = []
    for cam in camera_names(cfg.cameras):
        segs = []
        for start, stop in render_segments(cfg.frames, chunk_size, gop_frames(cfg)):
            seg = work / cam / f"{start:06d}.mp4"
            obs = work / cam / f"{start:06d}.parquet"
            render_chunk(test_dir, cam, start, stop, seg, obs)
            segs.append(seg)
            parts.append(obs)
        video = test_dir / TEST_FOLDER.video.format(camera=cam)
        video.parent.mkdir(exist_ok=True)
        concat_videos(segs, video)
        render_calibration(test_dir, cam, test_dir / TEST_FOLDER.calibration_images.format(camera=cam))
    finish_truth(test_dir, parts)
    if cfg.load_frame:
        write_load_frame(test_dir)
    shutil.rmtree(work)
