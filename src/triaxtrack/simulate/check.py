"""The simulator's self-check: rendered dot centroids against the exact images of their centres
(:func:`check_simulation`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.centroid import local_centroid
from triaxtrack.layout import TEST_FOLDER
from triaxtrack.simulate.config import SimulationConfig, recorded_frames
from triaxtrack.tables import OBSERVATIONS, read_table

CHECK_SAMPLE = 300  # dots per surface, camera and frame measured by check_simulation


def centroid_errors(
    observations: pd.DataFrame, targets: pd.DataFrame, gray: np.ndarray, sample: int | None = None
) -> pd.DataFrame:
    """Rendered centroid minus exact image of the centre, for dots seen in one image.

    ``observations``: truth rows of one camera and frame; ``targets``: the kit's targets.csv
    indexed by ``id``; ``gray``: the decoded image. ``sample``: measure at most this many dots
    per surface (a seeded choice); all by default. Columns: ``id``, ``surface``, ``du_px``,
    ``dv_px``, ``err_px`` (NaN where the blob is not isolated in its window).
    """
    obs = observations[targets.loc[observations.id, "kind"].to_numpy() == "dot"]
    surface = targets.loc[obs.id, "surface"].to_numpy()
    if sample is not None:
        rng = np.random.default_rng(0)
        keep = np.zeros(len(obs), bool)
        for name in np.unique(surface):
            idx = np.flatnonzero(surface == name)
            keep[rng.choice(idx, size=min(sample, len(idx)), replace=False)] = True
        obs, surface = obs[keep], surface[keep]
    uv = obs[["u_px", "v_px"]].to_numpy()
    d = local_centroid(gray, uv) - uv
    return pd.DataFrame({
        "id": obs.id.to_numpy(),
        "surface": surface,
        "du_px": d[:, 0],
        "dv_px": d[:, 1],
        "err_px": np.hypot(d[:, 0], d[:, 1]),
    })  # fmt: skip


def check_simulation(test_dir: str | Path, out_json: str | Path | None = None) -> dict:
    """Measure a simulated test against its own truth; optionally write the figures as JSON.

    For the first and last test frame every camera recorded, decoded from its video through the
    frame map (:mod:`triaxtrack.frames`, so start offsets and dropped frames are honoured): the
    contrast-weighted centroid of the dots the truth says the camera sees (a seeded sample of
    ``CHECK_SAMPLE`` per surface), against the exact image of the dot's centre. Cell-wall dots
    are seen in air; membrane dots through both walls and the water. Also checks frame counts
    and calibration images. ``ok`` is true when every video has the frames its camera recorded
    and the median errors are within 0.10 px (air) and 0.15 px (water).
    """
    from triaxtrack.frames import frame_map, read_camera_timing, read_test_frame
    from triaxtrack.testfolder import camera_entries, read_test_yaml
    from triaxtrack.video import probe_video

    test_dir = Path(test_dir)
    scene_cfg = SimulationConfig.from_dict(
        json.loads((test_dir / TEST_FOLDER.truth.scene).read_text())["simulation"]
    )
    test_yaml = test_dir / TEST_FOLDER.test_yaml
    meta = read_test_yaml(test_yaml)
    truth_obs = read_table(test_dir / TEST_FOLDER.truth.observations, OBSERVATIONS)
    targets = pd.read_csv(test_dir / TEST_FOLDER.kit / "targets.csv").set_index("id")
    rows, per_camera = [], {}
    for entry in camera_entries(meta["cameras"]):
        cam = entry["name"]
        video = test_dir / TEST_FOLDER.video.format(camera=cam)
        info = probe_video(video)
        n_cal = len(list((test_dir / TEST_FOLDER.calibration_images.format(camera=cam)).glob("*.png")))
        recorded = recorded_frames(scene_cfg, cam)
        fmap = frame_map(read_camera_timing(test_yaml, cam), scene_cfg.frames, info["frames"])
        for frame in sorted({int(recorded[0]), int(recorded[-1])}):
            image = read_test_frame(video, fmap, frame)
            if image is None:
                continue  # the video is short: counted below
            sel = truth_obs[(truth_obs.camera == cam) & (truth_obs.frame == frame)]
            e = centroid_errors(sel, targets, image, CHECK_SAMPLE)
            e["camera"], e["frame"] = cam, frame
            rows.append(e)
        per_camera[cam] = {
            "frames": info["frames"],
            "frames_expected": len(recorded),
            "calibration_images": n_cal,
        }
    err = pd.concat(rows, ignore_index=True)

    def stats(sel: pd.DataFrame) -> dict:
        ok = sel.dropna()
        return {
            "n": int(len(ok)),
            "measured_fraction": float(len(ok) / max(len(sel), 1)),
            "median_px": float(ok.err_px.median()) if len(ok) else None,
            "p95_px": float(ok.err_px.quantile(0.95)) if len(ok) else None,
            "bias_u_px": float(ok.du_px.mean()) if len(ok) else None,
            "bias_v_px": float(ok.dv_px.mean()) if len(ok) else None,
        }

    air = stats(err[err.surface == "cell_outer"])
    water = stats(err[err.surface == "membrane"])
    for cam in per_camera:
        sel = err[err.camera == cam]
        per_camera[cam]["air_median_px"] = stats(sel[sel.surface == "cell_outer"])["median_px"]
        per_camera[cam]["water_median_px"] = stats(sel[sel.surface == "membrane"])["median_px"]
    frames_ok = all(c["frames"] == c["frames_expected"] for c in per_camera.values())
    ok = bool(frames_ok and air["median_px"] is not None and air["median_px"] <= 0.10
              and water["median_px"] is not None and water["median_px"] <= 0.15)  # fmt: skip
    report = {"test": meta["name"], "ok": ok, "frames_expected": scene_cfg.frames, "air_dots": air,
              "membrane_dots": water, "cameras": per_camera}  # fmt: skip
    if out_json is not None:
        Path(out_json).write_text(json.dumps(report, indent=2))
    return report
