"""The truth tables of a simulated test: exact volume and strains, target positions, and the
observations and points gathered from the rendered chunks."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.deformation import Deformation
from triaxtrack.layout import TEST_FOLDER
from triaxtrack.simulate.config import SimulationConfig
from triaxtrack.simulate.scene import Scene, _surface_points, frame_progress, load_scene
from triaxtrack.tables import OBSERVATIONS, POINTS, read_table, write_table


def truth_volume(cfg: SimulationConfig, deformation: Deformation) -> pd.DataFrame:
    """Exact soil volume and strains at every frame."""
    frames = np.arange(cfg.frames)
    v0 = deformation.soil_volume(0.0)
    vol = np.array([deformation.soil_volume(frame_progress(k, cfg)) for k in range(cfg.frames)])
    h = np.array([deformation.current_height(frame_progress(k, cfg)) for k in range(cfg.frames)])
    return pd.DataFrame({
        "frame": frames.astype(np.int64),
        "time_s": frames / cfg.fps,
        "volume_mm3": vol,
        "axial_strain": (deformation.height - h) / deformation.height,
        "volumetric_strain": (v0 - vol) / v0,
    })  # fmt: skip


def target_positions(scene: Scene, frame: int) -> pd.DataFrame:
    """Cell-frame centre (x, y, z) of every target at a frame (membrane: printed surface)."""
    p = frame_progress(frame, scene.cfg)
    t = scene.table
    xyz = np.zeros((len(t), 3))
    for surface, sel in t.groupby("surface").groups.items():
        xyz[t.index.get_indexer(sel)] = _surface_points(
            scene, surface, t.loc[sel, ["theta_rad", "z_mm"]].to_numpy(), p
        )[0]
    return pd.DataFrame({"id": t["id"].to_numpy(), "x_mm": xyz[:, 0], "y_mm": xyz[:, 1], "z_mm": xyz[:, 2]})


def finish_truth(test_dir: str | Path, observation_parts: Sequence[str | Path]) -> None:
    """Gather the per-chunk observations into ``truth/observations.parquet`` and write
    ``truth/points.parquet`` (every target at every frame, ``n_rays`` = cameras that see it)."""
    test_dir = Path(test_dir)
    scene = load_scene(test_dir)
    obs = pd.concat([read_table(p, OBSERVATIONS) for p in observation_parts], ignore_index=True)
    write_table(obs, test_dir / TEST_FOLDER.truth.observations, OBSERVATIONS)
    n_rays = obs.groupby(["frame", "id"]).size()
    rows = []
    for k in range(scene.cfg.frames):
        pos = target_positions(scene, k)
        pos.insert(0, "frame", np.int64(k))
        pos.insert(1, "time_s", k / scene.cfg.fps)
        rows.append(pos)
    pts = pd.concat(rows, ignore_index=True)
    key = pd.MultiIndex.from_arrays([pts.frame, pts.id])
    pts["n_rays"] = n_rays.reindex(key).fillna(0).astype(np.int64).to_numpy()
    pts["rms_px"] = 0.0
    write_table(pts, test_dir / TEST_FOLDER.truth.points, POINTS)
