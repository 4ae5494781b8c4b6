"""The simulator: rendered dots sit where exact physics puts them; the test folder is complete."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import yaml

from triaxtrack.centroid import local_centroid
from triaxtrack.optics import Camera, project_air
from triaxtrack.raster import circle_polygon, packed_polygon_coverage
from triaxtrack.simulate import CameraRenderer, SimulationConfig, check_simulation, load_scene
from triaxtrack.tables import OBSERVATIONS, POINTS, VOLUME, read_table
from triaxtrack.video import probe_video


def test_flat_dot_head_on_centroid_within_0p02_px():
    """A flat 1.8 mm dot facing the camera: rendered centroid vs projected centre."""
    K = np.array([[794.0, 0, 639.5], [0, 794.0, 359.5], [0, 0, 1]])
    cam = Camera("c", 1280, 720, K, np.array([-0.3, 0.08, 0, 0, 0]), np.eye(3), np.zeros(3))
    rng = np.random.default_rng(2)
    errs = []
    for _ in range(50):
        c = np.r_[rng.uniform(-40, 40, 2), 260.0]
        ring = circle_polygon([0, 0], 0.9, 16)
        verts = project_air(cam, c + np.c_[ring, np.zeros(16)])
        cov = packed_polygon_coverage(verts, [16], 720, 1280)
        ys, xs = np.mgrid[:720, :1280]
        cen = np.array([(cov * xs).sum(), (cov * ys).sum()]) / cov.sum()
        errs.append(np.linalg.norm(cen - project_air(cam, c[None])[0]))
    assert max(errs) < 0.02


@pytest.fixture(scope="module")
def noiseless_frame(small_test):
    """Frame 0 of cam01 rendered without noise, and its exact observations."""
    scene = load_scene(small_test)
    scene.cfg = SimulationConfig(**{**scene.cfg.__dict__, "noise_sigma": 0.0})
    img, obs = CameraRenderer(scene, "cam01").render(0)
    return scene, img, obs


def test_rendered_centroids_match_exact_projection(noiseless_frame):
    """Rendered dot centroids vs exact images of their centres (air: cell wall; water: membrane).

    The remaining bias is physical (perspective and refraction across a dot of finite size,
    plus the nearest-blob centroid's own error); it is printed for the record.
    """
    scene, img, obs = noiseless_frame
    t = scene.table.set_index("id")
    obs = obs[t.loc[obs.id, "kind"].to_numpy() == "dot"]
    c = local_centroid(img, obs[["u_px", "v_px"]].to_numpy())
    d = c - obs[["u_px", "v_px"]].to_numpy()
    err = np.hypot(d[:, 0], d[:, 1])
    surf = t.loc[obs.id, "surface"].to_numpy()
    for name, limit in (("cell_outer", 0.05), ("membrane", 0.05)):
        sel = (surf == name) & np.isfinite(err)
        assert sel.sum() > 50
        med = np.median(err[sel])
        print(f"{name}: n={sel.sum()} median {med:.4f} px, p95 {np.quantile(err[sel], 0.95):.4f} px, "
              f"bias ({d[sel, 0].mean():+.4f}, {d[sel, 1].mean():+.4f}) px")  # fmt: skip
        assert med < limit


def test_test_folder_is_complete(small_test):
    meta = yaml.safe_load((small_test / "test.yaml").read_text())
    assert meta["name"] == "small" and meta["fps"] == 15.0 and meta["cameras"] == ["cam01", "cam02", "cam03"]
    for cam in meta["cameras"]:
        info = probe_video(small_test / "videos" / f"{cam}.mp4")
        assert info["frames"] == 4 and (info["width"], info["height"]) == (960, 540)
        assert len(list((small_test / "calibration" / cam).glob("*.png"))) == 3
    pts = read_table(small_test / "truth" / "points.parquet", POINTS)
    assert len(pts) == 4352 * 4
    assert pts.n_rays.between(0, 3).all() and (pts.n_rays > 0).mean() > 0.3
    assert np.allclose(pts.time_s, pts.frame / 15.0)
    obs = read_table(small_test / "truth" / "observations.parquet", OBSERVATIONS)
    assert obs.u_px.between(0, 959).all() and obs.v_px.between(0, 539).all()
    counts = obs.groupby(["frame", "id"]).size()
    merged = pts.set_index(["frame", "id"]).n_rays
    assert (merged.reindex(counts.index) == counts).all()
    vol = read_table(small_test / "truth" / "volume.parquet", VOLUME)
    assert len(vol) == 4 and vol.volumetric_strain.iloc[0] == 0.0
    assert vol.axial_strain.iloc[-1] == pytest.approx(0.08)
    cams = json.loads((small_test / "truth" / "cameras.json").read_text())["cameras"]
    assert set(cams) == {"cam01", "cam02", "cam03"} and len(cams["cam01"]["dist"]) == 5


def test_top_cap_moves_with_axial_strain(small_test):
    pts = read_table(small_test / "truth" / "points.parquet", POINTS)
    top = pts[pts.id.between(1, 16)].groupby("frame").z_mm.mean()
    assert top.iloc[-1] - top.iloc[0] == pytest.approx(-0.08 * 142.2, abs=1e-9)
    bottom = pts[pts.id.between(17, 32)].groupby("id")[["x_mm", "y_mm", "z_mm"]].agg(np.ptp)
    assert bottom.to_numpy().max() < 1e-12  # the bottom pedestal does not move


def test_check_simulation_passes(small_test):
    rep = check_simulation(small_test)
    assert rep["ok"], rep
    assert rep["membrane_dots"]["median_px"] < 0.15 and rep["air_dots"]["median_px"] < 0.10


def test_unknown_setting_is_refused():
    with pytest.raises(ValueError, match="unknown simulation settings"):
        SimulationConfig.from_dict({"camreas": 13})


def test_observations_are_deterministic(small_test):
    a = pd.read_parquet(small_test / "truth" / "observations.parquet")
    scene = load_scene(small_test)
    _, obs = CameraRenderer(scene, "cam02").render(0)
    ref = a[(a.camera == "cam02") & (a.frame == 0)].sort_values("id")
    obs = obs.sort_values("id")
    assert list(ref.id) == list(obs.id)
    assert np.abs(ref.u_px.to_numpy() - obs.u_px.to_numpy()).max() < 1e-6


def test_small_membrane_dot_is_at_least_6_px_at_1080p(design):
    """Default cameras at 1920x1080: a small membrane dot facing a camera spans >= 6 px."""
    from triaxtrack.kit import _disc
    from triaxtrack.optics import cell_optics, project_water
    from triaxtrack.simulate import make_cameras

    cam = make_cameras(SimulationConfig(width=1920, height=1080))[0]
    theta = np.arctan2(cam.center[1], cam.center[0])
    r = design["specimen"]["diameter"] / 2 + design["specimen"]["membrane_thickness"]
    ring = _disc(design["membrane"]["small_dot_diameter"] / 2)
    pts = np.c_[r * np.cos(theta + ring[:, 0] / r), r * np.sin(theta + ring[:, 0] / r), 71.1 + ring[:, 1]]
    uv, _, _ = project_water(cam, pts, cell_optics(design))
    width, height = np.ptp(uv, axis=0)
    print(f"small membrane dot at 1920x1080: {width:.2f} x {height:.2f} px")
    assert min(width, height) >= 6.0


def test_cell_wall_dots_land_where_opencv_projects_them(noiseless_frame):
    """Rendered cell-wall dot centroids vs cv2.projectPoints of their design positions."""
    import cv2

    scene, img, _ = noiseless_frame
    cam = scene.cameras["cam01"]
    t = scene.table
    dots = t[(t.surface == "cell_outer") & (t.kind == "dot")]
    r = scene.design["cell"]["outer_radius"]
    xyz = np.c_[r * np.cos(dots.theta_rad), r * np.sin(dots.theta_rad), dots.z_mm]
    facing = (xyz[:, :2] * (cam.center[:2] - xyz[:, :2])).sum(axis=1) > 0.8 * r * np.linalg.norm(
        cam.center[:2] - xyz[:, :2], axis=1
    )
    uv, _ = cv2.projectPoints(xyz[facing], cv2.Rodrigues(cam.R)[0], cam.t, cam.K, cam.dist)
    uv = uv.reshape(-1, 2)
    inside = (uv[:, 0] > 10) & (uv[:, 0] < cam.width - 10) & (uv[:, 1] > 10) & (uv[:, 1] < cam.height - 10)
    err = np.linalg.norm(local_centroid(img, uv[inside]) - uv[inside], axis=1)
    err = err[np.isfinite(err)]
    assert len(err) > 30
    assert np.median(err) < 0.03


def test_camera_above_the_final_top_cap_is_refused(kit_dir, tmp_path):
    from triaxtrack.simulate import make_scene

    cfg = SimulationConfig(cameras=3, frames=3, camera_height_mm=138.0, axial_strain=0.05)
    with pytest.raises(ValueError, match="between the pedestal faces"):
        make_scene(cfg, kit_dir, tmp_path / "t", "t")
